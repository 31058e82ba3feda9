"""Report stage (workflow/rules/report.smk), rule docs_numbers: the documents of docs/templates rendered with the
numbers of this run (lumbar.report.docs).

By hand: python workflow/scripts/docs_numbers.py docs_numbers --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.inputs.manifests import results_root  # noqa: E402
from lumbar.report.docs import render_file  # noqa: E402


def main(snakemake, log):
    root = results_root(snakemake.config)       # the run's results (config run.name)
    for template, out in zip(snakemake.input.templates, snakemake.output):
        render_file(template, out, results_root=root)
        log.info("rendered %s -> %s", template, out)

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
