"""Figures of record: rule figures_of_record, the numbers of this run that must not get worse quietly, read from
its results into one JSON document (lumbar.report.figures_of_record; absent stages give "absent" entries).

By hand, after a run (from the repository root):
    python workflow/scripts/figures_of_record.py figures_of_record [--configfile F] [--out FILE]
--out (--output) writes elsewhere; a file that holds "records" (benchmarks/results/figures_default.json) gets this
run as the record of the working tree's commit (docs/benchmarks.md).
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
from lumbar.report.figures_of_record import collect, write_figures  # noqa: E402


def main(snakemake, log):
    doc = collect(snakemake.params.root)
    figs = doc["figures"]
    absent = sorted(k for k, v in figs.items() if v.get("value") is None)
    write_figures(doc, snakemake.output[0])
    log.info("figures of record: %d figures, %d absent in this run%s", len(figs), len(absent),
             f" ({', '.join(absent)})" if absent else "")


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
