# Discrepancy discovery: lumbar.discovery on the default stepwise-reduction table, the published
# vertebral-arch artefact and the in-vivo validation of the muscle model; the null hypothesis drawn from banks of
# virtual specimens of the nominal model (rule discovery_specimen_bank); the benchmark (test fixtures from other
# virtual specimens) split into one job per hidden effect, one for the null tables, one for the out-of-library causes.


# the null bank: virtual specimens of the nominal model in every compared scenario (lumbar.discovery.specimens)
rule discovery_specimen_bank:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("discovery", "discovery_specimen_bank"),
    log:
        log_file("discovery_specimen_bank_{experiment}"),
    benchmark:
        benchmark_file("discovery_specimen_bank_{experiment}")
    wildcard_constraints:
        experiment="rom|idp",
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_specimen_bank.py"


# the virtual specimens the IDP fixtures of the benchmark are drawn from (a stream disjoint from the null bank's),
# in parts (lumbar.discovery.power_study.IDP_FIXTURE_PARTS), so both cores make them
rule discovery_fixture_specimens_idp:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("discovery", "discovery_fixture_specimens_idp"),
    log:
        log_file("discovery_fixture_specimens_idp_{part}"),
    benchmark:
        benchmark_file("discovery_fixture_specimens_idp_{part}")
    wildcard_constraints:
        part="[0-9]+",
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_fixture_specimens_idp.py"


rule discovery_idp_model:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
        cables=config["l2s1"]["cables"],
    output:
        **stage_outputs("discovery", "discovery_idp_model"),
    log:
        log_file("discovery_idp_model"),
    benchmark:
        benchmark_file("discovery_idp_model")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_idp_model.py"


rule discovery_default:
    input:
        geometry_inputs,
        measured=stepwise_reduction_experiment,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
        bank=discovery_specimen_bank("stepwise_rom"),
    output:
        **discovery_case_outputs("default"),
    log:
        log_file("discovery_default"),
    benchmark:
        benchmark_file("discovery_default")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_default.py"


rule discovery_va_artefact:
    input:
        geometry_inputs,
        measured=config["discovery"]["va_artefact"],
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
    output:
        **discovery_case_outputs("va_artefact"),
    log:
        log_file("discovery_va_artefact"),
    benchmark:
        benchmark_file("discovery_va_artefact")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_va_artefact.py"


# real data: the published intact L4-L5 ROM (discovery.intact_rom)
rule discovery_intact_rom:
    input:
        geometry_inputs,
        measured=config["discovery"]["intact_rom"] or [],
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
        bank=discovery_specimen_bank("stepwise_rom"),
        model_bands=discovery_model_bands(),
    output:
        **discovery_case_outputs("intact_rom"),
    log:
        log_file("discovery_intact_rom"),
    benchmark:
        benchmark_file("discovery_intact_rom")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_intact_rom.py"


# every discovery on real measurements in one table (the report's "What the model is missing, on real data")
rule discovery_real_data_summary:
    input:
        runs=discovery_real_data_runs,
        cases=discovery_real_misses_runs,
    output:
        **stage_outputs("discovery", "discovery_real_data_summary"),
    log:
        log_file("discovery_real_data_summary"),
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
        adopted=config["adopted_effects"],
    script:
        "../scripts/discovery_real_data_summary.py"


# chains on the muscle model by path: its rules produce these two tables
rule discovery_in_vivo:
    input:
        measured=out("muscle_model", "validation"),
        segment_loads=config["discovery"]["in_vivo_segment_loads"],
    output:
        **discovery_case_outputs("in_vivo"),
    log:
        log_file("discovery_in_vivo"),
    benchmark:
        benchmark_file("discovery_in_vivo")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_in_vivo.py"


rule discovery_benchmark_job:
    input:
        geometry_inputs,
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
        idp_model=discovery_benchmark_idp_model,
        banks=discovery_benchmark_banks,
    output:
        **stage_outputs("discovery", "discovery_benchmark_job"),
    log:
        log_file("discovery_benchmark_job_{job}"),
    benchmark:
        benchmark_file("discovery_benchmark_job_{job}")
    wildcard_constraints:
        job="[a-z_]+",
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_benchmark_job.py"


rule discovery_benchmark:
    input:
        jobs=expand(out("discovery", "benchmark_job"), job=discovery_benchmark_jobs()),
    output:
        **stage_outputs("discovery", "discovery_benchmark"),
    log:
        log_file("discovery_benchmark"),
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_benchmark.py"


# real misses posed (lumbar.discovery.real_data): the Yamamoto ROM of the levels the calibration did not fit, the
# in-vivo IDP with the lying postures, the facet share of compression; each also at half and double its assumed spread
rule discovery_multilevel_rom:
    input:
        geometry_inputs,
        measured="data/experiments/yamamoto1989_levels_original_text.csv",
        multilevel=out("validation", "multilevel_rom"),
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
    output:
        **discovery_case_outputs("multilevel_rom"),
    log:
        log_file("discovery_multilevel_rom"),
    benchmark:
        benchmark_file("discovery_multilevel_rom")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
        levels=config["load_sharing"]["other_levels"],
        adopted=config["adopted_effects"],
    script:
        "../scripts/discovery_multilevel_rom.py"


rule discovery_in_vivo_lying:
    input:
        measured=out("muscle_model", "validation"),
        segment_loads=config["discovery"]["in_vivo_segment_loads"],
        lying="data/in_vivo/wilke1999_idp_lying_original_text.csv",
        compression=out("load_sharing", "compression", set="calibrated"),
    output:
        **discovery_case_outputs("in_vivo_lying"),
    log:
        log_file("discovery_in_vivo_lying"),
    benchmark:
        benchmark_file("discovery_in_vivo_lying")
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
        adopted=config["adopted_effects"],
    script:
        "../scripts/discovery_in_vivo_lying.py"


rule discovery_facet_share:
    input:
        literature="data/load_sharing/load_sharing_literature.csv",
        compression=out("load_sharing", "compression", set="calibrated"),
    output:
        **stage_outputs("discovery", "discovery_facet_share"),
    log:
        log_file("discovery_facet_share"),
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
        adopted=config["adopted_effects"],
    script:
        "../scripts/discovery_facet_share.py"
