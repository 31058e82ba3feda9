rule fsu_rom:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"], config["characteristics"]["sets"]
        ),
        calibrated=(
            characteristic_tables(
                "results/calibration/characteristics", ["calibrated"]
            )
            if "calibrated" in config["characteristics"]["sets"]
            else []
        ),
    output:
        report(
            "results/tables/fsu_rom_intact.csv",
            caption="../report/fsu_rom_intact.rst",
            category="Functional spinal unit",
        ),
    log:
        "logs/fsu_rom.log",
    benchmark:
        "results/benchmarks/fsu_rom.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sets=config["characteristics"]["sets"],
    script:
        "../scripts/fsu.py"
