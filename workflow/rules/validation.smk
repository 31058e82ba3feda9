rule validation_real_data:
    input:
        geometry_inputs,
        synopsis="results/tables/table4_rom_synopsis.csv",
        real_targets=config["stepwise_reduction"]["real_targets"],
        calibrated=CALIBRATION_CHARACTERISTICS,
        va_artefact=config["discovery"]["va_artefact"],
        anatomy="data/anatomy/l4l5_magnitudes_original_text.csv",
        in_vivo="results/tables/in_vivo_validation.csv",
    output:
        report(
            "results/tables/validation_real_data.csv",
            caption="../report/validation_real_data.rst",
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
    script:
        "../scripts/validation.py"


# The first figure of the report: every distinct comparison of validation_real_data.csv (measured value, the
# interval a simulated value must fall in, the simulated value), independent checks apart from calibration
# targets; one panel per quantity, whatever rows the table holds.
rule validation_scoreboard_figure:
    input:
        "results/tables/validation_real_data.csv",
    output:
        report(
            "results/figures/validation_scoreboard.png",
            caption="../report/validation_scoreboard.rst",
            category="Validation on real data",
        ),
    log:
        "logs/validation_scoreboard_figure.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/validation.py"
