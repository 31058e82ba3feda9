"""Muscle-driven model (paper 2), rule muscle_sensitivity_table: the sensitivity chunks as one table with the change
from the baseline IDP, paper 2's sensitivity claims read against it (lumbar.muscles.reproduction), and one figure per
parameter
(lumbar.plots.muscle_model.plot_sensitivity).

By hand: python workflow/scripts/muscle_sensitivity_table.py muscle_sensitivity_table --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.muscles import muscle_sensitivity as sens  # noqa: E402
from lumbar.plots.muscle_model import plot_sensitivity  # noqa: E402


def main(snakemake, log):
    p = snakemake.params.muscle_model
    df = pd.concat([pd.read_csv(f) for f in snakemake.input.chunks], ignore_index=True)
    base = pd.read_csv(snakemake.input.baseline_table).set_index("activity")
    cols = ["parameter", "value", "ssl_um", "group_scope", "posture", "idp_mpa", "idp_force_mpa", "idp_moment_mpa",
            "converged", "reached", "certified", "kkt_residual", "ipopt_status", "tracking_error_deg", "extensor_active_n",
            "extensor_passive_n", "abdominal_active_n", "paper_claims"]
    df = df[cols].copy()
    df["baseline_idp_mpa"] = [base.loc[mm.POSTURES[q], "idp_sim_mpa"] if mm.POSTURES[q] in base.index else np.nan
                              for q in df["posture"]]
    df["change_pct"] = 100 * (df["idp_mpa"] / df["baseline_idp_mpa"] - 1)
    write_table_atomic(df, snakemake.output[0])
    # one WARNING for the study (each chunk's log line counts its own): uncertified scenarios are in the figures
    unc = df["reached"].astype(bool) & ~df["certified"].astype(bool)
    warning = mm.uncertified_message(
        f"muscle sensitivity study ({len(df)} scenarios in {len(snakemake.input.chunks)} chunks; by posture: "
        + ", ".join(f"{q} {int(n)}" for q, n in df.loc[unc, "posture"].value_counts().sort_index().items()) + ")",
        list(df.index[unc]), snakemake.output[0], df.loc[unc, "ipopt_status"])
    if warning:
        log.warning("%s", warning)
    dirs = sens.sensitivity_directions(df, pd.read_csv(snakemake.input.baseline_table))
    write_table_atomic(dirs, snakemake.output[-1])
    for cls, d in dirs.groupby("claim_class", sort=False):
        log.info("paper 2's %s claims: %d reproduced, %d direction only, %d not reproduced, %d not comparable", cls,
                 int((d["verdict"] == "reproduced").sum()), int((d["verdict"] == "direction only").sum()),
                 int((d["verdict"] == "not reproduced").sum()), int((d["verdict"] == "not comparable").sum()))
    scopes = list(p["sensitivity"]["scopes"])
    posts = list(p["sensitivity"]["postures"])
    for k, param in enumerate(mm.PARAMETERS):      # the order of the rule's figures output (the same constant)
        plot_sensitivity(df, param, scopes, posts, snakemake.output[1 + k])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
