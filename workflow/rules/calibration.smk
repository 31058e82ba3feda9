rule calibrate:
    input:
        geometry_inputs,
        experiment=stepwise_reduction_experiment,
        derived=stepwise_reduction_derived,
        real_targets=config["stepwise_reduction"]["real_targets"],
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        # the surrogate generator's anchoring: the start of the calibration's own real-target fit
        generator_fit=out("virtual_experiment", "generator_fit"),
    output:
        **stage_outputs("calibration", "calibrate"),
    log:
        log_file("calibrate"),
    benchmark:
        benchmark_file("calibrate")
    # on the longest chain (see stepwise_reduction_surrogate)
    priority: 10
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
    script:
        "../scripts/calibrate.py"


# The calibration's diagnostic refits (leave-one-row-out, held facet stiffness, wider disc-only spread): the same
# calibration with the refits from its MAP, in its own job so that everything that reads the calibrated set starts
# while they run (they took 40 of the 48 s of one calibration job). It checks that its MAP is the shipped one.
rule calibration_influence:
    input:
        geometry_inputs,
        experiment=stepwise_reduction_experiment,
        derived=stepwise_reduction_derived,
        real_targets=config["stepwise_reduction"]["real_targets"],
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        generator_fit=out("virtual_experiment", "generator_fit"),
        posterior=out("calibration", "posterior"),
    output:
        **stage_outputs("calibration", "calibration_influence"),
    log:
        log_file("calibration_influence"),
    benchmark:
        benchmark_file("calibration_influence")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
    script:
        "../scripts/calibration_influence.py"


# Draws from the calibration's posterior: a short MCMC (emcee) on the objective the MAP fit minimises, in a job of
# its own (the calibration rerun deterministically, its MAP checked against the shipped one). The band rules run
# these draws forward where a linearised band fails its check (lumbar.experiments.posterior.checked_band).
rule calibration_draws:
    input:
        geometry_inputs,
        experiment=stepwise_reduction_experiment,
        derived=stepwise_reduction_derived,
        real_targets=config["stepwise_reduction"]["real_targets"],
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        generator_fit=out("virtual_experiment", "generator_fit"),
        posterior=out("calibration", "posterior"),
    output:
        **stage_outputs("calibration", "calibration_draws"),
    log:
        log_file("calibration_draws"),
    benchmark:
        benchmark_file("calibration_draws")
    # the band rules wait for it
    priority: 8
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
    script:
        "../scripts/calibration_draws.py"


rule fig4_disc_torque_angle:
    input:
        points=out("calibration", "disc_points"),
        table=out("calibration", "table1"),
    output:
        **stage_outputs("calibration", "fig4_disc_torque_angle"),
    log:
        log_file("fig4_disc_torque_angle"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/fig4_disc_torque_angle.py"


rule fig5_ligament_characteristics:
    input:
        points=out("calibration", "ligament_points"),
        table=out("calibration", "table3"),
    output:
        **stage_outputs("calibration", "fig5_ligament_characteristics"),
    log:
        log_file("fig5_ligament_characteristics"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/fig5_ligament_characteristics.py"


# What the data told us: every calibrated parameter's prior and posterior (Laplace) 90 % interval.
rule posterior_figure:
    input:
        posterior=out("calibration", "posterior"),
        sampling=out("calibration", "sampling"),
    output:
        **stage_outputs("calibration", "posterior_figure"),
    log:
        log_file("posterior_figure"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/posterior_figure.py"
