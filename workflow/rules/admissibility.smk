# Physical admissibility of the calibrated set (lumbar.experiments.admissibility): unloaded state, snap-through and
# curve shape, neutral zone, ligaments functional in flexion, facet loading, force scales and bounds.


rule admissibility:
    input:
        geometry_inputs,
        prior="results/calibration/calibration_prior.csv",
        curves="results/load_sharing/curves_calibrated.csv",
        compression="results/load_sharing/compression_calibrated.csv",
        characteristics=CALIBRATION_CHARACTERISTICS,
        real_fit="results/calibration/calibration_real_fit.csv",
        published=characteristic_tables(
            config["characteristics"]["data_dir"], ["calibrated"]
        ),
        literature="data/load_sharing/load_sharing_literature.csv",
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        table=report(
            "results/calibration/admissibility.csv",
            caption="../report/admissibility.rst",
            category="Load sharing",
        ),
        limits="results/calibration/pretension_limits.csv",
        remus=report(
            "results/calibration/remus2021_comparison.csv",
            caption="../report/remus2021_comparison.rst",
            category="Load sharing",
        ),
    log:
        "logs/admissibility.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
    script:
        "../scripts/admissibility.py"
