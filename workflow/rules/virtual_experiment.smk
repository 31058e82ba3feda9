rule stepwise_reduction_surrogate:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"],
            [config["stepwise_reduction"]["generator_set"]],
        ),
        real_targets=config["stepwise_reduction"]["real_targets"],
        # the disc-only rows: data of the anchoring fit as of the calibration's final fit (same MAP problem)
        derived=stepwise_reduction_derived,
    output:
        **stage_outputs("virtual_experiment", "stepwise_reduction_surrogate"),
    log:
        log_file("stepwise_reduction_surrogate"),
    benchmark:
        benchmark_file("stepwise_reduction_surrogate")
    # heads the longest chain of the DAG (surrogate -> calibrate -> the muscle model's baseline -> its Sobol and
    # sensitivity chunks): first, so that the calibration does not wait for it behind short jobs
    priority: 10
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
        seed=config["seed"],
    script:
        "../scripts/virtual_experiment.py"


rule idp_surrogate:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"], [config["l2s1"]["generator_set"]]
        ),
        # generator_set "calibrated" = the workflow's calibration output (one resolver for every stage)
        calibrated=(
            characteristic_tables(
                config["l2s1"]["calibrated_characteristics"], ["calibrated"]
            )
            if config["l2s1"]["generator_set"] == "calibrated"
            and config["l2s1"]["calibrated_characteristics"]
            else []
        ),
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("virtual_experiment", "idp_surrogate"),
    log:
        log_file("idp_surrogate"),
    benchmark:
        benchmark_file("idp_surrogate")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        l2s1=config["l2s1"],
        seed=config["seed"],
    script:
        "../scripts/idp_surrogate.py"
