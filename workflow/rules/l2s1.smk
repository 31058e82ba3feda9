# L2-S1 lumbar spine with wire-cable muscles: L4-L5 IDP in 49 scenarios per characteristic set (Table 5,
# Figs. 3 and 7). The surrogate reference table comes from rule idp_surrogate (virtual_experiment.smk).


rule l2s1_idp:
    input:
        geometry_inputs,
        characteristics=l2s1_characteristics,
        characteristic_tables=l2s1_tables,
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("l2s1", "l2s1_idp"),
    log:
        log_file("l2s1_idp_{set}"),
    benchmark:
        benchmark_file("l2s1_idp_{set}")
    wildcard_constraints:
        set="calibrated|chazal1985|shirazi_adl1986|white_panjabi1990|nolte1990|rupp2015",
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        l2s1=config["l2s1"],
    script:
        "../scripts/l2s1_idp.py"


# The 90 % posterior band of every Table 5 scenario of the calibrated set (linearisation of the calibration's
# Laplace posterior).
rule l2s1_bands:
    input:
        geometry_inputs,
        characteristics=outs("calibration", "characteristics"),
        posterior=out("calibration", "posterior"),
        covariance=out("calibration", "covariance"),
        draws=out("calibration", "draws"),
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("l2s1", "l2s1_bands"),
    log:
        log_file("l2s1_bands"),
    benchmark:
        benchmark_file("l2s1_bands")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        l2s1=config["l2s1"],
    script:
        "../scripts/l2s1_bands.py"


rule table5:
    input:
        sims=expand(out("l2s1", "idp"), set=config["l2s1"]["sets"]),
        reference=l2s1_idp_reference,
        published=published_model_results,
        bands=out("l2s1", "bands"),
    output:
        **stage_outputs("l2s1", "table5"),
    log:
        log_file("table5"),
    conda:
        "../envs/lumbar.yaml"
    params:
        l2s1=config["l2s1"],
        published=config["paths"]["published_model_results"],
    script:
        "../scripts/table5.py"


rule fig3_l2s1_cables:
    input:
        geometry_inputs,
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("l2s1", "fig3_l2s1_cables"),
    log:
        log_file("fig3_l2s1_cables"),
    benchmark:
        benchmark_file("fig3_l2s1_cables")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        render=config["render"],
    script:
        "../scripts/fig3_l2s1_cables.py"
