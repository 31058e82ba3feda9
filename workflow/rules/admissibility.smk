# Physical admissibility of the calibrated set (lumbar.experiments.admissibility): unloaded state, snap-through and
# curve shape, neutral zone, ligaments functional in flexion, facet loading, force scales and bounds.


rule admissibility:
    input:
        geometry_inputs,
        prior=out("calibration", "prior"),
        curves=out("load_sharing", "curves", set="calibrated"),
        compression=out("load_sharing", "compression", set="calibrated"),
        characteristics=outs("calibration", "characteristics"),
        real_fit=out("calibration", "real_fit"),
        published=characteristic_tables(
            config["characteristics"]["data_dir"], ["calibrated"]
        ),
        literature="data/load_sharing/load_sharing_literature.csv",
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        **stage_outputs("admissibility", "admissibility"),
    log:
        log_file("admissibility"),
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
    script:
        "../scripts/admissibility.py"
