# The automatic landmarks scored where the truth is known (the embedded Visible Human meshes given as a user gives
# them, leave one out) and what their error does to the calibrated unit (lumbar.experiments.landmark_accuracy).
# Built by the default target when landmark_accuracy.run (the stage manifest's when).


rule landmark_accuracy:
    input:
        characteristics=outs("calibration", "characteristics"),
    output:
        **stage_outputs("landmark_accuracy", "landmark_accuracy"),
    log:
        log_file("landmark_accuracy"),
    benchmark:
        benchmark_file("landmark_accuracy")
    conda:
        "../envs/lumbar.yaml"
    params:
        accuracy=config["landmark_accuracy"],
        level=config["fsu"]["level"],
    script:
        "../scripts/landmark_accuracy.py"
