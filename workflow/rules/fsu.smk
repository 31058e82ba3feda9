rule fsu_rom:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"], config["characteristics"]["sets"]
        ),
        calibrated=(
            characteristic_tables(calibrated_dir(), ["calibrated"])
            if "calibrated" in config["characteristics"]["sets"]
            else []
        ),
    output:
        **stage_outputs("fsu", "fsu_rom"),
    log:
        log_file("fsu_rom"),
    benchmark:
        benchmark_file("fsu_rom")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sets=config["characteristics"]["sets"],
    script:
        "../scripts/fsu.py"
