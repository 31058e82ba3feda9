rule stepwise_reduction_sim:
    input:
        geometry_inputs,
        characteristics=stepwise_reduction_characteristics,
        characteristic_tables=stepwise_reduction_tables,
    output:
        "results/stepwise_reduction/rom_{set}.csv",
    log:
        "logs/stepwise_reduction_sim_{set}.log",
    benchmark:
        "results/benchmarks/stepwise_reduction_sim_{set}.tsv"
    wildcard_constraints:
        set="calibrated|chazal1985|shirazi_adl1986|white_panjabi1990|nolte1990|rupp2015",
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
    script:
        "../scripts/stepwise_reduction_sim.py"


# The 90 % posterior band of every Table 4 scenario of the calibrated set (linearisation of the calibration's
# Laplace posterior).
rule stepwise_reduction_bands:
    input:
        geometry_inputs,
        characteristics=CALIBRATION_CHARACTERISTICS,
        posterior="results/calibration/posterior.csv",
        covariance="results/calibration/posterior_covariance.csv",
    output:
        "results/stepwise_reduction/bands_calibrated.csv",
    log:
        "logs/stepwise_reduction_bands.log",
    benchmark:
        "results/benchmarks/stepwise_reduction_bands.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        solver=config["solver"],
        sr=config["stepwise_reduction"],
    script:
        "../scripts/stepwise_reduction_bands.py"


rule table4:
    input:
        sims=expand(
            "results/stepwise_reduction/rom_{set}.csv",
            set=config["characteristics"]["sets"],
        ),
        experiment=stepwise_reduction_experiment,
        derived=stepwise_reduction_derived,
        real_targets=config["stepwise_reduction"]["real_targets"],
        published=published_model_results,
        bands="results/stepwise_reduction/bands_calibrated.csv",
    output:
        synopsis=report(
            "results/tables/table4_rom_synopsis.csv",
            caption="../report/table4_rom_synopsis.rst",
            category="Stepwise reduction",
        ),
        counts=report(
            "results/tables/table4_outlier_counts.csv",
            caption="../report/table4_outlier_counts.rst",
            category="Stepwise reduction",
        ),
        vs_paper=report(
            "results/tables/table4_vs_paper.csv",
            caption="../report/table4_vs_paper.rst",
            category="Stepwise reduction",
        ),
        grid=report(
            "results/figures/table4_grid.png",
            caption="../report/table4_grid.rst",
            category="Stepwise reduction",
        ),
    log:
        "logs/table4.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        sr=config["stepwise_reduction"],
        published=config["paths"]["published_model_results"],
    script:
        "../scripts/table4.py"


rule fig6_rom_stepwise_reduction:
    input:
        "results/tables/table4_rom_synopsis.csv",
    output:
        report(
            "results/figures/fig6_rom_stepwise_reduction.png",
            caption="../report/fig6_rom_stepwise_reduction.rst",
            category="Stepwise reduction",
        ),
    log:
        "logs/fig6_rom_stepwise_reduction.log",
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/fig6_rom_stepwise_reduction.py"
