rule fsu_geometry:
    input:
        geometry_inputs,
    output:
        "results/tables/fsu_geometry.csv",
    params:
        geometry=config["geometry"],
    log:
        "logs/fsu_geometry.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/geometry.py"


rule fig1_l4l5_model:
    input:
        geometry_inputs,
    output:
        report(
            "results/figures/fig1_l4l5_model.png",
            caption="../report/fig1_l4l5_model.rst",
            category="Geometry",
        ),
    params:
        geometry=config["geometry"],
        level=config["fsu"]["level"],
        backend=config["render"]["backend"],
    log:
        "logs/fig1_l4l5_model.log",
    benchmark:
        "results/benchmarks/fig1_l4l5_model.tsv"
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/geometry.py"
