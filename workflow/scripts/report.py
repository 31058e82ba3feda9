"""Paper-style report: rule paper_report (workflow/rules/report.smk) -> results/report/paper.html, paper.pdf.

By hand (every file that exists under results/ and data/ is taken as an input):
    python workflow/scripts/report.py paper_report --configfile config/test/config.yaml \
        --output /tmp/paper.html /tmp/paper.pdf
"""
import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("_common", Path(__file__).resolve().parent / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)


def _existing(*globs):
    return sorted(str(p) for g in globs for p in Path(".").glob(g) if p.is_file()
                  and not p.as_posix().startswith(("results/report/", "results/benchmarks/")))


RULES = {
    "paper_report": lambda c: dict(
        input=dict(results=_existing("results/**/*.csv", "results/**/*.png", "results/**/*.json",
                                     "results/**/*.md"),
                   data=_existing("data/**/*.csv"),
                   captions=_existing("workflow/report/*.rst")),
        output=["results/report/paper.html", "results/report/paper.pdf"],
        params=dict(config=c, published=c["paths"]["published_model_results"])),
}

if "snakemake" not in globals():
    snakemake = _common.stand_in(RULES, __doc__)

log = _common.setup_logging(snakemake)

from lumbar.report import build_report  # noqa: E402

inputs = []
for item in snakemake.input:   # snakemake flattens named lists; the by-hand stand-in keeps them nested
    inputs += [str(x) for x in item] if isinstance(item, (list, tuple)) else [str(item)]
captions = [str(c) for c in snakemake.input.captions]
summary = build_report(inputs, snakemake.params.config, snakemake.output[0], snakemake.output[1],
                       captions_dir=Path(captions[0]).parent if captions else None,
                       published=snakemake.params.published)
log.info("report: %d figures, %d tables; surrogate reference: %s", summary["figures"], summary["tables"],
         summary["surrogate"])
for note in summary["not_built"]:
    log.info("  %s", note)
