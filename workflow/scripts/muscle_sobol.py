"""Muscle-driven model (paper 2), rule muscle_sobol: the Sobol indices of the L4-L5 IDP from the PCE fitted to the
chunks' samples, with bootstrap intervals, and their figure (lumbar.plots.muscle_model.plot_sobol).

By hand: python workflow/scripts/muscle_sobol.py muscle_sobol --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import time  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles import muscle_sensitivity as sens  # noqa: E402
from lumbar.plots.muscle_model import plot_sobol  # noqa: E402


def main(snakemake, log):
    p = snakemake.params.muscle_model
    sb = p["sobol"]
    samples = pd.concat([pd.read_csv(f) for f in snakemake.input.chunks], ignore_index=True)
    t0 = time.perf_counter()
    df = sens.sobol_indices(samples, sb["n_train"], sb["degree"], snakemake.params.seed, sb.get("n_bootstrap", 500))
    log.info("PCE fits and %d bootstrap refits per posture in %.1f s", sb.get("n_bootstrap", 500),
             time.perf_counter() - t0)
    for post, d in df.groupby("posture", sort=False):
        r = d.iloc[0]
        top = d[d["parameter"] == r["top_parameter"]]
        top = top.iloc[0] if len(top) else r
        log.info("Sobol %s: PCE degree %d on %d of %d samples, Q2_loo = %.3f%s; top first-order index %s S1 = %.3f "
                 "[%.3f, %.3f] (bootstrap 95 %%; width %.3f: %s), sum S1 = %.2f; %d not reached, %d not certified",
                 post, int(r["degree"]), int(r["n_fit"]), int(r["n_train"]), r["q2_loo"],
                 "" if r["fit_ok"] else f" < {sens.SOBOL_Q2_MIN} (poor fit)", top["parameter"], top["S1"],
                 top["S1_lo"], top["S1_hi"], r["top_s1_width"], "stable" if r["stable"] else "NOT stable",
                 d["S1"].sum(), int(r["n_failed"]), int(r["n_uncertified"]))
    write_table_atomic(df, snakemake.output[0])
    plot_sobol(df, snakemake.output[1])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
