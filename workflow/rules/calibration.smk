CALIBRATION_CHARACTERISTICS = [
    f"results/calibration/characteristics/{n}"
    for n in (
        "disc.csv",
        "facet.csv",
        "ligament_prestrain.csv",
        "ligaments_softplus.csv",
        "ligaments_rupp2015.csv",
        "rupp2015_shape_check.csv",
    )
]


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
        generator_fit="results/experiments/stepwise_reduction_generator_fit.csv",
    output:
        characteristics=CALIBRATION_CHARACTERISTICS,
        summary="results/calibration/calibration_summary.csv",
        real_fit="results/calibration/calibration_real_fit.csv",
        targets="results/calibration/calibration_targets.csv",
        prior="results/calibration/calibration_prior.csv",
        penalties="results/calibration/calibration_penalties.csv",
        posterior="results/calibration/posterior.csv",
        covariance="results/calibration/posterior_covariance.csv",
        row_influence="results/calibration/row_influence.csv",
        rom_fit="results/calibration/calibration_rom_fit.csv",
        disc_points="results/calibration/fig4_points.csv",
        ligament_points="results/calibration/fig5_points.csv",
        table1=report(
            "results/tables/table1_disc_calibrated.csv",
            caption="../report/table1_disc_calibrated.rst",
            category="Stepwise reduction",
        ),
        table2=report(
            "results/tables/table2_facet_surfaces.csv",
            caption="../report/table2_facet_surfaces.rst",
            category="Stepwise reduction",
        ),
        table3=report(
            "results/tables/table3_ligaments_calibrated.csv",
            caption="../report/table3_ligaments_calibrated.rst",
            category="Stepwise reduction",
        ),
    log:
        "logs/calibrate.log",
    benchmark:
        "results/benchmarks/calibrate.tsv"
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
        points="results/calibration/fig4_points.csv",
        table="results/tables/table1_disc_calibrated.csv",
    output:
        report(
            "results/figures/fig4_disc_torque_angle.png",
            caption="../report/fig4_disc_torque_angle.rst",
            category="Stepwise reduction",
        ),
    log:
        "logs/fig4_disc_torque_angle.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/fig4_disc_torque_angle.py"


rule fig5_ligament_characteristics:
    input:
        points="results/calibration/fig5_points.csv",
        table="results/tables/table3_ligaments_calibrated.csv",
    output:
        report(
            "results/figures/fig5_ligament_characteristics.png",
            caption="../report/fig5_ligament_characteristics.rst",
            category="Stepwise reduction",
        ),
    log:
        "logs/fig5_ligament_characteristics.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/fig5_ligament_characteristics.py"


# What the data told us: every calibrated parameter's prior and posterior (Laplace) 90 % interval.
rule posterior_figure:
    input:
        posterior="results/calibration/posterior.csv",
    output:
        report(
            "results/figures/calibration_posterior.png",
            caption="../report/calibration_posterior.rst",
            category="Stepwise reduction",
        ),
    log:
        "logs/posterior_figure.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/posterior_figure.py"
