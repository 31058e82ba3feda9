# The automatic landmarks scored where the truth is known (the embedded Visible Human meshes given as a user gives
# them, leave one out) and what their error does to the calibrated unit (lumbar.experiments.landmark_accuracy).


rule landmark_accuracy:
    input:
        characteristics=CALIBRATION_CHARACTERISTICS,
    output:
        summary="results/geometry/landmark_accuracy_summary.csv",
        groups="results/geometry/landmark_accuracy_groups.csv",
        lengths="results/geometry/landmark_accuracy_lengths.csv",
        facets="results/geometry/landmark_accuracy_facets.csv",
        effect="results/geometry/landmark_error_effect.csv",
    log:
        "logs/landmark_accuracy.log",
    benchmark:
        "results/benchmarks/landmark_accuracy.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        accuracy=config["landmark_accuracy"],
        level=config["fsu"]["level"],
    script:
        "../scripts/landmark_accuracy.py"
