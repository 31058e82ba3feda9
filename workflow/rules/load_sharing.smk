# How the unit shares a load between disc, facets and ligaments (lumbar.experiments.load_sharing), for every
# characteristic set, stage and direction; the L4-L5 load paths under the Table 5 wire cables.


rule load_sharing_curves:
    input:
        geometry_inputs,
        characteristics=stepwise_reduction_characteristics,
        characteristic_tables=stepwise_reduction_tables,
    output:
        **stage_outputs("load_sharing", "load_sharing_curves"),
    log:
        log_file("load_sharing_curves_{set}"),
    benchmark:
        benchmark_file("load_sharing_curves_{set}")
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
        characteristics=outs("calibration", "characteristics"),
        posterior=out("calibration", "posterior"),
        covariance=out("calibration", "covariance"),
        draws=out("calibration", "draws"),
    output:
        **stage_outputs("load_sharing", "load_sharing_bands"),
    log:
        log_file("load_sharing_bands"),
    benchmark:
        benchmark_file("load_sharing_bands")
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
            out("load_sharing", "curves"),
            set=config["characteristics"]["sets"],
        ),
        compression=expand(
            out("load_sharing", "compression"),
            set=config["characteristics"]["sets"],
        ),
        l2s1=out("l2s1", "idp", set="calibrated"),
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
        bands=out("load_sharing", "bands"),
    output:
        **stage_outputs("load_sharing", "load_sharing_summary"),
    log:
        log_file("load_sharing_summary"),
    conda:
        "../envs/lumbar.yaml"
    params:
        fsu=config["fsu"],
    script:
        "../scripts/load_sharing_summary.py"
