"""Discrepancy stage, rule discovery_benchmark: the benchmark's jobs in one table, its summary against the targets,
the report paragraph and the figure (lumbar.discovery.power_study, lumbar.plots.discovery).

By hand: python workflow/scripts/discovery_benchmark.py discovery_benchmark --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar import discovery as discover  # noqa: E402
from lumbar.inputs.io import write_json_atomic, write_table_atomic, write_text_atomic  # noqa: E402
from lumbar.plots.discovery import plot_benchmark  # noqa: E402

COLUMNS = ["case", "experiment", "category", "hidden_effect", "magnitude_label", "magnitude", "named_effect",
           "correct", "decision", "p_value", "p_vs_nuisance", "p_fit_specimen_mean", "best_candidate",
           "best_nuisance", "param_true", "param_est", "at_bound", "gap_before", "gap_specimen_mean", "gap_after",
           "confidence", "fixture"]


def main(snakemake, log):
    cfg = snakemake.params.cfg
    bench = pd.concat([pd.read_csv(p) for p in snakemake.input.jobs], ignore_index=True)
    bench = bench.sort_values("case", kind="stable").reset_index(drop=True)
    summary = discover.summarise_benchmark(bench, discover.benchmark_settings(cfg)["generator"])
    summary["paragraph"] = discover.benchmark_paragraph(summary)
    write_table_atomic(bench[COLUMNS], snakemake.output.table, float_format="%.6g")
    write_json_atomic(summary, snakemake.output.summary, allow_nan=True)
    write_text_atomic("## Discrepancy benchmark\n\n" + summary["paragraph"] + "\n", snakemake.output.paragraph)
    plot_benchmark(bench, summary, snakemake.output.figure)
    log.info("benchmark: %d nulls, false-positive rate %s (95%% CI %s); library at m1/m2 named %s; out of library "
             "unnamed %s; null p-values KS p %s; all targets met: %s", summary["n_null"],
             summary["false_positive_rate"], summary["false_positive_rate_95ci"],
             summary["library_at_benchmark_magnitudes"]["rate"], summary["out_of_library_unnamed"]["rate"],
             summary["null_p_values"]["ks_p"], summary["all_pass"])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
