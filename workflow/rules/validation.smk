rule validation_real_data:
    input:
        geometry_inputs,
        synopsis="results/tables/table4_rom_synopsis.csv",
        idp_synopsis="results/tables/table5_idp_synopsis.csv",
        real_targets=config["stepwise_reduction"]["real_targets"],
        # the rows the calibration's final fit was pinned to: those are calibration targets, the rest independent
        fitted="results/calibration/calibration_targets.csv",
        calibrated=CALIBRATION_CHARACTERISTICS,
        va_artefact=config["discovery"]["va_artefact"],
        anatomy="data/anatomy/l4l5_magnitudes_original_text.csv",
        in_vivo="results/tables/in_vivo_validation.csv",
        multilevel="results/tables/multilevel_rom.csv",
        curves="results/load_sharing/curves_calibrated.csv",
        compression="results/load_sharing/compression_calibrated.csv",
        literature="data/load_sharing/load_sharing_literature.csv",
        bands="results/load_sharing/bands_calibrated.csv",
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        table=report(
            "results/tables/validation_real_data.csv",
            caption="../report/validation_real_data.rst",
            category="Validation on real data",
        ),
        null_models=report(
            "results/tables/validation_null_models.csv",
            caption="../report/validation_null_models.rst",
            category="Validation on real data",
        ),
    log:
        "logs/validation_real_data.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        sr=config["stepwise_reduction"],
        idp_table=config["l2s1"]["measured_table"],
    script:
        "../scripts/validation_real_data.py"


rule multilevel_validation:
    input:
        geometry_inputs,
        prior="results/calibration/calibration_prior.csv",
        posterior="results/calibration/posterior.csv",
        covariance="results/calibration/posterior_covariance.csv",
        characteristics=CALIBRATION_CHARACTERISTICS,
        published=characteristic_tables(
            config["characteristics"]["data_dir"], ["calibrated"]
        ),
        literature="data/load_sharing/load_sharing_literature.csv",
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        rom=report(
            "results/tables/multilevel_rom.csv",
            caption="../report/multilevel_rom.rst",
            category="Validation on real data",
        ),
        admissibility="results/tables/multilevel_admissibility.csv",
        curves="results/load_sharing/multilevel_curves.csv",
        readings=report(
            "results/tables/multilevel_transfer_readings.csv",
            caption="../report/multilevel_transfer_readings.rst",
            category="Validation on real data",
        ),
        figure=report(
            "results/figures/multilevel_rom.png",
            caption="../report/multilevel_rom_figure.rst",
            category="Validation on real data",
        ),
    log:
        "logs/multilevel_validation.log",
    benchmark:
        "results/benchmarks/multilevel_validation.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        ls=config["load_sharing"],
    script:
        "../scripts/multilevel_validation.py"


# The first figure of the report: every distinct comparison of validation_real_data.csv (measured value, the
# interval a simulated value must fall in, the simulated value), independent checks apart from calibration
# targets; one panel per quantity, whatever rows the table holds.
rule validation_scoreboard_figure:
    input:
        "results/tables/validation_real_data.csv",
    output:
        scoreboard=report(
            "results/figures/validation_scoreboard.png",
            caption="../report/validation_scoreboard.rst",
            category="Validation on real data",
        ),
        internal_loads=report(
            "results/figures/validation_internal_loads.png",
            caption="../report/validation_internal_loads.rst",
            category="Validation on real data",
        ),
    log:
        "logs/validation_scoreboard_figure.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/validation_scoreboard_figure.py"
