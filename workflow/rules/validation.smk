rule validation_real_data:
    input:
        geometry_inputs,
        synopsis=out("stepwise_reduction", "synopsis"),
        idp_synopsis=out("l2s1", "synopsis"),
        real_targets=config["stepwise_reduction"]["real_targets"],
        # the rows the calibration's final fit was pinned to: those are calibration targets, the rest independent
        fitted=out("calibration", "targets"),
        calibrated=outs("calibration", "characteristics"),
        va_artefact=config["discovery"]["va_artefact"],
        anatomy="data/anatomy/l4l5_magnitudes_original_text.csv",
        in_vivo=out("muscle_model", "validation"),
        multilevel=out("validation", "multilevel_rom"),
        curves=out("load_sharing", "curves", set="calibrated"),
        compression=out("load_sharing", "compression", set="calibrated"),
        literature="data/load_sharing/load_sharing_literature.csv",
        bands=out("load_sharing", "bands"),
        band_draws=out("load_sharing", "band_draws"),
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        **stage_outputs("validation", "validation_real_data"),
    log:
        log_file("validation_real_data"),
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
        prior=out("calibration", "prior"),
        posterior=out("calibration", "posterior"),
        covariance=out("calibration", "covariance"),
        draws=out("calibration", "draws"),
        characteristics=outs("calibration", "characteristics"),
        published=characteristic_tables(
            config["characteristics"]["data_dir"], ["calibrated"]
        ),
        literature="data/load_sharing/load_sharing_literature.csv",
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        **stage_outputs("validation", "multilevel_validation"),
    log:
        log_file("multilevel_validation"),
    benchmark:
        benchmark_file("multilevel_validation")
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
        out("validation", "scoreboard_table"),
    output:
        **stage_outputs("validation", "validation_scoreboard_figure"),
    log:
        log_file("validation_scoreboard_figure"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/validation_scoreboard_figure.py"
