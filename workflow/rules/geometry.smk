rule fsu_geometry:
    input:
        geometry_inputs,
    output:
        **stage_outputs("geometry", "fsu_geometry"),
    log:
        log_file("fsu_geometry"),
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
        **stage_outputs("geometry", "fig1_l4l5_model"),
    log:
        log_file("fig1_l4l5_model"),
    benchmark:
        benchmark_file("fig1_l4l5_model")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        level=config["fsu"]["level"],
        backend=config["render"]["backend"],
    script:
        "../scripts/fig1_l4l5_model.py"
