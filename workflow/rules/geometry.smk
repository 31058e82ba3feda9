rule fsu_geometry:
    input:
        geometry_inputs,
    output:
        report(
            "results/tables/fsu_geometry.csv",
            caption="../report/fsu_geometry.rst",
            category="Geometry",
        ),
    log:
        "logs/fsu_geometry.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
    script:
        "../scripts/fsu_geometry.py"


rule fig1_l4l5_model:
    input:
        geometry_inputs,
    output:
        report(
            "results/figures/fig1_l4l5_model.png",
            caption="../report/fig1_l4l5_model.rst",
            category="Geometry",
        ),
    log:
        "logs/fig1_l4l5_model.log",
    benchmark:
        "results/benchmarks/fig1_l4l5_model.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        level=config["fsu"]["level"],
        backend=config["render"]["backend"],
    script:
        "../scripts/fig1_l4l5_model.py"
