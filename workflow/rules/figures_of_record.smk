# The figures of record (lumbar.report.figures_of_record): the numbers of this run that must not get worse quietly
# (validation counts by role beside the trivial models, other levels, Tables 4 and 5 outliers, the discovery benchmark,
# the muscle model's in-vivo R2, admissibility, landmark accuracy, the report's first page, every job's time), read
# from every other final output after they are built. Feeds nothing: the default target's last job. The test suite
# compares the test configuration's with tests/reference/figures_test_config.json (docs/benchmarks.md).


rule figures_of_record:
    input:
        figures_of_record_inputs,
    output:
        **stage_outputs("figures_of_record", "figures_of_record"),
    log:
        log_file("figures_of_record"),
    conda:
        "../envs/lumbar.yaml"
    params:
        # the run's results root (<root>/figures_of_record.json): the figures are read by their roles
        # under it, the job times from its benchmarks/
        root=lambda wildcards, output: str(Path(output.json).parent),
    script:
        "../scripts/figures_of_record.py"
