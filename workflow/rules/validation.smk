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
