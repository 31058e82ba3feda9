"""Paper-style report (workflow/rules/report.smk), rule paper_report: the report as self-contained HTML and PDF.

By hand (the rule's inputs that are not built yet are reported as "not built in this configuration"):
    python workflow/scripts/paper_report.py paper_report --configfile config/test/config.yaml \
        --output /tmp/paper.html /tmp/paper.pdf
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.report import build_report  # noqa: E402


def main(snakemake, log):
    inputs = [p for p in snakemake.input if Path(p).is_file()]   # under Snakemake all of them; by hand, those built
    captions = [str(c) for c in snakemake.input.captions]
    summary = build_report(inputs, snakemake.params.config, snakemake.output.html, snakemake.output.pdf,
                           captions_dir=Path(captions[0]).parent if captions else None,
                           published=snakemake.params.published, logs_dir=snakemake.params.logs_dir,
                           logs_exclude=snakemake.params.logs_exclude)
    log.info("report: %d figures, %d tables; surrogate reference: %s; %d warning(s) of the workflow's logs listed "
             "under Flags", summary["figures"], summary["tables"], summary["surrogate"], len(summary["warnings"]))
    for note in summary["not_built"]:
        log.info("  %s", note)

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
