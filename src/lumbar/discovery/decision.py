"""The decision of a discovery and its record: the share of the discrepancy the best candidate explains
(:func:`explained_share`), the naming rule (:func:`decide` on an :class:`Evidence`: named, nothing named, a nuisance,
unexplained, with the reasons) and the result record of :func:`lumbar.discovery.fit.discover` (:func:`result_record`:
discovery.json's fields and the per-scenario table)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..experiments import effects as fx


def explained_share(gap_after_best_w: float, nv: int, chi_null_obs: float, tests) -> tuple:
    """The share of the discrepancy the best candidate's refit explains (``tests``: the null tests,
    :class:`lumbar.discovery.fit.NullTests`): its chi2 drop (metric of the tests) over
    the excess of the observed chi2 above its expectation under the null (the null tables taken at face value); the
    null's own discrepancy (specimens, noise) is no effect's to explain. Returns (share, chi2 after the refit,
    chi2 expected under the null)."""
    chi_after_obs = gap_after_best_w ** 2 * nv if np.isfinite(gap_after_best_w) else float("nan")
    # fit0: tables without specimens
    null_chi = (tests.boot if tests.fit0 is None else tests.fit0) if tests.boot is not None else None
    chi_null_expected = float(np.mean(null_chi["chi_r"])) if null_chi is not None else float(nv)
    excess = chi_null_obs - chi_null_expected
    if not np.isfinite(chi_after_obs):
        explained = 0.0
    elif excess > 0:
        explained = (chi_null_obs - chi_after_obs) / excess
    else:
        # no discrepancy beyond what the null tables give: the share has nothing to measure, the directed tests
        # (max-T, candidate against nuisance, the refit's goodness of fit) decide; the refit must not fit worse
        explained = 1.0 if chi_after_obs <= chi_null_obs else 0.0
    return explained, chi_after_obs, chi_null_expected


@dataclass
class Evidence:
    """What the decision reads (phase 5): the best candidate, its tests, and what the nuisance explanations and the
    null model give. Defaults: nothing tested."""
    best: str | None
    n_rows: int                       # rows compared
    n_candidates: int
    gap_before: float
    too_few: bool = False
    p_adj: dict = field(default_factory=dict)       # candidate -> max-T p-value
    B: int = 0                                      # null tables
    with_specimens: bool = False                    # the null tables are virtual specimens (a bank)
    versus: str | None = None
    p_vs: float | None = None
    p_fit: dict = field(default_factory=dict)
    explained: float = 0.0
    chi_null_obs: float = float("nan")
    chi_after_obs: float = float("nan")
    chi_null_expected: float = float("nan")
    null_text: str = "the nominal model and the measurement noise"
    none_label: str = "nominal model"
    best_nuisance: str = "nominal model"
    p_nuis: dict = field(default_factory=dict)
    nres: dict = field(default_factory=dict)        # NuisanceRefits.nres


@dataclass
class Decision:
    named: str | None     # the named effect, or None
    decision: str         # "named: <effect>", "nothing named...", "nuisance: ...", "unexplained"
    reasons: list         # why (every criterion the best candidate fails; what the table is otherwise)


def decide(ev: Evidence, settings: dict) -> Decision:
    """Phase 5: ``named: <best>`` only if at least ``min_rows`` rows are compared, gap_before > ``min_gap``, its max-T
    p < ``alpha``, it beats the nuisance ``versus`` at ``alpha``, its refit is adequate (p >= alpha) and explains at
    least ``min_gap_reduction`` of the discrepancy; otherwise what the table is (nothing named, a nuisance,
    unexplained), with the reasons."""
    s, best, nv, bank = settings, ev.best, ev.n_rows, ev.with_specimens
    p_fit, p_nuis, nres, best_nuisance = ev.p_fit, ev.p_nuis, ev.nres, ev.best_nuisance
    gap_before, null_text = ev.gap_before, ev.null_text
    alpha = float(s["alpha"])
    reasons = []
    if best is None:
        reasons.append("no candidate effect acts on this experiment")
    elif ev.too_few:
        reasons.append(f"too few rows: {nv} scenario(s) compared, at least {int(s['min_rows'])} needed to test "
                       f"{ev.n_candidates} candidate(s) against the measurement noise; nothing can be named from "
                       f"these data")
    else:
        if not gap_before > s["min_gap"]:
            reasons.append(f"gap_before {gap_before:.2f} <= min_gap {s['min_gap']:g}: model and data agree within the "
                           f"measurement uncertainty")
        if not ev.p_adj.get(best, 1.0) < alpha:
            reasons.append(f"p = {ev.p_adj.get(best, float('nan')):.3g} for {best} (max-T over {ev.n_candidates} "
                           f"candidates, {ev.B} null tables{' of virtual specimens' if bank else ''}) is not below "
                           f"alpha {alpha:g}")
        if not (ev.p_vs if ev.p_vs is not None else 1.0) < alpha:
            reasons.append(f"{best} does not beat the nuisance explanation '{ev.versus}' (p = {fmt_p(ev.p_vs)} by the "
                           f"same bootstrap LR test, tables of the nuisance hypothesis) below alpha {alpha:g}")
        if not p_fit.get("best_candidate", 0.0) >= alpha:
            reasons.append(f"the refit of {best} leaves a misfit the null tables do not have (p = "
                           f"{fmt_p(p_fit.get('best_candidate'))} < alpha {alpha:g}): part of the discrepancy is not "
                           f"this effect")
        red = ev.explained
        if not red >= s["min_gap_reduction"]:
            reasons.append(f"the refit explains {100 * red:.0f}% < {100 * s['min_gap_reduction']:.0f}% of the "
                           f"discrepancy beyond what the null hypothesis gives (chi2 {ev.chi_null_obs:.1f} -> "
                           f"{ev.chi_after_obs:.1f}, {ev.chi_null_expected:.1f} expected)")
    named = best if best is not None and not reasons else None
    if named:
        decision = f"named: {named}"
    elif ev.too_few or best is None:
        decision = "nothing named: " + "; ".join(reasons)
    elif p_fit.get("specimen_mean", 0.0) >= alpha:
        shifted = bank and gap_before > s["min_gap"]
        decision = "nuisance: specimen-mean shift" if shifted else "nothing named"
        reasons.append(f"the table is consistent with {null_text} (goodness of fit p = "
                       f"{fmt_p(p_fit.get('specimen_mean'))})" + (
                           f"; its gap to the nominal model ({gap_before:.2f}) is what the mean of varied specimens "
                           f"gives" if shifted else ""))
    elif (best_nuisance != ev.none_label and p_nuis.get(best_nuisance, 1.0) < alpha
          and p_fit.get("best_nuisance", 0.0) >= alpha):
        decision = f"nuisance: {nres[best_nuisance]['description']}"
        reasons.append(f"the table differs from {null_text} (p = "
                       f"{fmt_p(p_fit.get('specimen_mean'))}); '{nres[best_nuisance]['description']}' explains it "
                       f"(p = {fmt_p(p_nuis.get(best_nuisance))} against the null model, its refit consistent with "
                       f"its null tables, p = {fmt_p(p_fit.get('best_nuisance'))}); no library effect does better")
    else:
        decision = "unexplained"
        reasons.append(f"the table differs from {null_text} (p = "
                       f"{fmt_p(p_fit.get('specimen_mean'))}), and neither a library effect nor a nuisance explanation "
                       f"(best '{nres[best_nuisance]['description'] if best_nuisance in nres else best_nuisance}', "
                       f"refit p = {fmt_p(p_fit.get('best_nuisance'))}) accounts for it: something is missing that "
                       f"the library does not hold")
    return Decision(named, decision, reasons)


# result_record (112 lines) is mostly one literal: the result's fields in the order discovery.json has kept them.
def result_record(problem, s, cands, cand_rank, best, est, exact, grids, null, score, obs, tests, refits, diag,
                  comparison, evidence, decision, ident) -> tuple[dict, pd.DataFrame]:
    """The result (discovery.json's fields, without ``forward_batches`` and ``seconds``, which :func:`discover` adds)
    and the per-scenario table of the phases' outputs."""
    y, sig, valid, nv, r, base, bank = problem.y, problem.sigma, null.valid, null.nv, null.r, grids.base, null.bank
    named, reasons, alpha = decision.named, decision.reasons, float(s["alpha"])
    fam, nres, best_nuisance, equiv = refits.fam, refits.nres, refits.best_nuisance, refits.equiv
    p_adj, p_raw, B, Tmax_null, c_hat0 = tests.p_adj, tests.p_raw, tests.B, tests.Tmax_null, tests.c_hat0
    T_obs = {c: float(v[0]) for c, v in obs["T_c"].items()}
    gap_before, z0 = null.gap_before, null.z0
    nuis_pred = r if best_nuisance not in fam else fam[best_nuisance].predict(
        np.where(valid, r, np.nan), obs["par_n"][best_nuisance][0])
    after = exact[named] if named else base
    z1 = (after - y) / sig
    gap_after = diag.gap_after_best if named else gap_before
    zr = (r - y) / sig
    zn = (nuis_pred - y) / sig
    rms_phys0 = float(np.sqrt(np.mean((base - y)[valid] ** 2))) if nv else float("nan")
    dev1 = np.where(np.isfinite(after), after - y, np.nan)[valid]
    rms_phys1 = float(np.sqrt(np.mean(dev1 ** 2))) if nv else float("nan")
    scen = problem.keys.copy()
    for k, v in (("measured", y), ("sigma", sig), ("model_before", base), ("z_before", z0), ("model_specimen_mean", r),
                 ("z_specimen_mean", zr), ("model_nuisance", nuis_pred), ("z_nuisance", zn), ("model_after", after),
                 ("z_after", z1), ("unit", problem.unit)):
        scen[k] = v
    for k in ("quantity", "nominal_model"):      # what is compared, and with which model (when the problem says)
        if k in problem.meta:
            scen[k] = problem.meta[k]
    eff = fx.EFFECTS.get(named) if named else None

    def at_bound(c):
        lo, hi = fx.EFFECTS[c].bounds
        return bool(np.isfinite(est[c]) and min(est[c] - lo, hi - est[c]) <= 1e-3 * (hi - lo))

    ranking = [["none", 0.0]] + [[c, T_obs[c]] for c in cand_rank]
    ranking = sorted(ranking, key=lambda kv: -kv[1])
    kind = ("virtual_specimens" if bank is not None else "gaussian")
    null_desc = ({"kind": kind, "specimens": bank.K, "bank": bank.source,
                  "correlation_shrinkage": score.metric.shrinkage} | score.null_model.describe(problem.unit)
                 if bank is not None else {"kind": kind, "noise_scale": float(np.sqrt(c_hat0))})
    gr = float(np.sqrt(np.mean(zr[valid] ** 2))) if nv else float("nan")
    res = {
        "experiment": problem.experiment,
        "n_scenarios": nv,
        "unit": problem.unit,
        "named_effect": named,
        "decision": decision.decision,
        "decision_reasons": reasons,
        "parameter_estimate": ({"effect": named, "parameter": eff.parameter, "value": est[named], "unit": eff.unit,
                                "at_bound": at_bound(named)} if named else None),
        "named_equivalent_to": equiv.get(named, []) if named else [],
        "p_value": p_adj.get(best) if best is not None and not score.too_few else None,
        "p_value_method": (f"single-step max-T (Westfall-Young): share of {B} null tables whose largest LR statistic "
                           f"over the {len(cands)} candidates reaches the observed one, (1 + k) / (B + 1); null tables "
                           + ("of the table's n virtual specimens of the nominal model (a bank of "
                              f"{bank.K}, lumbar.discovery.specimens) plus measurement noise, summarised as the table "
                              "is" if bank is not None else
                              f"of the nominal model plus Gaussian noise x sqrt(c), c = {c_hat0:.3g}")
                           + "; corrected for the number of candidates"),
        "null_model": null_desc,
        "alpha": alpha,
        "null_distribution_size": int(len(Tmax_null)),
        "null_lr_quantiles": ({q: float(np.quantile(Tmax_null, float(q))) for q in ("0.5", "0.95", "0.99")}
                              if len(Tmax_null) else None),
        "lr_statistic": T_obs,
        "p_values_adjusted": p_adj,
        "p_values_unadjusted": p_raw,
        "specimen_mean": {"chi2": float(obs["chi_r"][0]), "gap": gr, "chi2_nominal": null.chi_nominal,
                          "p_fit": comparison.p_fit.get("specimen_mean")},
        "nuisance": nres,
        "best_nuisance": best_nuisance,
        "best_nuisance_description": nres[best_nuisance]["description"] if best_nuisance in nres else best_nuisance,
        "nuisance_test": {"candidate": best, "against": comparison.versus, "statistic": comparison.D_obs,
                          "p_value": comparison.p_vs, "equivalent_nuisance": equiv.get(best, []) if best else []},
        "adequacy_p": comparison.p_fit,
        "gap_before": gap_before, "gap_after": gap_after,
        "gap_after_above_threshold": bool(np.isfinite(gap_after) and gap_after > s["min_gap"]),
        "gap_before_rms": rms_phys0, "gap_after_rms": rms_phys1,
        "gap_specimen_mean": gr,
        "gap_nuisance": float(np.sqrt(np.mean(zn[valid] ** 2))) if nv else float("nan"),
        "gap_reduction": (1 - gap_after / gap_before) if named and gap_before > 0 else 0.0,
        "discrepancy_explained": evidence.explained,
        "gap_metric": {"null": diag.gap_null, "after_best_candidate": diag.gap_after_best_w,
                       "definition": "RMS of the residuals in the metric of the tests (standard errors of the table, "
                                     "decorrelated by the specimens' correlation; the RMS z without specimens): the "
                                     "naming margins min_gap and min_gap_reduction apply to it"},
        "ranking": ranking,
        "confidence": diag.cw.get(named) if named else None,
        "confidence_definition": ("probability of the named effect among the candidates: weights exp(-chi2_c / "
                                  "(2 c_best)) normalised over the candidates (each has one parameter); null when "
                                  "nothing is named"),
        "candidate_weights": diag.cw,
        "best_candidate": best,
        "best_candidate_estimate": est.get(best) if best else None,
        "best_candidate_gap_after": diag.gap_after_best,
        "estimates": {c: est[c] for c in cands},
        "at_bound": {c: at_bound(c) for c in cands},
        "bounds": {c: list(fx.EFFECTS[c].bounds) for c in cands},
        "too_few_rows": bool(score.too_few),
        "identifiability": ident,
        "qaicc": diag.score,
        "cv_rms_z": diag.cv,
        "overdispersion_none": c_hat0,
        "input_warnings": list(problem.meta.get("input_warnings", [])),
        "criterion": ("LR statistic T_c = (chi2_0 - chi2_c) / c, chi2_0 of the specimen mean (nominal model + "
                      "specimen-mean shift), c = max(1, chi2_0 / (n - 1)); p-value by parametric bootstrap with "
                      "virtual specimens (max-T over candidates); named only if it also beats the best nuisance "
                      "explanation it is not equivalent to by the same test, and its refit is consistent with its own "
                      "null tables; gap = RMS of z against the nominal model"),
        "margins": {k: s[k] for k in ("alpha", "min_gap", "min_gap_reduction", "min_rows", "n_bootstrap")},
    }
    return res, scen


def fmt_p(p):
    return "n/a" if p is None else f"{p:.3g}"
