"""Muscle-driven model stage (paper 2, issue 5): rules muscle_validation, muscle_sensitivity (one
Paramspace chunk), muscle_sensitivity_table and muscle_sobol.

By hand: python workflow/scripts/muscle_model.py muscle_validation --configfile config/test/config.yaml
    (outputs as in workflow/rules/muscle_model.smk; --output to redirect)
"""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pandas as pd

_spec = importlib.util.spec_from_file_location("_common", Path(__file__).resolve().parent / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)

OUT = "results/muscle_model"
BASELINE = f"{OUT}/baseline.npz"
VALIDATION_OUT = ["results/tables/muscle_model_segment_loads.csv", "results/tables/in_vivo_validation.csv",
                  f"{OUT}/in_vivo_metrics.json", "results/tables/flexion_relaxation.csv",
                  "results/figures/muscle_in_vivo_validation.png", BASELINE, "results/tables/muscle_fascicles.csv",
                  "results/tables/muscle_capacity.csv"]
FIGURE_PARAMETERS = ("ssl_um", "k_n_per_cm2", "in_situ_sl_um", "spt_n_per_cm2", "pennation_deg")


RULES = {
    "muscle_validation": lambda c: dict(
        input=dict(in_vivo=c["muscle_model"]["in_vivo_table"]), output=VALIDATION_OUT,
        params=dict(muscle_model=c["muscle_model"], published=c["paths"]["published_model_results"])),
    "muscle_sensitivity": lambda c: dict(
        input=dict(baseline=BASELINE), output=[f"{OUT}/sensitivity/parameter~ssl_um_ssl_um~none.csv"],
        params=dict(muscle_model=c["muscle_model"], chunk={"parameter": "ssl_um", "ssl_um": "none"})),
    "muscle_sensitivity_table": lambda c: dict(
        input=dict(chunks=sorted(str(f) for f in Path(OUT, "sensitivity").glob("*.csv")),
                   baseline_table="results/tables/in_vivo_validation.csv"),
        output=["results/tables/sensitivity_idp.csv"]
        + [f"results/figures/muscle_sensitivity_{p}.png" for p in FIGURE_PARAMETERS]
        + ["results/tables/sensitivity_directions.csv"],
        params=dict(muscle_model=c["muscle_model"])),
    "muscle_sobol": lambda c: dict(
        input=dict(baseline=BASELINE), output=["results/tables/sobol_indices.csv", "results/figures/muscle_sobol.png"],
        params=dict(muscle_model=c["muscle_model"], seed=c["seed"])),
}

if "snakemake" not in globals():
    snakemake = _common.stand_in(RULES, __doc__)

log = _common.setup_logging(snakemake)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from lumbar import muscle_model as mm  # noqa: E402
from lumbar.io import write_table_atomic  # noqa: E402
from lumbar.muscles.redundancy import PostureSolution  # noqa: E402

SAVE = dict(dpi=150, metadata={"Software": None})


def _model(p):
    return mm.LumbarMuscleModel(body_mass_kg=p["body_mass_kg"], characteristics=p["characteristics"],
                                symmetric_passive=p.get("symmetric_passive", True),
                                in_situ_posture=p.get("in_situ_posture", "reference"),
                                iap_force_n=p.get("iap_force_n", 0.0))


def _save(fig, path):
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(path).with_suffix(".tmp.png")
    fig.savefig(tmp, **SAVE)
    plt.close(fig)
    tmp.replace(path)


def _load_baseline(path):
    z = np.load(path)
    out = {}
    for posture in mm.POSTURES:
        out[posture] = PostureSolution(z[f"{posture}_x"], z[f"{posture}_R"], z[f"{posture}_a"], True, True, 0.0,
                                       0.0, 0.0, 0.0, 0)
    return out


rule = snakemake.rule
p = snakemake.params.muscle_model
if rule == "muscle_validation":
    import time

    model = _model(p)
    solver = mm.make_solver(model, p["solver"])
    names = list(p["activities"])
    for post in mm.POSTURES.values():          # the baseline postures of the sweep are always solved
        if post not in names:
            names.append(post)
    t0 = time.perf_counter()
    sols = mm.solve_postures(model, solver, names)
    log.info("%d activities solved in %.1f s; converged: %s", len(names), time.perf_counter() - t0,
             {n: s.converged for n, s in zip(names, sols)})
    for n, s in zip(names, sols):
        log.info("%s: converged=%s residual %.1e N %.1e N*m tracking error %.3f deg, %d iterations %s", n,
                 s.converged, s.residual_force_n, s.residual_moment_nm, s.tracking_error_deg, s.iterations,
                 s.message)
    seg, val, metrics = mm.validation(model, sols, names, mm.read_in_vivo(snakemake.input.in_vivo), p["disc_area_m2"])
    keep = [n for n in names if n in p["activities"]]
    seg = seg[seg["activity"].isin(keep)]
    val = val[val["activity"].isin(keep)]
    _, val2, metrics = mm.validation(model, [s for n, s in zip(names, sols) if n in keep], keep,
                                     mm.read_in_vivo(snakemake.input.in_vivo), p["disc_area_m2"])
    fr = mm.flexion_relaxation(model, sols, names)
    fr = fr[fr["activity"].isin(list(mm.POSTURES.values()))].copy()
    paper = {"upright_standing": (206.0, 0.0, 4.0), "flexion_36deg": (44.0, 334.0, 371.0)}
    fr["paper_extensor_active_n"] = [paper[a][0] for a in fr["activity"]]
    fr["paper_extensor_passive_n"] = [paper[a][1] for a in fr["activity"]]
    fr["paper_abdominal_active_n"] = [paper[a][2] for a in fr["activity"]]
    fr["paper_source"] = "paraspinal_muscle_properties_spinal_loading.md, Sect. 3.1 (original_text)"
    fr["note"] = ("as the paper (Sect. 2.1): pelvis fixed, all 36 deg of thorax rotation in L1-S1; SL = in-situ SL x "
                  "fibre length / its length in the as-segmented myo-sim posture (Christophy 2012 normalisation; "
                  "optimal fibre and path lengths within 3 % of Christophy's table; MuJoCo wrapping changes extensor "
                  "lengths by < 3 mm). Extensor fibres stretch ~20-30 % from in-situ 2.2-2.4 um and reach only the "
                  "toe of the passive curve; 334 N over the extensors' PCSA would need SL ~3.5 um in all of them "
                  "(25 % beyond SSL 2.8). Not tuned; README, Muscle-driven model.")
    write_table_atomic(seg[["level", "activity", "compressive_n", "shear_n", "moment_nm", "converged",
                            "lateral_moment_nm", "axial_moment_nm"]], snakemake.output[0])
    write_table_atomic(val2, snakemake.output[1])
    Path(snakemake.output[2]).parent.mkdir(parents=True, exist_ok=True)
    Path(snakemake.output[2]).write_text(json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    write_table_atomic(fr, snakemake.output[3])
    log.info("in-vivo validation: %s", metrics)
    # Fig. 3 analog
    fig, ax = plt.subplots(figsize=(6.5, 4))
    xs = np.arange(len(val2))
    ax.bar(xs - 0.2, val2["idp_force_mpa"], 0.4, color="#4c72b0", label="model: compressive force part")
    ax.bar(xs - 0.2, val2["idp_moment_mpa"], 0.4, bottom=val2["idp_force_mpa"], color="#8fb0d9",
           label="model: sagittal moment part")
    ax.bar(xs + 0.2, val2["idp_in_vivo_mpa"], 0.4, color="#555555", label="in vivo (Wilke et al.)")
    starred = False
    for k, ok in enumerate(val2["converged"]):
        if not ok:
            ax.plot(xs[k] - 0.2, val2["idp_sim_mpa"].iloc[k] + 0.05, "r*", ms=12,
                    label=None if starred else "not converged (excluded from R2)")
            starred = True
    ax.set_xticks(xs, [a.replace("_", "\n") for a in val2["activity"]], fontsize=8)
    ax.set_ylabel("L4-L5 IDP [MPa]")
    r2 = metrics["r2"]
    ax.set_title(f"L4-L5 IDP, model vs in vivo (R2 = {r2:.2f}, n = {metrics['n']})" if r2 is not None
                 else "L4-L5 IDP, model vs in vivo (R2 undefined: < 3 converged)", fontsize=10)
    ax.legend(fontsize=7)
    _save(fig, snakemake.output[4])
    base = {}
    for post, name in mm.POSTURES.items():
        s = sols[names.index(name)]
        base.update({f"{post}_x": s.x, f"{post}_R": s.R, f"{post}_a": s.a})
    tmp = Path(snakemake.output[5]).with_suffix(".tmp.npz")
    np.savez(tmp, **base)
    tmp.replace(snakemake.output[5])
    fas = model.ms.table()
    fas["l_ref_m"] = model.props.l_ref_m
    fas["l_opt_m"] = model.props.l_opt_m
    write_table_atomic(fas, snakemake.output[6])
    cap = mm.capacity_table(model, [s for n, s in zip(names, sols) if n in keep], keep)
    write_table_atomic(cap, snakemake.output[7])
    short = cap[(cap["pose"] == "own solution") & (cap["demand_ratio"] > 1.0)]
    for _, r in short.iterrows():
        log.info("%s, %s: external + passive muscle moment %.1f N*m exceeds the active extension capacity %.1f N*m "
                 "(ratio %.2f; SpT %.0f N/cm2 would be needed)", r["activity"], r["level"],
                 r["external_moment_nm"] + r["passive_muscle_moment_nm"], r["extension_capacity_nm"],
                 r["demand_ratio"], r["spt_needed_n_per_cm2"])
elif rule == "muscle_sensitivity":
    import time

    chunk = getattr(snakemake.wildcards, "parameter", None)
    if chunk is not None:
        param, ssl = snakemake.wildcards.parameter, snakemake.wildcards.ssl_um
    else:
        param, ssl = snakemake.params.chunk["parameter"], snakemake.params.chunk["ssl_um"]
    s = p["sensitivity"]
    rows = mm.sensitivity_rows(param, None if ssl == "none" else float(ssl), s[param], s["scopes"], s["postures"])
    model = _model(p)
    solver = mm.make_solver(model, p["solver"])
    t0 = time.perf_counter()
    out = mm.run_sensitivity(model, solver, rows, _load_baseline(snakemake.input.baseline), p["disc_area_m2"])
    log.info("chunk %s (ssl %s): %d scenarios in %.1f s, %d not converged", param, ssl, len(out),
             time.perf_counter() - t0, int((~out["converged"]).sum()))
    write_table_atomic(out, snakemake.output[0])
elif rule == "muscle_sensitivity_table":
    df = pd.concat([pd.read_csv(f) for f in snakemake.input.chunks], ignore_index=True)
    base = pd.read_csv(snakemake.input.baseline_table).set_index("activity")
    cols = ["parameter", "value", "ssl_um", "group_scope", "posture", "idp_mpa", "idp_force_mpa", "idp_moment_mpa",
            "converged", "reached", "tracking_error_deg", "extensor_active_n", "extensor_passive_n", "abdominal_active_n",
            "paper_change"]
    df = df[cols].copy()
    df["baseline_idp_mpa"] = [base.loc[mm.POSTURES[q], "idp_sim_mpa"] if mm.POSTURES[q] in base.index else np.nan
                              for q in df["posture"]]
    df["change_pct"] = 100 * (df["idp_mpa"] / df["baseline_idp_mpa"] - 1)
    write_table_atomic(df, snakemake.output[0])
    dirs = mm.sensitivity_directions(df)
    write_table_atomic(dirs, snakemake.output[-1])
    log.info("paper statements reproduced in direction: %d of %d (%d reached postures with uncertified optimum)",
             int(dirs["agrees"].sum()), len(dirs), int((dirs["reached"] & ~dirs["certified"]).sum()))
    scopes = list(p["sensitivity"]["scopes"])
    for k, param in enumerate(FIGURE_PARAMETERS):
        d = df[df["parameter"] == param]
        ssls = [x for x in d["ssl_um"].fillna(-1).unique()]
        fig, axes = plt.subplots(len(ssls) * len(p["sensitivity"]["postures"]), 1, squeeze=False,
                                 figsize=(8, 2.6 * len(ssls) * len(p["sensitivity"]["postures"])))
        r = 0
        for sv in ssls:
            for post in p["sensitivity"]["postures"]:
                ax = axes[r, 0]
                r += 1
                dd = d[(d["ssl_um"].fillna(-1) == sv) & (d["posture"] == post)]
                vals = sorted(dd["value"].unique())
                width = 0.8 / max(len(vals), 1)
                for j, v in enumerate(vals):
                    for si, sc in enumerate(scopes):
                        row = dd[(dd["value"] == v) & (dd["group_scope"] == sc)]
                        if row.empty:
                            continue
                        row = row.iloc[0]
                        xpos = si + (j - (len(vals) - 1) / 2) * width
                        ax.bar(xpos, row["idp_force_mpa"], width * 0.9, color=plt.cm.viridis(j / max(len(vals) - 1, 1)),
                               label=f"{v:g}" if si == 0 else None)
                        ax.bar(xpos, row["idp_moment_mpa"], width * 0.9, bottom=row["idp_force_mpa"], color="none",
                               edgecolor="k", hatch="//", lw=0.4)
                        if not row["reached"]:
                            ax.plot(xpos, max(row["idp_mpa"], 0) + 0.05, "r*", ms=9)
                        elif not row["converged"]:
                            ax.plot(xpos, max(row["idp_mpa"], 0) + 0.05, "o", ms=5, mfc="none", mec="0.4")
                b = dd["baseline_idp_mpa"].iloc[0] if len(dd) else np.nan
                if np.isfinite(b):
                    ax.axhline(b, color="k", lw=1, ls="--", label="baseline")
                ax.set_xticks(range(len(scopes)), scopes)
                ax.set_ylabel("L4-L5 IDP [MPa]")
                ttl = f"{param} ({post}" + (f", SSL {sv:g} um)" if sv != -1 else ")")
                ax.set_title(ttl + "; solid: force part, hatched: moment part; red star: not reached; "
                             "open circle: reached, optimum not certified", fontsize=8)
                ax.legend(fontsize=6, ncol=7, loc="upper left")
        fig.tight_layout()
        _save(fig, snakemake.output[1 + k])
elif rule == "muscle_sobol":
    import time

    model = _model(p)
    solver = mm.make_solver(model, p["solver"])
    t0 = time.perf_counter()
    df = mm.sobol_study(model, solver, _load_baseline(snakemake.input.baseline), p["sobol"]["n_base"],
                        snakemake.params.seed, p["sobol"]["scope"], tuple(p["sensitivity"]["postures"]),
                        p["disc_area_m2"])
    log.info("Sobol: %d samples per posture in %.1f s; failed: %s", int(df["n_samples"].iloc[0]),
             time.perf_counter() - t0, df.groupby("posture")["n_failed"].first().to_dict())
    write_table_atomic(df, snakemake.output[0])
    fig, axes = plt.subplots(1, df["posture"].nunique(), figsize=(8, 3.2), squeeze=False)
    for ax, (post, d) in zip(axes[0], df.groupby("posture", sort=False)):
        xs = np.arange(len(d))
        ax.bar(xs - 0.2, d["S1"], 0.4, yerr=d["S1_conf"], label="first order S1")
        ax.bar(xs + 0.2, d["ST"], 0.4, yerr=d["ST_conf"], label="total ST")
        ax.set_xticks(xs, d["parameter"], rotation=30, fontsize=7)
        ax.set_title(f"{post}: N = {int(d['n_samples'].iloc[0])} samples, {int(d['n_failed'].iloc[0])} not reached, "
                     f"{int(d['n_uncertified'].iloc[0])} optimum not certified",
                     fontsize=8)
        ax.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, snakemake.output[1])
else:  # pragma: no cover
    raise ValueError(f"unknown rule {rule}")
