rule stepwise_reduction_surrogate:
    input:
        geometry_inputs,
        characteristics=config["characteristics"]["data_dir"],
    output:
        "results/experiments/stepwise_reduction_surrogate.csv",
    log:
        "logs/stepwise_reduction_surrogate.log",
    benchmark:
        "results/benchmarks/stepwise_reduction_surrogate.tsv"
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
        characteristics=config["characteristics"]["data_dir"],
        cables=config["l2s1"]["cables"],
    output:
        "results/experiments/idp_wilke1996_surrogate.csv",
    log:
        "logs/idp_surrogate.log",
    benchmark:
        "results/benchmarks/idp_surrogate.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        l2s1=config["l2s1"],
        seed=config["seed"],
    script:
        "../scripts/l2s1.py"
