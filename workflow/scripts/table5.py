"""L2-S1 IDP stage, rule table5: the synopsis of every set against the reference IDP table (with the calibrated set's
90 % posterior band), the outlier counts, the comparison with the paper, the internal loads, the Table 5 grid and
Fig. 7 (lumbar.plots.l2s1).

By hand: python workflow/scripts/table5.py table5 --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import l2s1  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots.l2s1 import plot_fig7, plot_table5_grid  # noqa: E402


def main(snakemake, log):
    ref = l2s1.read_idp_table(snakemake.input.reference)   # the user's table first: fail fast on bad input
    sims = pd.concat([pd.read_csv(f) for f in snakemake.input.sims], ignore_index=True)
    kinds = sorted(set(ref["kind"]))
    log.info("reference IDP table %s, kind(s) %s%s", snakemake.input.reference, kinds,
             " -- SURROGATE, not measured" if "surrogate" in kinds else "")
    syn = l2s1.synopsis(sims, ref)
    # the calibrated set's 90 % posterior band beside its MAP value (the outlier count stays on the MAP value)
    syn = l2s1.with_bands(syn, pd.read_csv(snakemake.input.bands), "calibrated")
    counts = l2s1.outlier_counts(syn)
    vs = l2s1.versus_paper(counts, snakemake.params.published)
    out = snakemake.output
    write_table_atomic(syn, out.synopsis)
    write_table_atomic(counts, out.counts)
    write_table_atomic(vs, out.vs_paper)
    internal = sims.drop(columns=["idp_mpa"]).merge(syn[["set", "muscle_setup", "load_case", "idp_sim_mpa",
                                                         "outlier", "data_kind"]], on=["set", "muscle_setup", "load_case"])
    write_table_atomic(internal, out.internal)
    plot_table5_grid(syn, out.grid)
    plot_fig7(syn, out.fig7)
    for _, r in vs.iterrows():
        log.info("set %s: %d outliers of %d (paper: %s) [reference %s]", r["set"], r["n_outliers"],
                 r["n_scenarios"], r["paper_n_outliers"], r["data_kind"])
    log.info("done: %s", ", ".join(map(str, snakemake.output)))

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
