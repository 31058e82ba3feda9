"""Stepwise-reduction stage, rule table4: the synopsis of every set against the reference table (with the calibrated
set's 90 % posterior band), the outlier counts, the comparison with the paper and the check/cross grid
(lumbar.plots.stepwise_reduction).

By hand: python workflow/scripts/table4.py table4 --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import stepwise_reduction as sr_mod  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots.stepwise_reduction import plot_table4_grid  # noqa: E402


def main(snakemake, log):
    sr = snakemake.params.sr
    exp = sr_mod.read_experiment_table(snakemake.input.experiment)
    derived = sr_mod.read_experiment_table(_common.first(snakemake.input.derived)) \
        if _common.first(snakemake.input.derived) else None
    real = [sr_mod.read_experiment_table(p) for p in _common.as_list(snakemake.input.real_targets)]
    ref = sr_mod.reference_table(exp, derived, pd.concat(real, ignore_index=True) if real else None)
    parts, missing = [], set()
    for p in snakemake.input.sims:
        sim = pd.read_csv(p)
        parts.append(sr_mod.assess(sim, ref, str(sim["set"].iloc[0]), sr["outlier_tolerance_deg"]))
        missing.update(sr_mod.unreferenced_scenarios(sim, ref))
    if missing and not (ref["kind"] == "surrogate").any():
        log.warning("the measured table %s has no row for %d simulated scenario(s), not assessed in any set: %s",
                    snakemake.input.experiment, len(missing), "; ".join(sorted(missing)))
    syn = pd.concat(parts, ignore_index=True)
    # the calibrated set's 90 % posterior band beside its MAP value (the outlier count stays on the MAP value)
    syn = sr_mod.with_bands(syn, pd.read_csv(snakemake.input.bands), "calibrated")
    counts = sr_mod.outlier_counts(syn)
    vs = sr_mod.compare_with_paper(counts, snakemake.params.published)
    for _, r in counts.iterrows():
        log.info("set %-18s %3d outliers of %d (%d not converged; reference %s)", r["set"], r["n_outliers"],
                 r["n_scenarios"], r["n_not_converged"], r["data_kinds"])
    write_table_atomic(syn, snakemake.output.synopsis)
    write_table_atomic(counts, snakemake.output.counts)
    write_table_atomic(vs, snakemake.output.vs_paper)
    plot_table4_grid(syn, snakemake.output.grid)

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
