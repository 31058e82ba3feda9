"""Load-sharing stage, rule load_sharing_summary: the tables at 10 N*m and at rest, the flexion reduction, the
compression shares, the L4-L5 load paths under the Table 5 wire cables, and two figures (lumbar.plots.load_sharing).

By hand: python workflow/scripts/load_sharing_summary.py load_sharing_summary --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import load_sharing as LS  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots.load_sharing import plot_curves, plot_shares  # noqa: E402


def main(snakemake, log):
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
    plot_curves(curves, ref, snakemake.output.curves_figure, bands=pd.read_csv(snakemake.input.bands))
    if "calibrated" in curves:
        plot_shares(curves["calibrated"], snakemake.output.shares_figure,
                    title=f"Moment carried by each structure, calibrated {lvl} unit (below 0: acting with the applied "
                    "moment; upper stack minus lower stack = the applied moment, dashed)")
    else:
        first = next(iter(curves))
        plot_shares(curves[first], snakemake.output.shares_figure)
    write_table_atomic(summary, snakemake.output.summary)
    reduction = LS.reduction_flexion(pd.concat(list(curves.values()), ignore_index=True))
    write_table_atomic(reduction, snakemake.output.reduction)
    write_table_atomic(comp_summary, snakemake.output.compression)
    write_table_atomic(cables, snakemake.output.cables)
    neutral = cables[cables["load_case"] == "neutral"]
    log.info("load sharing: %d sets; L4-L5 under the cables (neutral, calibrated): disc share %s", len(curves),
             ", ".join(f"{r.muscle_setup} {r.disc_share:.2f}" for r in neutral.itertuples()))

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
