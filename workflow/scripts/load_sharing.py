"""Load-sharing stage: rules load_sharing_curves (one characteristic set: moment-rotation curves of every stage and
direction with the internal loads, and the follower-load compression curve) and load_sharing_summary (tables at
10 N*m, the compression shares, the L4-L5 load paths under the Table 5 wire cables, two figures).

By hand: python workflow/scripts/load_sharing.py load_sharing_curves set=calibrated --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.experiments import load_sharing as LS  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots import load_sharing as LSP  # noqa: E402

if snakemake.rule == "load_sharing_curves":
    s, ls = snakemake.params.solver, snakemake.params.ls
    set_name, _, fsu = _common.set_fsu(snakemake, follower=True)
    moments = np.round(np.arange(0.0, ls["max_moment_nm"] + 1e-9, ls["moment_step_nm"]), 6)
    curves = LS.moment_rotation_curves(fsu, moments_nm=moments, stages=ls["stages"], max_iter=s["max_iter"])
    curves.insert(0, "set", set_name)
    comp = LS.axial_compression_curve(fsu, forces_n=np.arange(0.0, ls["compression_max_n"] + 1e-9,
                                                              ls["compression_step_n"]), max_iter=s["max_iter"])
    comp.insert(0, "set", set_name)
    bad = curves[curves["converged"] & (curves["moment_balance_residual_nm"] > 1e-6)]
    if len(bad):
        raise RuntimeError(f"set {set_name}: the structures' moments do not balance the applied moment in {len(bad)} "
                           f"converged steps (largest residual {bad['moment_balance_residual_nm'].max():.3g} N*m)")
    n_jump, n_bad = int(curves["jump"].sum()), int((~curves["converged"]).sum())
    log.info("set %s: %d curve steps (%d stages x %d directions), %d jumps >= %g deg, %d not converged; moment "
             "balance of the converged steps <= %.1e N*m; facet share of a %g N follower load %.3f", set_name, len(curves),
             len(ls["stages"]), len(LS.CURVE_DIRECTIONS), n_jump, LS.JUMP_DEG, n_bad,
             curves.loc[curves["converged"], "moment_balance_residual_nm"].max(), comp["force_n"].iloc[-1], comp["facet_share"].iloc[-1])
    write_table_atomic(curves, snakemake.output.curves)
    write_table_atomic(comp, snakemake.output.compression)
elif snakemake.rule == "load_sharing_summary":
    curves = {}
    parts = []
    for p in _common.as_list(snakemake.input.curves):
        cv = pd.read_csv(p)
        name = str(cv["set"].iloc[0])
        curves[name] = cv
        parts.append(LS.summary_at(cv, name, float(cv["moment_nm"].max())))
        parts.append(LS.summary_at(cv, name, 0.0))
    summary = pd.concat(parts, ignore_index=True)
    comp = pd.concat([pd.read_csv(p) for p in _common.as_list(snakemake.input.compression)], ignore_index=True)
    comp_summary = comp.groupby("set", sort=False).tail(1)[
        ["set", "force_n", "converged", "disc_share", "facet_share"] +
        [c for c in comp.columns if c.endswith("_axial_n")]].reset_index(drop=True)
    cables = LS.cable_load_paths(pd.read_csv(snakemake.input.l2s1))
    y = pd.read_csv(snakemake.input.yamamoto)
    lvl = snakemake.params.fsu["level"]
    ref = y[(y["level"] == lvl) & (y["quantity"] == "rom")].assign(
        direction=lambda d: d["direction"].str.replace("_one_side", "", regex=False))
    LSP.plot_curves(curves, ref, snakemake.output.curves_figure, bands=pd.read_csv(snakemake.input.bands))
    if "calibrated" in curves:
        LSP.plot_shares(curves["calibrated"], snakemake.output.shares_figure,
                       title=f"Moment carried by each structure, calibrated {lvl} unit (below 0: acting with the applied "
                       "moment; upper stack minus lower stack = the applied moment, dashed)")
    else:
        first = next(iter(curves))
        LSP.plot_shares(curves[first], snakemake.output.shares_figure)
    write_table_atomic(summary, snakemake.output.summary)
    reduction = LS.reduction_flexion(pd.concat(list(curves.values()), ignore_index=True))
    write_table_atomic(reduction, snakemake.output.reduction)
    write_table_atomic(comp_summary, snakemake.output.compression)
    write_table_atomic(cables, snakemake.output.cables)
    neutral = cables[cables["load_case"] == "neutral"]
    log.info("load sharing: %d sets; L4-L5 under the cables (neutral, calibrated): disc share %s", len(curves),
             ", ".join(f"{r.muscle_setup} {r.disc_share:.2f}" for r in neutral.itertuples()))
