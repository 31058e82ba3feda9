# How the unit shares a load between disc, facets and ligaments (lumbar.experiments.load_sharing), for every
# characteristic set, stage and direction; the L4-L5 load paths under the Table 5 wire cables.


rule load_sharing_curves:
    input:
        geometry_inputs,
        characteristics=stepwise_reduction_characteristics,
        characteristic_tables=stepwise_reduction_tables,
    output:
        curves="results/load_sharing/curves_{set}.csv",
        compression="results/load_sharing/compression_{set}.csv",
    log:
        "logs/load_sharing_curves_{set}.log",
    benchmark:
        "results/benchmarks/load_sharing_curves_{set}.tsv"
    wildcard_constraints:
        set="calibrated|chazal1985|shirazi_adl1986|white_panjabi1990|nolte1990|rupp2015",
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        ls=config["load_sharing"],
    script:
        "../scripts/load_sharing_curves.py"


# The 90 % posterior bands of the calibrated unit's intact curves and internal loads (linearisation of the
# calibration's Laplace posterior: one finite-difference step per fitted parameter).
rule load_sharing_bands:
    input:
        geometry_inputs,
        characteristics=CALIBRATION_CHARACTERISTICS,
        posterior="results/calibration/posterior.csv",
        covariance="results/calibration/posterior_covariance.csv",
    output:
        bands="results/load_sharing/bands_calibrated.csv",
    log:
        "logs/load_sharing_bands.log",
    benchmark:
        "results/benchmarks/load_sharing_bands.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        ls=config["load_sharing"],
    script:
        "../scripts/load_sharing_bands.py"


rule load_sharing_summary:
    input:
        curves=expand(
            "results/load_sharing/curves_{set}.csv",
            set=config["characteristics"]["sets"],
        ),
        compression=expand(
            "results/load_sharing/compression_{set}.csv",
            set=config["characteristics"]["sets"],
        ),
        l2s1="results/l2s1/idp_calibrated.csv",
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
        bands="results/load_sharing/bands_calibrated.csv",
    output:
        summary=report(
            "results/load_sharing/load_sharing_summary.csv",
            caption="../report/load_sharing_summary.rst",
            category="Load sharing",
        ),
        reduction=report(
            "results/load_sharing/reduction_flexion.csv",
            caption="../report/load_sharing_reduction.rst",
            category="Load sharing",
        ),
        compression=report(
            "results/load_sharing/compression_summary.csv",
            caption="../report/load_sharing_compression.rst",
            category="Load sharing",
        ),
        cables=report(
            "results/load_sharing/l2s1_cables_l4l5.csv",
            caption="../report/load_sharing_cables.rst",
            category="Load sharing",
        ),
        curves_figure=report(
            "results/figures/load_sharing_curves.png",
            caption="../report/load_sharing_curves.rst",
            category="Load sharing",
        ),
        shares_figure=report(
            "results/figures/load_sharing_shares.png",
            caption="../report/load_sharing_shares.rst",
            category="Load sharing",
        ),
    log:
        "logs/load_sharing_summary.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        fsu=config["fsu"],
    script:
        "../scripts/load_sharing_summary.py"
