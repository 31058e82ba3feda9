# Paper-style report: <results root>/report/paper.html (self-contained) and paper.pdf, from every final
# output. A file that is not among the inputs (a stage not in this configuration) becomes a one-line
# "not built in this configuration" note in the report, not an error.


rule paper_report:
    input:
        results=report_inputs,
        derived=stepwise_reduction_derived(None),
        data=sorted(glob("data/**/*.csv", recursive=True)),
        captions=sorted(glob("workflow/report/*.rst")),
        published=published_model_results,
    output:
        **stage_outputs("report", "paper_report"),
    log:
        log_file("paper_report"),
    benchmark:
        benchmark_file("paper_report")
    conda:
        "../envs/lumbar.yaml"
    params:
        config=config,
        published=config["paths"]["published_model_results"],
        # read when the report is built (every rule before it has finished): their WARNING lines are the
        # report's "Flags" section; not inputs (a log is no rule's output file)
        logs_dir=LOGS,
        # the default run's logs folder also holds the named runs' (logs/<name>/): not this run's warnings
        logs_exclude=other_runs_logs,
    script:
        "../scripts/paper_report.py"


# Documents whose numbers are read from the results (lumbar.report.docs): docs/templates/<name>.md rendered into
# <results root>/report/<name>.md. The files a template's placeholders read are the rule's inputs, so a template that
# names a file no rule makes fails the dry run.
rule docs_numbers:
    input:
        templates=DOC_TEMPLATES,
        results=doc_template_inputs,
    output:
        doc_outputs(),
    log:
        log_file("docs_numbers"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/docs_numbers.py"
