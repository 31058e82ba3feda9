"""Stepwise-reduction stage: rules stepwise_reduction_sim (one characteristic set, 160 scenarios),
table4 (synopsis, outlier counts, comparison with the paper, check/cross grid) and
fig6_rom_stepwise_reduction.

By hand: python workflow/scripts/stepwise_reduction.py stepwise_reduction_sim set=chazal1985 \
    --configfile config/test/config.yaml --output /tmp/rom_chazal1985.csv
"""
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

from lumbar.experiments import stepwise_reduction as sr_mod  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots import stepwise_reduction as SRP  # noqa: E402

if snakemake.rule == "stepwise_reduction_sim":
    s, sr = snakemake.params.solver, snakemake.params.sr
    set_name, data_dir, fsu = _common.set_fsu(snakemake)
    sim = sr_mod.simulate_stepwise_reduction(fsu, moments_nm=sr["moments_nm"], max_iter=s["max_iter"],
                                             tol=min(s["tol_force_n"], s["tol_moment_nm"]), load_steps=s["load_steps"])
    sim.insert(0, "set", set_name)
    bad = sim.loc[~sim["converged"]]
    where = ", ".join(f"{st} ({n})" for st, n in bad.groupby("stage", sort=False).size().items())
    saddle = sorted(set(sim.loc[~sim["rest_state_stable"].astype(bool), "stage"]))
    log.info("set %s (characteristics from %s): %d scenarios, %d not converged%s; ROM measured from an unstable "
             "0 N*m state (rest_state_stable=False): %s", set_name, data_dir, len(sim), len(bad),
             f" (by stage: {where})" if len(bad) else "", ", ".join(saddle) or "none")
    write_table_atomic(sim, snakemake.output[0])
elif snakemake.rule == "table4":
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
    SRP.plot_table4_grid(syn, snakemake.output.grid)
elif snakemake.rule == "fig6_rom_stepwise_reduction":
    syn = pd.read_csv(snakemake.input[0])
    set_name = "calibrated" if "calibrated" in set(syn["set"]) else str(syn["set"].iloc[0])
    SRP.plot_rom_stepwise_reduction(syn, snakemake.output[0], set_name)
    log.info("wrote %s", snakemake.output[0])
