"""Muscle-driven model stage (paper 2): rules muscle_validation, muscle_sensitivity (one
Paramspace chunk), muscle_sensitivity_table, muscle_sobol_chunk (one posture, one chunk of the PCE
training samples) and muscle_sobol (indices and figure). The long jobs log progress lines through the library's
logger (lumbar.muscles.muscle_model: scenarios done / total, elapsed, estimated remaining), which setup_logging sends
to the rule's log and the console.

By hand: python workflow/scripts/muscle_model.py muscle_validation --configfile config/test/config.yaml
         python workflow/scripts/muscle_model.py muscle_sobol_chunk posture=standing chunk=0 \
    --configfile config/test/config.yaml      (the rule's wildcards as name=value; --output to redirect)
"""
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402


snakemake, log = _common.start(globals())

from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles.redundancy import PostureSolution  # noqa: E402

SAVE = dict(dpi=150, metadata={"Software": None})


def _plt():
    """pyplot on the Agg backend, imported by the jobs that draw (0.6-0.8 s of import the solve jobs skip)."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


def _model(p):
    # the passive set's folder: the folder of its declared tables (rule input passive; muscle_model.passive_set)
    d = Path(_common.as_list(snakemake.input.passive)[0]).parent
    return mm.LumbarMuscleModel(body_mass_kg=p["body_mass_kg"], passive_set=p["passive_set"], data_dir=d,
                                calibrated_dir=d,
                                symmetric_passive=p.get("symmetric_passive", True),
                                in_situ_posture=p.get("in_situ_posture", "reference"),
                                iap_force_n=p.get("iap_force_n", 0.0))


def _save(fig, path):
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(path).with_suffix(".tmp.png")
    fig.savefig(tmp, **SAVE)
    _plt().close(fig)
    tmp.replace(path)


def _load_baseline(path):
    z = np.load(path)
    out = {}
    for posture in mm.POSTURES:
        out[posture] = PostureSolution(z[f"{posture}_x"], z[f"{posture}_R"], z[f"{posture}_a"], True, True, 0.0,
                                       0.0, 0.0, 0.0, 0)
    return out


UNITS = {"ssl_um": "SSL [um]", "k_n_per_cm2": "K [N/cm2]", "in_situ_sl_um": "in-situ SL [um]",
         "spt_n_per_cm2": "SpT [N/cm2]", "pennation_deg": "pennation [deg]"}


POSTURE_TITLES = {"standing": "upright standing", "flexion": "36 deg flexion"}


def _sobol_figure(df, path):
    """S1 and ST per parameter with their bootstrap 95 % intervals (whiskers), one panel per posture; the panel
    title gives the method (PCE degree, model solves, leave-one-out Q2). Indices and intervals lie in [0, 1]."""
    posts = list(dict.fromkeys(df["posture"]))
    fig, axes = _plt().subplots(1, len(posts), figsize=(4.6 * len(posts), 4.2), squeeze=False, sharey=True,
                             layout="constrained")
    for ax, post in zip(axes[0], posts):
        d = df[df["posture"] == post]
        xs = np.arange(len(d))
        for off, key, lab, col in ((-0.2, "S1", "first-order index S1", "#4c72b0"),
                                   (0.2, "ST", "total index ST", "#dd8452")):
            v = d[key].to_numpy(float)
            lo, hi = d[f"{key}_lo"].to_numpy(float), d[f"{key}_hi"].to_numpy(float)
            ax.bar(xs + off, np.nan_to_num(v), 0.4, color=col, label=lab)
            ax.errorbar(xs + off, np.nan_to_num(v), yerr=[np.clip(np.nan_to_num(v - lo), 0, None),
                                                          np.clip(np.nan_to_num(hi - v), 0, None)],
                        fmt="none", ecolor="k", lw=0.8, capsize=2)
        ax.set_ylim(0, 1.05)
        ax.set_xticks(xs, [UNITS.get(q, q) for q in d["parameter"]], rotation=30, ha="right", fontsize=8)
        r = d.iloc[0]
        q2 = (f"{r['q2_loo']:.3f}" if np.isfinite(r["q2_loo"]) else "n/a") + ("" if r["fit_ok"] else " (poor fit)")
        ax.set_title(f"{POSTURE_TITLES.get(post, post)}: PCE degree {int(r['degree'])}, {int(r['n_train'])} model "
                     f"solves, Q2_loo = {q2}\n{int(r['n_failed'])} not reached (left out), {int(r['n_uncertified'])} "
                     f"not certified; top S1 interval width {r['top_s1_width']:.3f}", fontsize=8)
    axes[0, 0].set_ylabel("Sobol index of L4-L5 IDP [-]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=7,
               title="whiskers: bootstrap 95 % interval", title_fontsize=7)
    _save(fig, path)


def _warn_uncertified(what, which, table, statuses=()):
    """One WARNING per rule for reached postures whose optimum IPOPT could not certify: a reported value (a row of the
    validation or of the sensitivity study) that may not be the optimum; postures the muscles cannot reach are
    expected outcomes (red stars), counted in the rule's summary line. The Sobol chunks do not call this: their
    uncertified samples are kept in the expansion by design and counted in sobol_indices.csv (n_uncertified)."""
    if which:
        why = ", ".join(sorted({str(s) for s in statuses})) or "see ipopt_status"
        log.warning("%s: %d reached posture(s) whose optimum IPOPT could not certify (%s; certified=False in %s): "
                    "read them as equilibria that may not be the optimum. A larger muscle_model.solver."
                    "ipopt_max_iter helps where IPOPT was still converging; near the edge of the muscles' capacity "
                    "it may stall at any limit", what, len(which), why, table)


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
    _warn_uncertified("muscle_validation", [n for n, s in zip(names, sols) if s.reached and not s.certified],
                      snakemake.output.segment_loads, [s.ipopt_status for s in sols if s.reached and not s.certified])
    for n, s in zip(names, sols):
        log.info("%s: converged=%s reached=%s certified=%s KKT residual %.1e, residual %.1e N %.1e N*m, tracking "
                 "error %.3f deg, %d iterations %s", n, s.converged, s.reached, s.certified, s.kkt_residual,
                 s.residual_force_n, s.residual_moment_nm, s.tracking_error_deg, s.iterations, s.message)
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
                  "(25 % beyond SSL 2.8). Not tuned; docs/findings.md, Muscle-driven model.")
    write_table_atomic(seg[["level", "activity", "compressive_n", "shear_n", "moment_nm", "converged",
                            "lateral_moment_nm", "axial_moment_nm", "reached", "certified", "kkt_residual"]],
                       snakemake.output.segment_loads)
    write_table_atomic(val2, snakemake.output.validation)
    Path(snakemake.output.metrics).parent.mkdir(parents=True, exist_ok=True)
    Path(snakemake.output.metrics).write_text(json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    write_table_atomic(fr, snakemake.output.flexion_relaxation)
    log.info("in-vivo validation: %s", metrics)
    # Fig. 3 analog
    fig, ax = _plt().subplots(figsize=(6.5, 4))
    xs = np.arange(len(val2))
    ax.bar(xs - 0.2, val2["idp_force_mpa"], 0.4, color="#4c72b0", label="model: compressive force part")
    ax.bar(xs - 0.2, val2["idp_moment_mpa"], 0.4, bottom=val2["idp_force_mpa"], color="#8fb0d9",
           label="model: sagittal moment part")
    ax.bar(xs + 0.2, val2["idp_in_vivo_mpa"], 0.4, color="#555555", label="in vivo (Wilke et al.)")
    starred = False
    for k, ok in enumerate(val2["converged"]):
        if not ok:
            ax.plot(xs[k] - 0.2, val2["idp_sim_mpa"].iloc[k] + 0.05, "r*", ms=12, clip_on=False,
                    label=None if starred else "not converged (excluded from R2)")
            starred = True
    ax.set_ylim(0, 1.2 * max(val2["idp_sim_mpa"].max(), val2["idp_in_vivo_mpa"].max()) + 0.1)
    ax.set_xticks(xs, [a.replace("_", "\n") for a in val2["activity"]], fontsize=8)
    ax.set_ylabel("L4-L5 IDP [MPa]")
    r2 = metrics["r2"]
    ax.set_title(f"L4-L5 IDP, model vs in vivo (R2 = {r2:.2f}, n = {metrics['n']})" if r2 is not None
                 else "L4-L5 IDP, model vs in vivo (R2 undefined: < 3 converged)", fontsize=10)
    ax.legend(fontsize=7)
    _save(fig, snakemake.output.figure)
    base = {}
    for post, name in mm.POSTURES.items():
        s = sols[names.index(name)]
        base.update({f"{post}_x": s.x, f"{post}_R": s.R, f"{post}_a": s.a})
    tmp = Path(snakemake.output.baseline).with_suffix(".tmp.npz")
    np.savez(tmp, **base)
    tmp.replace(snakemake.output.baseline)
    contact = mm.facet_contact(model, sols, names)
    contact = contact[contact["activity"].isin(keep)]
    write_table_atomic(contact, snakemake.output.facet_contact)
    for lv, d in contact.groupby("level", sort=False):
        log.info("facets %s (set %s, %.3g N/m): rest gap %.2f mm; contact force per posture %s", lv, p["passive_set"],
                 d["facet_stiffness_n_per_m"].iat[0], d["rest_min_gap_mm"].min(),
                 {a: round(float(v), 1) for a, v in d.groupby("activity", sort=False)["contact_n"].sum().items()})
    fas = model.ms.table()
    fas["l_ref_m"] = model.props.l_ref_m
    fas["l_opt_m"] = model.props.l_opt_m
    write_table_atomic(fas, snakemake.output.fascicles)
    cap = mm.capacity_table(model, [s for n, s in zip(names, sols) if n in keep], keep)
    write_table_atomic(cap, snakemake.output.capacity)
    short = cap[(cap["pose"] == "own solution") & (cap["demand_ratio"] > 1.0)]
    for _, r in short.iterrows():
        log.info("%s, %s: external + passive muscle moment %.1f N*m exceeds the active extension capacity %.1f N*m "
                 "(ratio %.2f; SpT %.0f N/cm2 would be needed)", r["activity"], r["level"],
                 r["external_moment_nm"] + r["passive_muscle_moment_nm"], r["extension_capacity_nm"],
                 r["demand_ratio"], r["spt_needed_n_per_cm2"])
elif rule == "muscle_sensitivity":
    import time

    param, ssl = snakemake.wildcards.parameter, snakemake.wildcards.ssl_um
    s = p["sensitivity"]
    rows = mm.sensitivity_rows(param, None if ssl == "none" else float(ssl), s[param], s["scopes"], s["postures"])
    model = _model(p)
    solver = mm.make_solver(model, p["solver"])
    t0 = time.perf_counter()
    log.info("chunk %s (ssl %s): %d scenarios", param, ssl, len(rows))
    out = mm.run_sensitivity(model, solver, rows, _load_baseline(snakemake.input.baseline), p["disc_area_m2"],
                             label=f"sensitivity {param} (ssl {ssl})")
    log.info("chunk %s (ssl %s): %d scenarios in %.1f s, %d not reached, %d reached but not certified "
             "(max KKT residual %.1e)", param, ssl, len(out), time.perf_counter() - t0, int((~out["reached"]).sum()),
             int((out["reached"] & ~out["certified"]).sum()), out["kkt_residual"].max())
    unc = out["reached"] & ~out["certified"]
    _warn_uncertified(f"sensitivity chunk {param} (ssl {ssl})", list(out.index[unc]), snakemake.output[0],
                      out.loc[unc, "ipopt_status"])
    write_table_atomic(out, snakemake.output[0])
elif rule == "muscle_sensitivity_table":
    df = pd.concat([pd.read_csv(f) for f in snakemake.input.chunks], ignore_index=True)
    base = pd.read_csv(snakemake.input.baseline_table).set_index("activity")
    cols = ["parameter", "value", "ssl_um", "group_scope", "posture", "idp_mpa", "idp_force_mpa", "idp_moment_mpa",
            "converged", "reached", "certified", "kkt_residual", "ipopt_status", "tracking_error_deg", "extensor_active_n",
            "extensor_passive_n", "abdominal_active_n", "paper_change"]
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
    posts = list(p["sensitivity"]["postures"])
    for k, param in enumerate(mm.PARAMETERS):      # the order of the rule's figures output (the same constant)
        d = df[df["parameter"] == param]
        ssls = [x for x in d["ssl_um"].fillna(-1).unique()]
        unit = UNITS[param].split("[")[-1].rstrip("]")
        nrow = max(len(ssls) * len(posts), 1)
        fig, axes = _plt().subplots(nrow, 1, squeeze=False, figsize=(8.5, 0.6 + 2.5 * nrow), layout="constrained")
        fig.suptitle(f"L4-L5 IDP vs {UNITS[param]} per muscle-group scope. Bars: solid = compressive-force part, "
                     "hatched = sagittal-moment part;\ndashed line: baseline; red star: posture not reached; "
                     "open circle: reached, optimum not certified (KKT)", fontsize=8)
        r = 0
        for sv in ssls:
            for post in posts:
                ax = axes[r, 0]
                r += 1
                dd = d[(d["ssl_um"].fillna(-1) == sv) & (d["posture"] == post)]
                vals = sorted(dd["value"].unique())
                width = 0.8 / max(len(vals), 1)
                top = 0.0
                for j, v in enumerate(vals):
                    for si, sc in enumerate(scopes):
                        row = dd[(dd["value"] == v) & (dd["group_scope"] == sc)]
                        if row.empty:
                            continue
                        row = row.iloc[0]
                        xpos = si + (j - (len(vals) - 1) / 2) * width
                        ax.bar(xpos, row["idp_force_mpa"], width * 0.9, color=_plt().cm.viridis(j / max(len(vals) - 1, 1)),
                               label=f"{v:g} {unit}" if si == 0 else None)
                        ax.bar(xpos, row["idp_moment_mpa"], width * 0.9, bottom=row["idp_force_mpa"], color="none",
                               edgecolor="k", hatch="//", lw=0.4)
                        y = max(row["idp_mpa"], 0.0)
                        top = max(top, y)
                        if not row["reached"]:
                            ax.plot(xpos, y + 0.05, "r*", ms=9, clip_on=False)
                        elif not row.get("certified", row["converged"]):
                            ax.plot(xpos, y + 0.05, "o", ms=5, mfc="none", mec="0.4", clip_on=False)
                b = dd["baseline_idp_mpa"].iloc[0] if len(dd) else np.nan
                if np.isfinite(b):
                    ax.axhline(b, color="k", lw=1, ls="--", label="baseline")
                    top = max(top, b)
                ax.set_ylim(0, 1.15 * top + 0.12)
                ax.set_xticks(range(len(scopes)), scopes)
                ax.set_xlabel("muscle groups with the changed parameter", fontsize=7)
                ax.set_ylabel("L4-L5 IDP [MPa]")
                ax.set_title(f"{post}" + (f", SSL fixed at {sv:g} um" if sv != -1 else ""), fontsize=9, loc="left")
                ax.legend(fontsize=7, title=UNITS[param], title_fontsize=7, loc="upper left",
                          bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
        _save(fig, snakemake.output[1 + k])
elif rule == "muscle_sobol_chunk":
    import time

    posture, k = snakemake.wildcards.posture, int(snakemake.wildcards.chunk)
    sb = p["sobol"]
    X = mm.sobol_samples(sb["n_train"], snakemake.params.seed)
    rows = mm.sobol_chunk_rows(len(X), sb.get("chunks", 1), k)
    model = _model(p)
    solver = mm.make_solver(model, p["solver"])
    t0 = time.perf_counter()
    log.info("Sobol %s, chunk %d of %d: samples %d-%d of %d (PCE training design, n_train %d)", posture, k + 1,
             sb.get("chunks", 1), rows[0], rows[-1], len(X), sb["n_train"])
    out = mm.sobol_evaluate(model, solver, _load_baseline(snakemake.input.baseline), X, rows, posture, sb["scope"],
                            p["disc_area_m2"], label=f"sobol {posture} chunk {k + 1}/{sb.get('chunks', 1)}")
    # one summary line: samples not reached are left out of the expansion, reached but uncertified ones are kept
    # (n_failed / n_uncertified of sobol_indices.csv): results of the study, not something to act on
    unc = out["reached"] & ~out["certified"]
    log.info("Sobol %s chunk %d: %d samples in %.1f s, %d not reached, %d reached but not certified%s", posture, k + 1,
             len(out), time.perf_counter() - t0, int((~out["reached"]).sum()), int(unc.sum()),
             f" (IPOPT: {', '.join(sorted(set(out.loc[unc, 'ipopt_status'].astype(str))))}; kept in the expansion)"
             if unc.any() else "")
    write_table_atomic(out, snakemake.output[0])
elif rule == "muscle_sobol":
    import time

    sb = p["sobol"]
    samples = pd.concat([pd.read_csv(f) for f in snakemake.input.chunks], ignore_index=True)
    t0 = time.perf_counter()
    df = mm.sobol_indices(samples, sb["n_train"], sb["degree"], snakemake.params.seed, sb.get("n_bootstrap", 500))
    log.info("PCE fits and %d bootstrap refits per posture in %.1f s", sb.get("n_bootstrap", 500),
             time.perf_counter() - t0)
    for post, d in df.groupby("posture", sort=False):
        r = d.iloc[0]
        top = d[d["parameter"] == r["top_parameter"]]
        top = top.iloc[0] if len(top) else r
        log.info("Sobol %s: PCE degree %d on %d of %d samples, Q2_loo = %.3f%s; top first-order index %s S1 = %.3f "
                 "[%.3f, %.3f] (bootstrap 95 %%; width %.3f: %s), sum S1 = %.2f; %d not reached, %d not certified",
                 post, int(r["degree"]), int(r["n_fit"]), int(r["n_train"]), r["q2_loo"],
                 "" if r["fit_ok"] else f" < {mm.SOBOL_Q2_MIN} (poor fit)", top["parameter"], top["S1"],
                 top["S1_lo"], top["S1_hi"], r["top_s1_width"], "stable" if r["stable"] else "NOT stable",
                 d["S1"].sum(), int(r["n_failed"]), int(r["n_uncertified"]))
    write_table_atomic(df, snakemake.output[0])
    _sobol_figure(df, snakemake.output[1])
else:  # pragma: no cover
    raise ValueError(f"unknown rule {rule}")
