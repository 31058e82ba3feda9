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
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
    script:
        "../scripts/calibrate.py"


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
    output:
        **stage_outputs("calibration", "posterior_figure"),
    log:
        log_file("posterior_figure"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/posterior_figure.py"
