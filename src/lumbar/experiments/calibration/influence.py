"""Which measured row decides which internal load: the MAP refitted without each real row in turn.

The admissible fit (:func:`.admissible.fit_admissible`) meets its real rows (the intact ROM at 10 N*m) and its
sourced priors at once. Its posterior table says which rows moved each *parameter*; this table says what each
row does to the *internal loads* that are judged and never fitted (facet contact forces at 7.5 N*m, the ligament
roles in flexion at 10 N*m): each row is left out, the MAP refitted from the full fit's optimum with the same priors,
penalties and disc-only rows, and the left-out fit's internal loads, its prediction of the left-out row and its
largest parameter shifts are listed beside the full fit's. A row whose removal brings every parameter back to its
prior and every internal load into its sourced range is the row the model's structure cannot meet with physiological
loads: a finding about the model, not a tuning knob (the row stays in the fit).
"""
from __future__ import annotations

import logging
from typing import Callable

import numpy as np
import pandas as pd

from ..fsu import build_fsu
from ..load_sharing import moment_rotation_curves

log = logging.getLogger(__name__)

#: curve points the internal loads are read at: 0 to 10 N*m in 0.5 N*m steps (7.5 and 10 included)
MOMENTS_NM = tuple(np.round(np.arange(0.0, 10.0 + 1e-9, 0.5), 2))
DIRECTIONS = ("flexion", "extension", "lateral_bending_right", "axial_rotation_left")
LIGAMENTS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL")
#: the posterior-ligament reduction stages whose flexion ROM at 10 N*m is listed (from the intact rest state)
REDUCTION = ("intact", "wo_ssl", "wo_isl", "wo_fl", "wo_cl")
#: facet contact stiffnesses [N/m] at which the MAP is refitted with the stiffness held (every other parameter free):
#: half-decades between ten times the paper's value (12,000 N/m, Sect. 2.2.3) and the cartilage-contact range the
#: full fit reaches (about 1e6-1e7 N/m); the profile shows what the real rows and the internal loads each ask of it
FACET_PROFILE_N_PER_M = (1.0e5, 3.0e5, 1.0e6)
#: evaluations of a diagnostic refit (started from the MAP; the full fit converges in about 100-200): one that stops
#: there is a row with ``converged`` False, not a longer default DAG
DIAGNOSTIC_MAX_NFEV = 150
#: log10 spread of the zero-width prior that holds the facet stiffness in :func:`facet_profile`'s refits
HELD_LOG10_SD = 1e-4
#: relative spreads of the disc-only rows as data at which the MAP is refitted (:func:`disc_spread_profile`; the fit's
#: own is DATA_SD_REL, 25 %): how far the disc of Heuer et al.'s specimens, behind the disc-only curve, may differ
#: from the disc of Yamamoto et al.'s, behind the intact rows, is not published; the table shows what the judged
#: internal loads do when that assumed spread is wider
DISC_ROW_SPREADS = (0.35, 0.5)
COLUMNS = ("fit", "left_out", "facet_stiffness_held", "disc_row_spread", "n_rows", "converged", "cost", "left_out_measured_deg", "left_out_predicted_deg",
           "left_out_rel_error", "rom_flexion_deg", "rom_extension_deg", "rom_lateral_bending_deg",
           "rom_axial_rotation_deg", "facet_extension_7_5_n", "facet_axial_rotation_7_5_n", "facet_flexion_7_5_n",
           "largest_flexion_ligament", "itl_flexion_moment_nm", "isl_flexion_moment_nm", "ssl_flexion_tension_n",
           "flexion_reduction_monotone", "facet_stiffness_n_per_m", "disc_axial_rotation_scale", "largest_shifts")


def internal_loads(geometry, charset, level="L4-L5") -> dict:
    """The judged internal loads of ``charset`` on ``geometry``'s ``level`` (intact curves in
    :data:`DIRECTIONS` and the flexion curves of the posterior-ligament reduction :data:`REDUCTION`, read at 7.5 and
    10 N*m)."""
    fsu = build_fsu(geometry, charset, level)
    c = moment_rotation_curves(fsu, moments_nm=MOMENTS_NM, directions=DIRECTIONS, stages=REDUCTION)

    def at(stage, d, m):
        s = c[(c["stage"] == stage) & (c["direction"] == d) & np.isclose(c["moment_nm"], m)]
        return s.iloc[0]

    f10 = at("intact", "flexion", 10.0)
    # a structure the set does not have (e.g. the paper's Table 3 has no ITL) carries nothing
    moments = {k: -float(f10.get(f"{k}_moment_y_nm", 0.0)) for k in LIGAMENTS}
    red = [float(at(s, "flexion", 10.0)["rotation_from_first_rest_deg"]) for s in REDUCTION]

    def facet(d):
        r = at("intact", d, 7.5)
        return max(float(r["facet_left_contact_n"]), float(r["facet_right_contact_n"]))

    return {"converged": bool(c["converged"].all()),
            "rom": {d: float(at("intact", d, 10.0)["rotation_deg"]) for d in DIRECTIONS},
            "facet_extension_7_5_n": facet("extension"), "facet_axial_rotation_7_5_n": facet("axial_rotation_left"),
            "facet_flexion_7_5_n": facet("flexion"),
            "largest_flexion_ligament": max(moments, key=moments.get),
            "itl_flexion_moment_nm": moments["ITL"], "isl_flexion_moment_nm": moments["ISL"],
            "ssl_flexion_tension_n": float(f10.get("SSL_tension_n", 0.0)),
            "flexion_reduction_monotone": bool(np.all(np.diff(red) > 0))}


def _shifts(fit, top=3) -> str:
    """The ``top`` largest |shift| of the MAP from the prior centre, in prior spreads ("facet_stiffness +2.3 sd")."""
    p = fit.posterior
    z = (np.asarray(p.map_q) - np.asarray(p.prior_centre)) / np.asarray(p.prior_sd)
    order = np.argsort(-np.abs(z))[:top]
    return "; ".join(f"{p.names[i]} {z[i]:+.1f} sd" for i in order)


def _disc_scale(fit, direction="axial_rotation") -> float:
    """The fitted scale of the disc torque law of ``direction`` (1: the disc-only fit), NaN when it is not fitted."""
    p = fit.posterior
    name = f"disc_torque:{direction}"
    return float(10.0 ** np.asarray(p.map_q, float)[list(p.names).index(name)]) if name in p.names else np.nan


def _row(label, left_out, fit, loads, targets, measured=np.nan, predicted=np.nan, held=np.nan,
         spread=np.nan) -> dict:
    rom = loads["rom"]
    return {"fit": label, "left_out": left_out, "facet_stiffness_held": held, "disc_row_spread": spread,
            "n_rows": len(targets),
            "converged": bool(loads["converged"] and fit.optimizer.get("converged", True)),
            "cost": float(fit.cost), "left_out_measured_deg": measured, "left_out_predicted_deg": predicted,
            "left_out_rel_error": (predicted - measured) / measured if np.isfinite(measured) else np.nan,
            "rom_flexion_deg": rom["flexion"], "rom_extension_deg": rom["extension"],
            "rom_lateral_bending_deg": rom["lateral_bending_right"],
            "rom_axial_rotation_deg": rom["axial_rotation_left"],
            **{k: loads[k] for k in ("facet_extension_7_5_n", "facet_axial_rotation_7_5_n", "facet_flexion_7_5_n",
                                     "largest_flexion_ligament", "itl_flexion_moment_nm", "isl_flexion_moment_nm",
                                     "ssl_flexion_tension_n", "flexion_reduction_monotone")},
            "facet_stiffness_n_per_m": float(fit.charset.facet.stiffness),
            "disc_axial_rotation_scale": _disc_scale(fit), "largest_shifts": _shifts(fit)}


CURVE_DIRECTION = {"flexion": "flexion", "extension": "extension", "lateral_bending": "lateral_bending_right",
                   "axial_rotation": "axial_rotation_left"}


def row_influence(full_fit, targets: pd.DataFrame, refit: Callable, geometry, level="L4-L5") -> pd.DataFrame:
    """The leave-one-row-out table (:data:`COLUMNS`): the full fit ``full_fit`` (an
    :class:`.admissible.AdmissibleFit` on ``targets``) and, per row of ``targets``, ``refit(targets without the row,
    start)`` (the same fit from ``start``, the full fit's optimum), each with :func:`internal_loads` and the
    prediction of the left-out row. A refit that fails is a row with ``converged`` False and its error in
    ``largest_shifts``, never a silent gap."""
    t = targets.reset_index(drop=True)
    start = dict(zip(full_fit.posterior.names, np.asarray(full_fit.posterior.map_q, float)))
    rows = [_row("all rows (MAP)", "", full_fit, internal_loads(geometry, full_fit.charset, level), t)]
    for i, r in t.iterrows():
        rest = t.drop(index=i).reset_index(drop=True)
        label = f"without {r['direction']}"
        try:
            fit = refit(rest, start)
        except (RuntimeError, ValueError) as e:      # no equilibrium / no rows: say so in the table
            log.warning("row influence: the fit %s failed: %s", label, e)
            rows.append({"fit": label, "left_out": r["direction"], "n_rows": len(rest), "converged": False,
                         "largest_shifts": f"failed: {e}"})
            continue
        loads = internal_loads(geometry, fit.charset, level)
        pred = loads["rom"].get(CURVE_DIRECTION.get(str(r["direction"]), str(r["direction"])), np.nan)
        rows.append(_row(label, r["direction"], fit, loads, rest, float(r["rom_mean_deg"]), pred))
    return pd.DataFrame(rows).reindex(columns=list(COLUMNS))


def _profile(full_fit, targets, refit_at, geometry, level, values, label, key, what) -> pd.DataFrame:
    """Rows of :data:`COLUMNS` for the MAP refitted on every real row at each of ``values`` (``refit_at(targets, start,
    value)``, started from the full fit's optimum), with the value in column ``key``; a refit that fails is a row with
    ``converged`` False and its error, never a silent gap."""
    t = targets.reset_index(drop=True)
    start = dict(zip(full_fit.posterior.names, np.asarray(full_fit.posterior.map_q, float)))
    rows = []
    for v in values:
        name = label(v)
        try:
            fit = refit_at(t, start, float(v))
        except (RuntimeError, ValueError) as e:
            log.warning("%s: the fit %s failed: %s", what, name, e)
            rows.append({"fit": name, "left_out": "", key: float(v), "n_rows": len(t), "converged": False,
                         "largest_shifts": f"failed: {e}"})
            continue
        rows.append(_row(name, "", fit, internal_loads(geometry, fit.charset, level), t, **{
            {"facet_stiffness_held": "held", "disc_row_spread": "spread"}[key]: float(v)}))
    return pd.DataFrame(rows).reindex(columns=list(COLUMNS))


def facet_profile(full_fit, targets: pd.DataFrame, refit_held: Callable, geometry, level="L4-L5",
                  values=FACET_PROFILE_N_PER_M) -> pd.DataFrame:
    """Rows of :data:`COLUMNS` for the MAP refitted on every real row with the facet stiffness held at each of
    ``values`` [N/m] (``refit_held(targets, start, value)``, started from the full fit's optimum; every other parameter
    free, with the same priors and penalties): a profile of the fit along the one parameter the rows push furthest
    from its prior, with the judged internal loads of each refit. ``left_out`` is empty and ``facet_stiffness_held``
    the held value; a refit that fails is a row with ``converged`` False and its error, never a silent gap."""
    return _profile(full_fit, targets, refit_held, geometry, level, values,
                    lambda v: f"facet stiffness held at {v:.3g} N/m", "facet_stiffness_held", "facet profile")


def disc_spread_profile(full_fit, targets: pd.DataFrame, refit_spread: Callable, geometry, level="L4-L5",
                        values=DISC_ROW_SPREADS) -> pd.DataFrame:
    """Rows of :data:`COLUMNS` for the MAP refitted on every real row with the disc-only rows' relative spread as data
    widened to each of ``values`` (``refit_spread(targets, start, spread)``; priors, penalties and the real rows'
    spread unchanged): whether the judged internal loads follow the assumed likeness of the two studies' discs.
    ``disc_row_spread`` is the spread; ``disc_axial_rotation_scale`` what the refit's disc then carries in axial
    rotation relative to the disc-only fit."""
    return _profile(full_fit, targets, refit_spread, geometry, level, values,
                    lambda v: f"disc-only rows at {100 * v:.0f} % spread", "disc_row_spread", "disc spread profile")
