"""The calibration's output: the calibrated characteristic directory (role calibration.characteristics of the stage manifests) and the
analogs of paper 1's Tables 1-3 beside the paper's values."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from ...inputs import manifests
from ...inputs.io import write_table_atomic
from ..stepwise_reduction import MAIN_DIRECTIONS
from .disc import DISC_STAGE
from .prior import PRIOR_SOURCE
from .stepwise import FACET_STAGE, LIGAMENT_STAGE, CalibrationResult


def write_characteristics(result: CalibrationResult, src_dir, out_dir, reference_source: str = "") -> Path:
    """Copy ``src_dir`` (data/characteristics) to ``out_dir`` with the calibrated rows replaced.

    disc.csv torque rows and facet.csv stiffness (shared by all sets in that directory) and the
    ``calibrated`` rows of ligaments_softplus.csv get kind ``calibrated_on_<data kind>``; the paper's
    'SSL neg.' alternative row is dropped (it belongs to the paper's calibration, not this one).
    ``load_characteristic_set("calibrated", data_dir=out_dir)`` loads the result.
    """
    src, out = Path(src_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kind = "calibrated_on_measured" if result.data_kind == "measured" else "calibrated_on_surrogate"
    # provenance text written into the result tables: names the function that made them
    src_note = f"lumbar.experiments.calibration.calibrate on {reference_source or 'the stepwise-reduction reference table'}"
    for f in sorted(src.glob("*.csv")):
        if f.name not in ("disc.csv", "facet.csv", "ligaments_softplus.csv"):
            shutil.copyfile(f, out / f.name)
    disc = pd.read_csv(src / "disc.csv", dtype=str, keep_default_na=False)
    for i, r in disc.iterrows():
        if r["parameter"] in ("torque_p1", "torque_p2", "torque_p3") and r["direction"] in result.disc:
            k = int(r["parameter"][-1]) - 1
            disc.loc[i, "value"] = repr(float(result.disc[r["direction"]][k]))
            disc.loc[i, ["kind", "source"]] = [kind, src_note]
            disc.loc[i, "note"] = f"Eq. 3 fitted (trf) to T(ROM_mean) = M on stage {DISC_STAGE}" + (
                f"; p1 and p3 then scaled by the admissible fit (disc_torque posterior, "
                f"{manifests.path('calibration', 'posterior')})" if result.info.get("final_fit") is not None and
                result.info["final_fit"].posterior is not None else "")
    ks = getattr(result.charset.disc, "k_shear", None)
    if ks is not None and "real_fit" in result.info:
        disc = disc[disc["parameter"] != "shear_stiffness"]
        disc = pd.concat([disc, pd.DataFrame([{
            "parameter": "shear_stiffness", "direction": "shear", "value": repr(float(ks)), "unit": "N/m", "kind": kind,
            "source": src_note, "note": "fitted within the sourced range shear_stiffness_min..max on the real "
                                        "target rows (lumbar.experiments.calibration.fit_real_targets)"}])], ignore_index=True)
    write_table_atomic(disc, out / "disc.csv")
    fac = pd.read_csv(src / "facet.csv", dtype=str, keep_default_na=False)
    for i, r in fac.iterrows():
        if r["parameter"] == "stiffness":
            fac.loc[i, ["value", "unit", "kind", "source"]] = [repr(float(result.facet_stiffness)), "N/m", kind, src_note]
            fac.loc[i, "note"] = f"1-parameter fit on stage {FACET_STAGE} (facets removed with the vertebral arch)"
    write_table_atomic(fac, out / "facet.csv")
    sp = pd.read_csv(src / "ligaments_softplus.csv", dtype=str, keep_default_na=False)
    sp = sp[sp["set"] != "calibrated"]
    new = []
    for kind_l, law in result.charset.ligaments.items():
        if not hasattr(law, "a"):
            continue
        on_elongation = law.law_length_m is not None
        note = ("Eq. 7 on elongation in percent of law_length (calibrated with lumbar.experiments.calibration."
                "fit_admissible: force scale and pre-elongation of the prior law, real targets and admissibility)"
                if on_elongation else
                f"Eq. 7 (a,b,d fitted, c = -a*ln(1+exp(b/d)) so F(0)=0) on stage {LIGAMENT_STAGE.get(kind_l, '?')}; "
                "no ITL row (ITL absent, as Table 3)")
        values = [(p, v, {"a": "N", "b": "%", "c": "N", "d": "%"}[p])
                  for p, v in zip("abcd", (law.a, law.b, law.c, law.d))]
        if on_elongation:
            values += [("law_length", law.law_length_m * 1e3, "mm"), ("prestrain", law.prestrain_pct, "%")]
        for p, v, unit in values:
            new.append({"set": "calibrated", "ligament": kind_l, "variant": "primary", "parameter": p,
                        "value": repr(float(v)), "unit": unit, "kind": kind, "source": src_note, "note": note})
    write_table_atomic(pd.concat([pd.DataFrame(new), sp], ignore_index=True), out / "ligaments_softplus.csv")
    return out


def _fit_not_converged(result: CalibrationResult, structure: str) -> int:
    """Scenarios of the calibration step fitting ``structure`` that had no equilibrium at the fitted values:
    a table value fitted on them is marked (column ``fit_not_converged`` > 0) instead of looking clean."""
    s = result.summary
    if s is None or "structure" not in getattr(s, "columns", ()):
        return 0
    sel = s[s["structure"] == structure]
    return int(pd.to_numeric(sel["n_not_converged"], errors="coerce").fillna(0).sum())


def table1(result: CalibrationResult, paper) -> pd.DataFrame:
    rows = []
    for d in MAIN_DIRECTIONS:
        p, q = result.disc[d], paper.disc.torque[d]
        rows.append({"direction": d, "p1_nm": p[0], "p2_rad3": p[1], "p3_nm_per_rad": p[2],
                     "paper_p1_nm": q[0], "paper_p2_rad3": q[1], "paper_p3_nm_per_rad": q[2],
                     "fit_stage": DISC_STAGE, "fit_not_converged": _fit_not_converged(result, f"disc:{d}"),
                     "data_kind": result.data_kind})
    return pd.DataFrame(rows)


def table2(result: CalibrationResult, paper) -> pd.DataFrame:
    rows = []
    fs = result.facet_surfaces
    for p in ("p30", "p03", "p20", "p02", "p00"):
        r = {"parameter": p}
        for side in ("left", "right"):
            sel = fs[(fs["parameter"] == p) & (fs["side"] == side)]
            r[f"{side}"] = float(sel["value"].iloc[0]) if len(sel) else np.nan
            r["unit"] = sel["unit"].iloc[0] if len(sel) else ""
            r[f"paper_{side}"] = paper.facet.surface_paper.get(side, {}).get(p, np.nan)
        r["note"] = ("project geometry, fitted local frame (u ~ superior, w = joint normal), mm; paper's "
                     "values are in the paper's own frame (comparison only)")
        r["data_kind"] = "geometry"
        rows.append(r)
    rows.append({"parameter": "stiffness", "left": result.facet_stiffness, "right": result.facet_stiffness,
                 "unit": "N/m", "paper_left": paper.facet.stiffness, "paper_right": paper.facet.stiffness,
                 "note": f"Eq. 5 c_stiff fitted on stage {FACET_STAGE}", "data_kind": result.data_kind})
    return pd.DataFrame(rows)


def table3(result: CalibrationResult, paper) -> pd.DataFrame:
    """Table 3 analog: the calibrated Eq. 7 laws beside the paper's. For laws on elongation also the law length
    [mm] (the length their percent strain refers to), the pre-elongation at the reference geometry [mm], the force
    scale relative to the calibration's prior law and the prior's source."""
    rows = []
    prior = result.info.get("prior_set")
    for k, law in result.charset.ligaments.items():
        if not hasattr(law, "a"):
            continue
        q = paper.ligaments.get(k)
        pr = prior.ligaments.get(k) if prior is not None else None
        rows.append({"ligament": k, "a_n": law.a, "b_pct": law.b, "c_n": law.c, "d_pct": law.d,
                     "prestrain_pct": law.prestrain_pct,
                     "law_length_mm": law.law_length_m * 1e3 if law.law_length_m is not None else np.nan,
                     "pre_elongation_mm": law.pre_elongation_m * 1e3 if law.law_length_m is not None else np.nan,
                     "force_scale_vs_prior": law.a / pr.a if pr is not None and pr.a else np.nan,
                     "prior": PRIOR_SOURCE.get(k, ("", ""))[1] if pr is not None else "",
                     "fit_stage": LIGAMENT_STAGE.get(k, "real targets + admissibility"),
                     "paper_a_n": getattr(q, "a", np.nan), "paper_b_pct": getattr(q, "b", np.nan),
                     "paper_c_n": getattr(q, "c", np.nan), "paper_d_pct": getattr(q, "d", np.nan),
                     "fit_not_converged": _fit_not_converged(result, k), "data_kind": result.data_kind})
    return pd.DataFrame(rows)
