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
        "results/discrepancy/model/specimen_bank_{experiment}.csv",
    log:
        "logs/discovery_specimen_bank_{experiment}.log",
    benchmark:
        "results/benchmarks/discovery_specimen_bank_{experiment}.tsv"
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
        "results/discrepancy/model/fixture_specimens_idp_{part}.csv",
    log:
        "logs/discovery_fixture_specimens_idp_{part}.log",
    benchmark:
        "results/benchmarks/discovery_fixture_specimens_idp_{part}.tsv"
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
        "results/discrepancy/model/idp_invitro_model.csv",
    log:
        "logs/discovery_idp_model.log",
    benchmark:
        "results/benchmarks/discovery_idp_model.tsv"
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
        "logs/discovery_default.log",
    benchmark:
        "results/benchmarks/discovery_default.tsv"
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
        "logs/discovery_va_artefact.log",
    benchmark:
        "results/benchmarks/discovery_va_artefact.tsv"
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
        "logs/discovery_intact_rom.log",
    benchmark:
        "results/benchmarks/discovery_intact_rom.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
    script:
        "../scripts/discovery_intact_rom.py"


def discovery_real_misses_runs(wildcards):
    """real_case.json of every real-miss case this configuration can pose (the in-vivo one when the muscle model's
    tables are built or present, as for discovery_in_vivo)."""
    cases = ["facet_share"]
    if config["load_sharing"]["other_levels"]:
        cases.append("multilevel_rom")
    if "results/discrepancy/in_vivo/discovery.json" in discovery_final_outputs():
        cases.append("in_vivo_lying")
    return [f"results/discrepancy/{c}/real_case.json" for c in cases]


# every discovery on real measurements in one table (the report's "What the model is missing, on real data")
rule discovery_real_data_summary:
    input:
        runs=discovery_real_data_runs,
        cases=discovery_real_misses_runs,
    output:
        report(
            "results/discrepancy/real_data_summary.csv",
            caption="../report/discovery_real_data_summary.rst",
            category="Discrepancy",
        ),
    log:
        "logs/discovery_real_data_summary.log",
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
        measured="results/tables/in_vivo_validation.csv",
        segment_loads=config["discovery"]["in_vivo_segment_loads"],
    output:
        **discovery_case_outputs("in_vivo"),
    log:
        "logs/discovery_in_vivo.log",
    benchmark:
        "results/benchmarks/discovery_in_vivo.tsv"
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
        table="results/discrepancy/benchmark/{job}.csv",
        fixtures=directory("results/discrepancy/benchmark/{job}_fixtures"),
    log:
        "logs/discovery_benchmark_job_{job}.log",
    benchmark:
        "results/benchmarks/discovery_benchmark_job_{job}.tsv"
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
        jobs=expand(
            "results/discrepancy/benchmark/{job}.csv", job=discovery_benchmark_jobs()
        ),
    output:
        table=report(
            "results/discrepancy/benchmark.csv",
            caption="../report/discrepancy_benchmark_table.rst",
            category="Discrepancy",
        ),
        summary=report(
            "results/discrepancy/benchmark_summary.json",
            caption="../report/discrepancy_benchmark_table.rst",
            category="Discrepancy",
        ),
        figure=report(
            "results/figures/discrepancy_benchmark.png",
            caption="../report/discrepancy_benchmark.rst",
            category="Discrepancy",
        ),
        paragraph="results/discrepancy/benchmark_section.md",
    log:
        "logs/discovery_benchmark.log",
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
        multilevel="results/tables/multilevel_rom.csv",
        characteristics=characteristics_dir(),
        characteristic_tables=characteristic_tables(
            config["characteristics"]["data_dir"]
        ),
        calibrated=discovery_calibrated_tables(),
    output:
        **discovery_case_outputs("multilevel_rom"),
        real_case="results/discrepancy/multilevel_rom/real_case.json",
    log:
        "logs/discovery_multilevel_rom.log",
    benchmark:
        "results/benchmarks/discovery_multilevel_rom.tsv"
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
        measured="results/tables/in_vivo_validation.csv",
        segment_loads=config["discovery"]["in_vivo_segment_loads"],
        lying="data/in_vivo/wilke1999_idp_lying_original_text.csv",
        compression="results/load_sharing/compression_calibrated.csv",
    output:
        **discovery_case_outputs("in_vivo_lying"),
        real_case="results/discrepancy/in_vivo_lying/real_case.json",
    log:
        "logs/discovery_in_vivo_lying.log",
    benchmark:
        "results/benchmarks/discovery_in_vivo_lying.tsv"
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
        compression="results/load_sharing/compression_calibrated.csv",
    output:
        rows="results/discrepancy/facet_share/rows.csv",
        real_case="results/discrepancy/facet_share/real_case.json",
    log:
        "logs/discovery_facet_share.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        cfg=discovery_config,
        adopted=config["adopted_effects"],
    script:
        "../scripts/discovery_facet_share.py"
