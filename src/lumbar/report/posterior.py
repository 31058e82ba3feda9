"""Report section "What the data told us": the calibration as a regularised inverse problem. Every fitted parameter's
sourced prior beside its posterior (MAP and Laplace 90 % interval), which rows moved it, and the 90 % posterior
bands of the calibrated unit's range of motion and internal loads. Every number is read from the result files
(workflow/rules/calibration.smk, load_sharing.smk); registered after the calibration section (stage manifest
calibration, report_module)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.posterior import METHOD_BOUND, METHOD_CLIPPED, METHOD_LINEAR, METHOD_NONLINEAR, natural_units
from .influence_text import influence_sentence as _influence_sentence
from .influence_text import posterior_judged_sentence as _posterior_judged_sentence
from .influence_text import profile_sentence as _profile_sentence
from .influence_text import spread_sentence as _spread_sentence
from .sections import ReportBuilder, fmt, report_section

#: the rows of the band table shown in the report: (direction, moment, quantity, label)
BAND_ROWS = (("flexion", 10.0, "rotation_deg", "flexion ROM, 10 N*m [deg]"),
             ("extension", 10.0, "rotation_deg", "extension ROM, 10 N*m [deg]"),
             ("lateral_bending", 10.0, "rotation_deg", "lateral bending ROM (mean of sides), 10 N*m [deg]"),
             ("axial_rotation", 10.0, "rotation_deg", "axial rotation ROM (mean of sides), 10 N*m [deg]"),
             ("extension", 7.5, "facet_max_contact_n", "facet force (larger joint), extension 7.5 N*m [N]"),
             ("axial_rotation_left", 7.5, "facet_max_contact_n", "facet force (loaded joint), axial rotation 7.5 N*m [N]"),
             ("flexion", 10.0, "ISL_tension_n", "ISL tension, flexion 10 N*m [N]"),
             ("flexion", 10.0, "SSL_tension_n", "SSL tension, flexion 10 N*m [N]"),
             ("flexion", 10.0, "CL_tension_n", "capsular ligaments, flexion 10 N*m [N]"),
             ("flexion", 10.0, "FL_tension_n", "flavum, flexion 10 N*m [N]"),
             ("flexion", 10.0, "ITL_tension_n", "intertransverse ligaments, flexion 10 N*m [N]"),
             ("extension", 7.5, "disc_axial_force_n", "disc axial force, extension 7.5 N*m [N]"))


def _value(unit: str, v: float) -> str:
    return fmt(v) if "mm" in unit else fmt(v, 3)


def sampling_sentence(s: pd.DataFrame) -> str:
    """What the MCMC draws say about the Laplace approximation (role calibration.sampling), for the section."""
    if s is None or s.empty:
        return ""
    r = s["sd_ratio_sampled_over_laplace"].astype(float)
    c = s.iloc[0]
    return (f" A short MCMC on the same objective ({int(c['walkers'])} walkers x {int(c['steps'])} steps, the first "
            f"{int(c['burn_in'])} discarded; about {fmt(c['independent_samples'], 2)} independent samples) gives "
            f"posterior spreads of {fmt(r.min(), 2)} to {fmt(r.max(), 2)} times the Laplace spread (median "
            f"{fmt(r.median(), 2)}): the one-sided constraints that are inactive at the MAP have no curvature there, "
            "so the Laplace intervals of Table P are wider than the posterior where the ratio is below 1. A longer "
            "chain spreads further along the slowest directions (benchmark: docs/load_sharing.md), so the sampled "
            "intervals are, if anything, narrow.")


#: how a band was made, in the report's words
BAND_METHOD_WORDS = {METHOD_LINEAR: "linearised", METHOD_BOUND: "posterior draws (the linear band goes below zero)",
                     METHOD_NONLINEAR: "posterior draws (the linear band disagrees with them)",
                     METHOD_CLIPPED: "linearised, cut at zero (no usable draws)"}


def posterior_sentence(t: pd.DataFrame) -> str:
    """How many parameters the data moved, which stayed at their prior, which are at a bound: for the summary."""
    moved = t[t["data_moved_it"].astype(bool)]
    stayed = t[~t["data_moved_it"].astype(bool)]
    bound = t[t["at_bound"].astype(bool)]
    s = (f"The calibration is a MAP estimate over {len(t)} parameters with sourced priors; the data (the intact ROM "
         f"rows and the disc-only rows) and the admissibility constraints moved {len(moved)} of them, {len(stayed)} "
         f"stay at their prior ({', '.join(stayed['parameter']) or 'none'})")
    s += (f"; {len(bound)} {'ends' if len(bound) == 1 else 'end'} at a bound ({', '.join(bound['parameter'])})."
          if len(bound) else "; none ends at a bound.")
    far = t.loc[t["shift_prior_sd"].abs().idxmax()] if len(t) else None
    if far is not None:
        s += (f" The largest move is {far['parameter']}: {fmt(far['shift_prior_sd'])} prior spreads, moved by "
              f"{far['moved_by'] or 'no single row'}.")
    return s


@report_section("posterior", "What the data told us: priors, posterior and bands", after="calibration")
def posterior_section(b: ReportBuilder):
    posterior, bands = b.out("calibration", "posterior"), b.out("load_sharing", "bands")
    if not b.has(posterior):
        b.missing("Calibration posterior (posterior.csv)")
        return
    t = pd.read_csv(b.path(posterior))
    sampling = b.out("calibration", "sampling")
    smp = pd.read_csv(b.path(sampling)) if b.has(sampling) else None
    smp = smp.set_index("parameter") if smp is not None and not smp.empty else None
    if t.empty:
        b.para("This calibration has no admissible (MAP) fit, hence no posterior (ligament_transfer: strain).")
        return
    b.para(f"A few range-of-motion values cannot pin down {len(t)} parameters: the calibration therefore gives "
           "each parameter a sourced prior (centre and spread) and minimises the data misfit over the data's spread "
           "plus the prior misfit over the prior's spread, with the admissibility criteria as soft penalties (a MAP "
           "estimate). The posterior is the Laplace approximation of that same objective at its optimum. "
           + posterior_sentence(t) + " Data spread: " + str(t["data_spread"].iloc[0]) + "."
           + sampling_sentence(None if smp is None else smp.reset_index()) + " Design: docs/load_sharing.md.")
    rows = []
    for r in t.itertuples(index=False):
        rows.append([r.parameter.replace("_", " "), r.unit,
                     f"{_value(r.unit, r.prior_centre)} ({_value(r.unit, r.prior_90_low)} to "
                     f"{_value(r.unit, r.prior_90_high)})",
                     f"{_value(r.unit, r.map)} ({_value(r.unit, r.posterior_90_low)} to "
                     f"{_value(r.unit, r.posterior_90_high)})",
                     _sampled(smp, r.parameter, r.unit),
                     fmt(r.spread_ratio, 2), fmt(r.shift_prior_sd, 2),
                     (r.moved_by if isinstance(r.moved_by, str) and r.moved_by else "stays at its prior"),
                     ("yes: " + str(r.bound_reason)) if bool(r.at_bound) else "no"])
    b.table_block("Prior and posterior of every calibrated parameter", [
        "parameter", "unit", "prior centre (90 %)", "MAP (Laplace 90 %)", "posterior draws 90 %",
        "posterior / prior spread",
        "shift [prior spreads]", "moved by (share of the pull)", "at a bound"], rows, source=posterior,
        label="Table P",
        note="Prior sources per parameter: the CSV's prior_source column. A spread ratio near 1 with a shift near 0: "
             "the data did not inform the parameter. Posterior draws: the MCMC of rule calibration_draws "
             "(posterior_sampling.csv).")
    b.figure(b.out("calibration", "posterior_figure"), "Prior (grey), Laplace posterior (blue) and posterior draws' "
             "(black) 90 % interval of every calibrated parameter, in prior spreads from the prior centre.",
             label="Fig. P")
    if b.has(bands):
        bd = pd.read_csv(b.path(bands))
        rows = []
        for d, M, q, label in BAND_ROWS:
            g = bd[(bd["direction"] == d) & np.isclose(bd["moment_nm"], M) & (bd["quantity"] == q)]
            if len(g):
                r = g.iloc[0]
                how = str(r.get("band_method", METHOD_LINEAR))
                rows.append([label, fmt(r["map"]), f"{fmt(r['low90'])} to {fmt(r['high90'])}",
                             BAND_METHOD_WORDS.get(how, how)])
        b.table_block("The calibrated unit's predictions with their 90 % posterior band (intact)",
                      ["prediction", "MAP", "90 % band", "how the band was made"], rows, source=bands,
                      note="Every band starts as the linearisation of the posterior (one finite-difference step per "
                           "parameter) and is checked: where it reaches below zero (a force, a tension) or lies more "
                           "than a quarter of its width from the band of the posterior draws run forward, it is the "
                           "draws' 5th to 95th percentile. Every direction and moment of the curves is in the CSV.")
    else:
        b.missing("Posterior bands of the intact curves (bands_calibrated.csv)")
    draws = b.out("load_sharing", "band_draws")
    if b.has(draws):
        judged = _posterior_judged_sentence(pd.read_csv(b.path(draws)), fmt)
        if judged:
            b.para("How probable the judged limits of the internal loads are under the posterior: " + judged)
    influence_block(b)


def _sampled(smp, name: str, unit: str) -> str:
    """The posterior draws' 90 % interval of one parameter in its natural unit, or "-"."""
    if smp is None or name not in smp.index:
        return "-"
    lo, hi = natural_units(name, [smp.loc[name, "sampled_5_fit"], smp.loc[name, "sampled_95_fit"]])[0]
    return f"{_value(unit, lo)} to {_value(unit, hi)}"


def influence_block(b: ReportBuilder):
    """Table of the leave-one-row-out refits (role calibration.row_influence): the MAP refitted without each real
    row."""
    influence = b.out("calibration", "row_influence")
    if not b.has(influence):
        b.missing("Leave-one-row-out calibration (row_influence.csv)")
        return
    t = pd.read_csv(b.path(influence))
    if t.empty:
        b.para("The leave-one-row-out refits were not run in this configuration "
               "(stepwise_reduction.row_influence: false).")
        return
    rows = []
    for r in t.itertuples(index=False):
        if not bool(r.converged) and not np.isfinite(r.rom_flexion_deg):
            rows.append([r.fit] + ["-"] * 9 + [str(r.largest_shifts)])
            continue
        label = r.fit if bool(r.converged) else f"{r.fit} (stopped at its evaluation budget, not converged)"
        rows.append([label, (f"{fmt(r.left_out_predicted_deg)} vs {fmt(r.left_out_measured_deg)}"
                             if np.isfinite(r.left_out_measured_deg) else "-"),
                     f"{fmt(r.rom_flexion_deg)} / {fmt(r.rom_extension_deg)} / {fmt(r.rom_lateral_bending_deg)} / "
                     f"{fmt(r.rom_axial_rotation_deg)}",
                     fmt(r.facet_stiffness_n_per_m, 3), fmt(getattr(r, "disc_axial_rotation_scale", np.nan), 2),
                     fmt(r.facet_extension_7_5_n),
                     fmt(r.facet_axial_rotation_7_5_n), str(r.largest_flexion_ligament), fmt(r.ssl_flexion_tension_n),
                     "yes" if bool(r.flexion_reduction_monotone) else "no", str(r.largest_shifts)])
    b.para("Which measured row decides which internal load: the MAP refitted without each real row in turn (same "
           "priors, penalties and disc-only rows, started from the MAP), and on every row with the facet stiffness "
           "held at fixed values, and with the disc-only rows given a wider spread. " + _influence_sentence(t, fmt) +
           " " + _profile_sentence(t, fmt) + " " + _spread_sentence(t, fmt))
    b.table_block("The calibration without each real row, with the facet stiffness held, and with the disc-only rows "
                  "at a wider spread: the left-out row's prediction and the internal loads", [
        "fit", "left-out row: predicted vs measured [deg]", "ROM flex / ext / LB / AR, 10 N*m [deg]",
        "facet stiffness [N/m]", "disc axial-rotation law [x disc-only fit]", "facet force, extension 7.5 N*m [N]", "facet force, axial rotation 7.5 N*m [N]",
        "largest ligament moment, flexion 10 N*m", "SSL tension, flexion 10 N*m [N]",
        "flexion ROM rises as SSL, ISL, FL, CL are removed", "largest shifts from the prior"], rows,
        source=influence, label="Table P2",
        note="Internal loads are judged, never fitted: this table only shows which data row pulls them where. "
             "Yamamoto et al. (1989) rows, L4-L5, 10 N*m.")
