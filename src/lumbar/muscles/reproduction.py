"""Paper 2 reproduced claim by claim: every quantitative or directional statement of its Results, Discussion and
abstract (``data/paper2/paper2_claims_original_text.csv``, each with its quote) against this project's results, for
each model variant (the reproduction model and the calibrated passive chain).

Verdicts (:func:`verdict`):

* ``reproduced``: a value or change of the same sign within x1.5 of the paper's (``value``, ``change``,
  ``change_between``); a bound met (``abs_max``: |ours| <= tolerance; ``at_most``); the same reachability
  (``not_reached``, ``reached``); an increase above the tolerance (``increase``); ``increase_most``: an increase above
  the tolerance in at least 3 of the 4 scopes; ``greater``: flexion's mean |change| above standing's;
* ``direction only``: the same sign but outside x1.5 (value and change claims only);
* ``not reproduced``: otherwise;
* ``not comparable``: the claim cannot be read against this variant, with the reason (the scope is not stated, the
  scenario was not run or its optimum is not certified, the source data are not available here).

Only certified optima count as ours: a reached posture whose optimum IPOPT could not certify is not comparable, a
posture not reached is "not reached" (the paper's red star).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs import resources

CLAIMS_CSV = resources.data_dir() / "paper2" / "paper2_claims_original_text.csv"
VERDICTS = ("reproduced", "direction only", "not reproduced", "not comparable")
COMPARISONS = ("value", "change", "change_between", "abs_max", "at_most", "not_reached", "reached", "increase",
               "increase_most", "greater", "within_range")
FACTOR = 1.5
POSTURE_ACTIVITY = {"standing": "upright_standing", "flexion": "flexion_36deg"}
SCOPES = ("MUL", "EXT", "EXT+PS", "ALL")


def read_claims(path=None) -> pd.DataFrame:
    """The claims table, checked (file, row, column and expected form in every error)."""
    path = Path(path) if path is not None else CLAIMS_CSV
    df = pd.read_csv(path, dtype={"value": str, "ssl_um": str, "scope": str, "paper_value": str, "tolerance": str},
                     keep_default_na=False)
    need = {"claim_id", "claim_class", "quantity", "posture", "parameter", "value", "ssl_um", "scope", "paper_value",
            "comparison", "tolerance", "quote", "kind", "source"}
    miss = need - set(df.columns)
    if miss:
        raise ValueError(f"{path}: missing columns {sorted(miss)}")
    if df["claim_id"].duplicated().any():
        raise ValueError(f"{path}: duplicate claim_id {sorted(df.loc[df['claim_id'].duplicated(), 'claim_id'])}")
    for i, r in df.iterrows():
        if r["comparison"] not in COMPARISONS:
            raise ValueError(f"{path} row {i + 2}: column 'comparison' must be one of {COMPARISONS}, got "
                             f"{r['comparison']!r}")
        if r["kind"] != "original_text" or not r["quote"].strip():
            raise ValueError(f"{path} row {i + 2}: every claim needs kind original_text and its quote")
    return df


def _num(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return np.nan


def verdict(comparison, ours, paper, tolerance=np.nan) -> str:
    """The verdict of one comparable claim (module doc); ``ours`` NaN -> not reproduced."""
    if comparison in ("value", "change", "change_between"):
        if not np.isfinite(ours):
            return "not reproduced"
        if paper == 0:
            return "reproduced" if ours == 0 else "not reproduced"
        if np.sign(ours) != np.sign(paper):
            return "not reproduced"
        r = ours / paper
        return "reproduced" if 1.0 / FACTOR <= r <= FACTOR else "direction only"
    if comparison == "abs_max":
        return "reproduced" if np.isfinite(ours) and abs(ours) <= tolerance else "not reproduced"
    if comparison == "at_most":
        return "reproduced" if np.isfinite(ours) and ours <= tolerance else "not reproduced"
    if comparison in ("increase", "increase_most"):
        return "reproduced" if np.isfinite(ours) and ours > tolerance else "not reproduced"
    if comparison == "greater":
        return "reproduced" if np.isfinite(ours) and ours > 1.0 else "not reproduced"
    raise ValueError(f"verdict: comparison {comparison!r} has no numeric rule")


class _Results:
    """This variant's result tables, as the claims read them."""

    def __init__(self, validation, metrics, segment_loads, flexion_relaxation, sensitivity=None):
        self.val = validation.set_index("activity")
        self.metrics = metrics
        self.seg = segment_loads
        self.fr = flexion_relaxation.set_index("activity")
        self.sens = sensitivity

    def activity_state(self, activity):
        if activity not in self.val.index:
            return None
        r = self.val.loc[activity]
        return bool(r["reached"]), bool(r["certified"])

    def sweep(self, parameter, value, ssl, scope, posture):
        if self.sens is None:
            return None
        d = self.sens
        m = (d["parameter"] == parameter) & np.isclose(d["value"].astype(float), value) & \
            (d["group_scope"] == scope) & (d["posture"] == posture)
        m &= d["ssl_um"].isna() if ssl is None else np.isclose(d["ssl_um"].astype(float), ssl)
        d = d[m]
        return None if d.empty else d.iloc[0]


def _baseline_idp(res: _Results, posture):
    st = res.activity_state(POSTURE_ACTIVITY[posture])
    if st is None or not st[1]:
        return np.nan
    return float(res.val.loc[POSTURE_ACTIVITY[posture], "idp_sim_mpa"])


def _scenario(res, parameter, value, ssl, scope, posture):
    """(ours change %, ours IDP, reached, certified, reason) of one one-at-a-time scenario."""
    if res.sens is None:
        return np.nan, np.nan, False, False, "the sensitivity sweep is not run on this variant"
    r = res.sweep(parameter, value, ssl, scope, posture)
    if r is None:
        return np.nan, np.nan, False, False, "scenario not in this run's sweep (config muscle_model.sensitivity)"
    return float(r["change_pct"]), float(r["idp_mpa"]), bool(r["reached"]), bool(r["certified"]), ""


def evaluate_claim(c, res: _Results) -> dict:
    """ours, reached, certified, verdict and reason of one claim row ``c``."""
    out = {"ours": np.nan, "reached": np.nan, "certified": np.nan, "verdict": "not comparable", "reason": ""}
    comp, q, post = c["comparison"], c["quantity"], c["posture"]
    paper, tol = _num(c["paper_value"]), _num(c["tolerance"])
    ssl = None if c["ssl_um"] == "" else float(c["ssl_um"])

    def done(ours, reached=True, certified=True):
        out.update(ours=ours, reached=reached, certified=certified)
        if not reached:
            out["verdict"] = "not reproduced"
            out["reason"] = "posture not reached"
        elif not certified:
            out["reason"] = "optimum not certified"
        else:
            out["verdict"] = verdict(comp, ours, paper, tol)
        return out

    if comp == "within_range":
        out["reason"] = ("Wong et al. 2004's per-level ranges are not available here; the model's rotations are in "
                         "muscle_intervertebral_rotations.csv")
        return out
    if c["claim_class"] in ("sensitivity_headline", "sensitivity_bound", "sensitivity_direction",
                            "reachability") and c["scope"] == "" and q not in ("mean_abs_change_flexion_over_standing",
                                                                               "idp_moment_share_max_pct"):
        out["reason"] = "the paper does not state the scope (which muscles) of this sentence"
        return out
    if c["claim_class"] == "table1":
        st = res.activity_state(post)
        if st is None:
            out["reason"] = "activity not in this run (config muscle_model.activities)"
            return out
        d = res.seg[(res.seg["level"] == c["value"]) & (res.seg["activity"] == post)]
        if d.empty:
            out["reason"] = "level not in this run's segment loads"
            return out
        return done(float(d[q].iat[0]), *st)
    if q == "idp_r2":
        if res.metrics.get("n", 0) < 3:
            out["reason"] = "fewer than three certified activities"
            return out
        out["reason"] = f"over {res.metrics['n']} of {res.metrics['n_total']} activities (certified)"
        r = done(float(res.metrics["r2"]))
        r["reason"] = out["reason"] if r["verdict"] != "not comparable" else r["reason"]
        return r
    if q in ("idp_mpa", "idp_moment_share_pct", "mf_sl_um", "extensor_active_n", "extensor_passive_n",
             "abdominal_active_n", "extensor_active_flexion_over_standing") and c["parameter"] == "":
        act = POSTURE_ACTIVITY[post]
        st = res.activity_state(act)
        if st is None:
            out["reason"] = "activity not in this run (config muscle_model.activities)"
            return out
        v = res.val.loc[act]
        if q == "idp_mpa":
            return done(float(v["idp_sim_mpa"]), *st)
        if q == "idp_moment_share_pct":
            return done(100.0 * float(v["idp_moment_mpa"]) / float(v["idp_sim_mpa"]), *st)
        f = res.fr.loc[act]
        if q == "mf_sl_um":
            return done(float(f["mf_sl_mean_um"]), *st)
        if q == "extensor_active_flexion_over_standing":
            s0 = res.activity_state("upright_standing")
            if s0 is None:
                out["reason"] = "upright standing not in this run"
                return out
            ratio = float(f["extensor_active_n"]) / max(float(res.fr.loc["upright_standing", "extensor_active_n"]),
                                                         1e-9)
            return done(ratio, st[0] and s0[0], st[1] and s0[1])
        return done(float(f[q]), *st)
    # ---- sensitivity claims
    if q == "mean_abs_change_flexion_over_standing":
        if res.sens is None:
            out["reason"] = "the sensitivity sweep is not run on this variant"
            return out
        d = res.sens[res.sens["certified"].astype(bool)]
        m = {p: d[d["posture"] == p]["change_pct"].abs().mean() for p in ("standing", "flexion")}
        if not all(np.isfinite(v) for v in m.values()):
            out["reason"] = "no certified scenario in one of the postures"
            return out
        return done(float(m["flexion"] / m["standing"]))
    if q == "idp_moment_share_max_pct":
        if res.sens is None:
            out["reason"] = "the sensitivity sweep is not run on this variant"
            return out
        d = res.sens[res.sens["certified"].astype(bool) & (res.sens["posture"] == post)]
        if d.empty:
            out["reason"] = "no certified scenario in this posture"
            return out
        return done(float((100.0 * d["idp_moment_mpa"] / d["idp_mpa"]).max()))
    if comp == "increase_most":
        got = [_scenario(res, c["parameter"], float(c["value"]), ssl, sc, post) for sc in SCOPES]
        if all(g[4] for g in got):                # none of the scopes in this run's sweep
            out["reason"] = got[0][4]
            return out
        ok = [g for g in got if g[3]]
        if len(ok) < 3:
            out["reason"] = f"{len(ok)} of 4 scopes certified"
            return out
        n_up = sum(g[0] > tol for g in ok)
        out.update(ours=float(n_up), reached=True, certified=True)
        out["verdict"] = "reproduced" if n_up >= 3 else "not reproduced"
        out["reason"] = f"{n_up} of {len(ok)} certified scopes above +{tol:g} %"
        return out
    if comp == "change_between":
        a, b = (float(x) for x in c["value"].split("->"))
        ga = _scenario(res, c["parameter"], a, ssl, c["scope"], post)
        gb = _scenario(res, c["parameter"], b, ssl, c["scope"], post)
        if ga[4] or gb[4]:
            out["reason"] = ga[4] or gb[4]
            return out
        return done(100.0 * (gb[1] / ga[1] - 1.0), ga[2] and gb[2], ga[3] and gb[3])
    ch, idp, reached, certified, why = _scenario(res, c["parameter"], float(c["value"]), ssl, c["scope"], post)
    if why:
        out["reason"] = why
        return out
    if comp in ("not_reached", "reached"):
        out.update(ours=float(reached), reached=reached, certified=certified)
        want = comp == "reached"
        if reached and not certified:
            out["reason"] = "reached, optimum not certified"
            return out
        out["verdict"] = "reproduced" if reached == want else "not reproduced"
        return out
    if q == "idp_mpa":
        return done(idp, reached, certified)
    return done(ch, reached, certified)


def claims_table(claims: pd.DataFrame, variants: dict) -> pd.DataFrame:
    """One row per claim and variant: claim, paper, ours, reached, certified, verdict, reason; ``variants`` maps a
    variant name to its :class:`_Results` (:func:`results_from_files`)."""
    rows = []
    for name, res in variants.items():
        for _, c in claims.iterrows():
            e = evaluate_claim(c, res)
            rows.append({"variant": name, "claim_id": c["claim_id"], "claim_class": c["claim_class"],
                         "section": c["section"], "quantity": c["quantity"], "posture": c["posture"],
                         "parameter": c["parameter"], "value": c["value"], "ssl_um": c["ssl_um"], "scope": c["scope"],
                         "comparison": c["comparison"], "paper": c["paper_value"], "unit": c["unit"],
                         "tolerance": c["tolerance"], **e, "quote": c["quote"]})
    return pd.DataFrame(rows)


def counts(table: pd.DataFrame) -> pd.DataFrame:
    """Verdict counts per variant and claim class, with the share reproduced of the comparable claims."""
    g = table.groupby(["variant", "claim_class", "verdict"]).size().unstack(fill_value=0)
    for v in VERDICTS:
        if v not in g.columns:
            g[v] = 0
    g = g[list(VERDICTS)]
    tot = table.groupby(["variant", "verdict"]).size().unstack(fill_value=0)
    for v in VERDICTS:
        if v not in tot.columns:
            tot[v] = 0
    tot = tot[list(VERDICTS)]
    tot.index = pd.MultiIndex.from_tuples([(v, "all") for v in tot.index], names=g.index.names)
    out = pd.concat([g, tot]).reset_index()
    comparable = out[["reproduced", "direction only", "not reproduced"]].sum(axis=1)
    out["comparable"] = comparable
    out["reproduced_share"] = np.where(comparable > 0, out["reproduced"] / comparable.where(comparable > 0, 1), np.nan)
    return out


def results_from_frames(validation, metrics, segment_loads, flexion_relaxation, sensitivity=None) -> _Results:
    """A variant's results from its tables (``sensitivity`` None: the sweep is not run on it)."""
    return _Results(validation, metrics, segment_loads, flexion_relaxation, sensitivity)


def results_from_files(validation, metrics, segment_loads, flexion_relaxation, sensitivity=None) -> _Results:
    """A variant's results read from its files (``sensitivity`` None: the sweep is not run on it)."""
    return _Results(pd.read_csv(validation), json.loads(Path(metrics).read_text()), pd.read_csv(segment_loads),
                    pd.read_csv(flexion_relaxation), None if sensitivity is None else pd.read_csv(sensitivity))


def paper_flexion_relaxation(claims: pd.DataFrame | None = None) -> dict:
    """{activity: (extensor active, extensor passive, abdominal active) [N]} as the paper states them (claims table)."""
    claims = read_claims() if claims is None else claims
    c = claims.set_index("claim_id")
    out = {}
    for post, act in POSTURE_ACTIVITY.items():
        out[act] = tuple(_num(c.loc[f"fr_{k}_{post}", "paper_value"]) for k in ("ext_active", "ext_passive",
                                                                                  "abd_active"))
    return out


#: a rest gap below minus this [mm] is a facet overlap at rest: 1 um, far below the contact smoothing (50 um) and far
#: above the round-off of a surface moved to touch (clear_rest_overlap)
REST_OVERLAP_TOL_MM = 1e-3


def chain_admissibility(variant, facet_contact: pd.DataFrame, rotations: pd.DataFrame) -> pd.DataFrame:
    """Whether a variant's passive chain fits the muscle model's geometry, per level: facet contact points beyond
    their surface at rest (``rest_min_gap_mm`` below -:data:`REST_OVERLAP_TOL_MM`: a preload before any load; none for
    a chain without facets) and the level flexing when the thorax flexes 36 deg (its rotation from standing > 0)."""
    rows = []
    flex = rotations[rotations["activity"] == "flexion_36deg"].set_index("level")
    for lv in flex.index:
        fc = facet_contact[facet_contact["level"] == lv] if len(facet_contact) else facet_contact
        gap = float(fc["rest_min_gap_mm"].min()) if len(fc) else np.nan
        rot = float(flex.loc[lv, "rotation_from_standing_deg"])
        rows.append({"variant": variant, "level": lv, "rest_min_gap_mm": gap,
                     "facet_overlap_at_rest": bool(np.isfinite(gap) and gap < -REST_OVERLAP_TOL_MM),
                     "flexion_36deg_rotation_from_standing_deg": rot, "flexes_in_flexion": bool(rot > 0.0),
                     "admissible": bool(not (np.isfinite(gap) and gap < -REST_OVERLAP_TOL_MM) and rot > 0.0)})
    return pd.DataFrame(rows)
