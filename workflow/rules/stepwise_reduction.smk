rule stepwise_reduction_sim:
    input:
        geometry_inputs,
        characteristics=stepwise_reduction_characteristics,
        characteristic_tables=stepwise_reduction_tables,
    output:
        **stage_outputs("stepwise_reduction", "stepwise_reduction_sim"),
    log:
        log_file("stepwise_reduction_sim_{set}"),
    benchmark:
        benchmark_file("stepwise_reduction_sim_{set}")
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
        characteristics=outs("calibration", "characteristics"),
        posterior=out("calibration", "posterior"),
        covariance=out("calibration", "covariance"),
        draws=out("calibration", "draws"),
    output:
        **stage_outputs("stepwise_reduction", "stepwise_reduction_bands"),
    log:
        log_file("stepwise_reduction_bands"),
    benchmark:
        benchmark_file("stepwise_reduction_bands")
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
            out("stepwise_reduction", "rom"),
            set=config["characteristics"]["sets"],
        ),
        experiment=stepwise_reduction_experiment,
        derived=stepwise_reduction_derived,
        real_targets=config["stepwise_reduction"]["real_targets"],
        published=published_model_results,
        bands=out("stepwise_reduction", "bands"),
    output:
        **stage_outputs("stepwise_reduction", "table4"),
    log:
        log_file("table4"),
    conda:
        "../envs/lumbar.yaml"
    params:
        sr=config["stepwise_reduction"],
        published=config["paths"]["published_model_results"],
    script:
        "../scripts/table4.py"


rule fig6_rom_stepwise_reduction:
    input:
        out("stepwise_reduction", "synopsis"),
    output:
        **stage_outputs("stepwise_reduction", "fig6_rom_stepwise_reduction"),
    log:
        log_file("fig6_rom_stepwise_reduction"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/fig6_rom_stepwise_reduction.py"
