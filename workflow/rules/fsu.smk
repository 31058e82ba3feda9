rule fsu_rom:
    input:
        geometry_inputs,
        characteristics=config["characteristics"]["data_dir"],
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
