# L2-S1 lumbar spine with wire-cable muscles: L4-L5 IDP in 49 scenarios per characteristic set (Table 5,
# Figs. 3 and 7). The surrogate reference table comes from rule idp_surrogate (virtual_experiment.smk).


rule l2s1_idp:
    input:
        geometry_inputs,
        characteristics=l2s1_characteristics,
        characteristic_tables=l2s1_tables,
        cables=config["l2s1"]["cables"],
    output:
        "results/l2s1/idp_{set}.csv",
    log:
        "logs/l2s1_idp_{set}.log",
    benchmark:
        "results/benchmarks/l2s1_idp_{set}.tsv"
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
        characteristics=CALIBRATION_CHARACTERISTICS,
        posterior="results/calibration/posterior.csv",
        covariance="results/calibration/posterior_covariance.csv",
        cables=config["l2s1"]["cables"],
    output:
        "results/l2s1/bands_calibrated.csv",
    log:
        "logs/l2s1_bands.log",
    benchmark:
        "results/benchmarks/l2s1_bands.tsv"
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
        sims=expand("results/l2s1/idp_{set}.csv", set=config["l2s1"]["sets"]),
        reference=l2s1_idp_reference,
        published=published_model_results,
        bands="results/l2s1/bands_calibrated.csv",
    output:
        synopsis=report(
            "results/tables/table5_idp_synopsis.csv",
            caption="../report/table5_idp_synopsis.rst",
            category="IDP (L2-S1)",
        ),
        counts=report(
            "results/tables/table5_outlier_counts.csv",
            caption="../report/table5_outlier_counts.rst",
            category="IDP (L2-S1)",
        ),
        vs_paper=report(
            "results/tables/table5_vs_paper.csv",
            caption="../report/table5_vs_paper.rst",
            category="IDP (L2-S1)",
        ),
        internal=report(
            "results/tables/l2s1_internal_loads.csv",
            caption="../report/l2s1_internal_loads.rst",
            category="IDP (L2-S1)",
        ),
        grid=report(
            "results/figures/table5_grid.png",
            caption="../report/table5_grid.rst",
            category="IDP (L2-S1)",
        ),
        fig7=report(
            "results/figures/fig7_idp.png",
            caption="../report/fig7_idp.rst",
            category="IDP (L2-S1)",
        ),
    log:
        "logs/table5.log",
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
        report(
            "results/figures/fig3_l2s1_cables.png",
            caption="../report/fig3_l2s1_cables.rst",
            category="IDP (L2-S1)",
        ),
    log:
        "logs/fig3_l2s1_cables.log",
    benchmark:
        "results/benchmarks/fig3_l2s1_cables.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        render=config["render"],
    script:
        "../scripts/fig3_l2s1_cables.py"
