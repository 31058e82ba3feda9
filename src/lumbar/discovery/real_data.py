"""Every real miss posed to the discovery: the real measurements the calibrated model is compared with but was not
fitted on, each as a discovery problem with its spread, run per case, and one summary row per real dataset.

Cases (``REAL_CASES``):

* ``multilevel_rom``  Yamamoto et al. (1989) ROM at 10 N*m of the levels the calibration did not fit (L1-L2, L2-L3,
  L3-L4, L5-S1; 16 rows): the calibrated set applied unchanged at each level (the rule of
  the table of role ``validation.multilevel_rom``), re-solved with every candidate of the library
  (:class:`FsuVariants` per level). Spread: the abstract publishes none, so ``discovery.no_range_sd_deg`` is assumed per row mean, in
  quadrature with the calibrated model's 90 % posterior band (``sim_band_low``/``high`` of the multilevel table,
  converted to an SD).
* ``in_vivo_lying``   the in-vivo L4-L5 IDP (Wilke et al. 1999/2001) of the muscle model's activities plus the two
  lying postures of ``data/in_vivo/wilke1999_idp_lying_original_text.csv``. The muscle model has no lying activity
  (its redundancy solver holds postures against gravity along the trunk); lying takes the body weight off the spine's
  axis and the trunk muscles are quiet, so the model state chosen for lying is the calibrated passive L4-L5 unit at
  rest (no external load): its disc force is what the ligaments' pre-tension alone makes
  (role ``load_sharing.compression``, set calibrated, row ``force_n`` = 0), turned into IDP with the in-vivo
  muscle model's paper-2 formula at moment 0 (its IDP per newton, disc area ``l2s1.disc_area_m2``). Lying on the side adds a small lateral moment
  the state leaves out. Spread: ``discovery.in_vivo_sd_mpa`` (assumed; one volunteer).
* ``facet_share``     Adams and Hutton (1980): facets carry about 16 % of a compressive load in the erect posture;
  the model's share of a 1000 N follower load from the compression table. One row (the flexed-posture row, 0 %, is
  not posed: the source states no flexion angle or moment and the model's outputs hold no flexed state under
  compression); the calibration holds the share below 20 % (a one-sided constraint, not a target). Spread: none
  published, an SD of ``FACET_SHARE_ASSUMED_SD`` percentage points assumed.
* ``intact_rom``      the L4-L5 ROM of the same abstract: a calibration target, kept as a case and marked
  "calibration target: not posed" (a row the fit was made to match is no test of what the model misses).

Every posed case is decided at the assumed spread and again at half and double of it
(:data:`SPREAD_FACTORS`: the decision's sensitivity to an assumption nobody measured). What would decide it is
stated per case. Adoption (config ``adopted_effects``) is empty: nothing is adopted unless a case names an effect with
an estimate inside a sourced range."""
from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd

from ..experiments import effects as fx
from ..experiments.fsu import configured_unit
from ..experiments.validation import MULTILEVEL_DIRECTIONS
from ..geometry.configured import load_configured
from ..inputs.io import write_json_atomic, write_table_atomic
from ..mechanics.idp import DISC_AREA_M2, MPA, idp_per_newton
from ..inputs.tables import read_kind
from .detect import DiscoveryInputError, discovery_settings
from .fit import discover
from .outputs import REAL_DATA_COLUMNS, real_data_summary, write_outputs
from .problems import Problem, in_vivo_problem, nominal_model_label, resolve_charset
from .text import jsonable

log = logging.getLogger(__name__)

#: the assumed spread is scaled by these factors; the decision at each is a column of the summary
SPREAD_FACTORS = (0.5, 1.0, 2.0)
#: z of the two-sided 90 % band (the calibration's posterior bands are 90 % bands)
Z90 = 1.6448536269514722
#: assumed SD [percentage points] of the facet share of compression: "about 16 per cent" without spread; half its value
FACET_SHARE_ASSUMED_SD = 8.0
#: the compressive load [N] at which the model's facet share is read (the scoreboard's row)
FACET_SHARE_FORCE_N = 1000.0
#: planted tables per magnitude of the power check of a candidate with a sourced range (sourced_power)
SOURCED_POWER_TABLES = 10

#: per real dataset: its role for the calibration, and the measurement that would decide it
REAL_CASES = {
    "multilevel_rom": dict(
        role="independent (the calibration fits L4-L5 only)",
        what_would_decide="the per-level ROM with its specimens' spread (Yamamoto's abstract gives none) and, at L5-S1, "
                          "the disc's own stiffness and the facet gap measured on the same specimens (level-specific "
                          "properties the transfer rule carries over from L4-L5), whether the specimens kept their "
                          "iliolumbar ligaments, and per-level facet orientation from the same CTs"),
    "in_vivo_lying": dict(
        role="independent (no in-vivo value is fitted)",
        what_would_decide="IDP of more volunteers in each posture (the between-subject spread; one volunteer here) and "
                          "the unloaded disc's pressure in vitro on the same discs (its swelling pressure), which "
                          "separates a pressure the disc makes itself from one its loads make"),
    "facet_share": dict(
        role="constrained, not fitted (the calibration holds it below 20 %)",
        what_would_decide="the facet force under compression with its spread (specimens, SD) in a stated posture "
                          "(angle or moment), erect and flexed, on the same specimens"),
    "intact_rom": dict(
        role="calibration target",
        what_would_decide="an independent L4-L5 ROM dataset with its spread (not the rows the calibration was fitted "
                          "to)"),
    "va_artefact": dict(
        role="independent (paper 1, Sect. 4.2)",
        what_would_decide="the lordotic angle at 0 N*m of more reduction stages and specimens, with its spread"),
    "in_vivo": dict(
        role="independent (no in-vivo value is fitted)",
        what_would_decide="IDP of more volunteers in each posture (the between-subject spread; one volunteer here)"),
}

#: the extended summary's columns (the real-data summary's, then the posing's)
SUMMARY_COLUMNS = REAL_DATA_COLUMNS + (
    "role", "spread", "largest_miss", "largest_z", "decision_half_spread", "decision_double_spread", "adopted",
    "candidates_tried", "why_not_named", "what_would_decide")


# ------------------------------------------------------------------ the other levels' ROM (Yamamoto et al. 1989)
def yamamoto_other_levels(path, calibrated_level: str) -> pd.DataFrame:
    """The ROM rows of the Yamamoto levels table (data/experiments/yamamoto1989_levels_original_text.csv) at every
    level but ``calibrated_level``: level, direction (the table's), moment_nm, measured_deg, n_specimens, source."""
    p = Path(path)
    if not p.is_file():
        raise DiscoveryInputError(f"Yamamoto levels table not found: {p}; expected columns level, quantity, direction, "
                                  f"moment_nm, value_deg, n_specimens, source, kind")
    t = pd.read_csv(p)
    need = {"level", "quantity", "direction", "moment_nm", "value_deg", "n_specimens", "source"}
    if need - set(t.columns):
        raise DiscoveryInputError(f"{p}: column(s) {sorted(need - set(t.columns))} missing; expected {sorted(need)}")
    t = t[(t["quantity"] == "rom") & (t["level"] != calibrated_level)]
    bad = sorted(set(t["direction"]) - set(MULTILEVEL_DIRECTIONS))
    if bad:
        raise DiscoveryInputError(f"{p}, column 'direction': {bad} not understood; expected one of "
                                  f"{list(MULTILEVEL_DIRECTIONS)}")
    return (t.rename(columns={"value_deg": "measured_deg"})
            [["level", "direction", "moment_nm", "measured_deg", "n_specimens", "source"]].reset_index(drop=True))


def model_band_sd_levels(rows: pd.DataFrame, multilevel_rom) -> np.ndarray:
    """The calibrated model's posterior SD [deg] per row (level, direction) from the multilevel table's 90 % band
    (``sim_band_low``, ``sim_band_high``); 0 where the table has none."""
    if multilevel_rom is None:
        return np.zeros(len(rows))
    m = multilevel_rom if isinstance(multilevel_rom, pd.DataFrame) else pd.read_csv(multilevel_rom)
    if not {"sim_band_low", "sim_band_high"} <= set(m.columns):
        return np.zeros(len(rows))
    m = m.assign(sd=(m["sim_band_high"] - m["sim_band_low"]) / (2 * Z90))[["level", "direction", "sd"]]
    sd = rows[["level", "direction"]].merge(m, on=["level", "direction"], how="left")["sd"].to_numpy(float)
    return np.nan_to_num(sd)


_UNITS: dict = {}


def level_units(config, levels) -> dict:
    """{level: FsuVariants} of the configured geometry and characteristic set (cached per process)."""
    g, f = config.get("geometry") or {}, config.get("fsu") or {}
    c = config.get("characteristics") or {}
    s = discovery_settings(config)
    key = json.dumps([g, f, c, s["characteristic_set"], list(levels)], sort_keys=True, default=str)
    if key not in _UNITS:
        # the configured geometry, a user's specimen included (from the geometry cache its rule filled)
        geo = load_configured(dict(g), levels=list(levels))
        cs = resolve_charset(s["characteristic_set"], c.get("data_dir"), c.get("calibrated_dir"))
        _UNITS[key] = {lv: fx.FsuVariants(configured_unit(geo, cs, f, lv)) for lv in levels}
    return _UNITS[key]


def multilevel_forward(units: dict, rows: pd.DataFrame):
    """forward({effect: (G,)}) -> (G, n) ROM [deg] of ``rows`` (level, direction, moment_nm): each level's unit solved
    once per batch for every model direction its rows need; one-side directions are the mean of both sides (as the
    abstract's values and the table of role ``validation.multilevel_rom``)."""
    rows = rows.reset_index(drop=True)

    def forward(values):
        G = len(next(iter(values.values()))) if values else 1
        out = np.full((G, len(rows)), np.nan)
        for lv, sel in rows.groupby("level", sort=False):
            dirs = list(dict.fromkeys(d for yd in sel["direction"] for d in MULTILEVEL_DIRECTIONS[yd]))
            moments = sorted(set(map(float, sel["moment_nm"])))
            scen = pd.DataFrame([(d, m) for m in moments for d in dirs], columns=["direction", "moment_nm"])
            scen.insert(0, "stage", "intact")
            rom, conv, _, _ = units[lv].simulate(scen, values)
            rom = np.where(conv, rom, np.nan)
            col = {(d, m): i for i, (d, m) in enumerate(zip(scen["direction"], scen["moment_nm"]))}
            for i, yd, m in zip(sel.index, sel["direction"], sel["moment_nm"]):
                out[:, i] = np.mean([rom[:, col[(d, float(m))]] for d in MULTILEVEL_DIRECTIONS[yd]], axis=0)
        return out

    return forward


def multilevel_problem(config, yamamoto_path, multilevel_rom=None, units=None, levels=None) -> Problem:
    """The Yamamoto rows of the levels the calibration did not fit as a discovery problem (experiment
    ``stepwise_rom``: its candidates, re-solved at each level). sigma = hypot(assumed measurement SD of a row mean,
    the model's posterior SD); ``meta["sigma_assumed"]`` and ``meta["model_sd"]`` keep the parts. ``levels``: only
    these levels (None: every level of the table but the calibrated one)."""
    s = discovery_settings(config)
    level = (config.get("fsu") or {}).get("level", "L4-L5")
    rows = yamamoto_other_levels(yamamoto_path, level)
    if levels is not None:                 # the levels the workflow evaluates (load_sharing.other_levels)
        rows = rows[rows["level"].isin(list(levels))].reset_index(drop=True)
    if rows.empty:
        raise DiscoveryInputError(f"{yamamoto_path}: no ROM row at a level other than {level}")
    units = level_units(config, list(dict.fromkeys(rows["level"]))) if units is None else units
    fwd = multilevel_forward(units, rows)
    assumed = np.full(len(rows), float(s["no_range_sd_deg"]))
    model_sd = model_band_sd_levels(rows, multilevel_rom)
    keys = rows[["level", "direction", "moment_nm"]]
    cands = [c for c in fx.effect_names("stepwise_rom") + fx.effect_names("multilevel_rom")
             if not s.get("effects") or c in s["effects"]]
    return Problem("stepwise_rom", keys, rows["measured_deg"].to_numpy(float), np.hypot(assumed, model_sd), "deg",
                   fwd, cands, "level", ["direction", "moment_nm"], np.arange(len(rows)) % max(2, int(s["cv_folds"])),
                   meta={"quantity": "range of motion at the row's moment, other levels [deg]",
                         "nominal_model": nominal_model_label(config) + "; applied unchanged at each level",
                         "groups": keys["direction"].to_numpy(str), "model_sd": model_sd,
                         "sigma_assumed": assumed, "spread": f"assumed {s['no_range_sd_deg']:g} deg per row mean "
                         f"(discovery.no_range_sd_deg; none published) + model posterior band",
                         "design_keys": keys, "design_forward": fwd})


# ------------------------------------------------------------------ in-vivo IDP with the lying postures
def rest_disc_force(compression_table) -> float:
    """The calibrated L4-L5 unit's disc axial force [N] at rest (no external load): the compression table's row at
    ``force_n`` 0 (what the ligaments' pre-tension alone presses into the disc)."""
    t = compression_table if isinstance(compression_table, pd.DataFrame) else pd.read_csv(compression_table)
    for c in ("force_n", "disc_axial_force_n", "converged"):
        if c not in t.columns:
            raise DiscoveryInputError(f"compression table: column {c!r} missing; expected force_n, "
                                      "disc_axial_force_n, converged (role load_sharing.compression)")
    r = t[np.isclose(t["force_n"].astype(float), 0.0) & t["converged"].astype(str).str.lower().isin(["true", "1"])]
    if r.empty:
        raise DiscoveryInputError("compression table: no converged row at force_n = 0 (the unit at rest)")
    return float(r["disc_axial_force_n"].iloc[0])


def lying_tables(lying_path, validation: pd.DataFrame, segment_loads: pd.DataFrame, rest_force_n: float,
                 level="L4-L5", area_m2=DISC_AREA_M2):
    """(in-vivo table, segment loads) extended by the lying rows: the passive unit at rest, IDP = the muscle model's
    paper-2 formula at its disc force and moment 0, i.e. its IDP per newton (:func:`lumbar.mechanics.idp.idp_per_newton`,
    disc area ``area_m2``) x the force (see the module doc). The lying rows need no converged muscle posture: an
    in-vivo table whose activities all failed still poses them."""
    ly = read_kind(lying_path, "in_vivo_idp")
    conv = validation["converged"].astype(str).str.lower().isin(["true", "1"])
    per_n = idp_per_newton("paper2", area_m2=area_m2) / MPA
    rows = pd.DataFrame({"activity": ly["activity"], "idp_sim_mpa": per_n * rest_force_n,
                         "idp_in_vivo_mpa": ly["idp_mpa"].astype(float), "converged": True,
                         "source": ly["source"], "kind": ly["kind"],
                         "note": "model: calibrated passive L4-L5 unit at rest (no external load)"})
    v = pd.concat([validation.assign(converged=conv), rows], ignore_index=True)
    extra = pd.DataFrame({"level": level, "activity": ly["activity"], "compressive_n": rest_force_n, "shear_n": 0.0,
                          "moment_nm": 0.0, "converged": True})
    return v, pd.concat([segment_loads, extra], ignore_index=True)


def in_vivo_lying_problem(config, validation_path, segment_loads_path, lying_path, compression_path) -> Problem:
    s = discovery_settings(config)
    v, sl = lying_tables(lying_path, pd.read_csv(validation_path), pd.read_csv(segment_loads_path),
                         rest_disc_force(compression_path), s["in_vivo_level"],
                         (config.get("l2s1") or {}).get("disc_area_m2", DISC_AREA_M2))
    p = in_vivo_problem(v, config, segment_loads=sl)
    p.meta.update(sigma_assumed=p.sigma.copy(), model_sd=np.zeros(p.n),
                  spread=f"assumed {s['in_vivo_sd_mpa']:g} MPa per row (discovery.in_vivo_sd_mpa; one volunteer, none "
                         f"published)", rest_disc_force_n=rest_disc_force(compression_path))
    return p


# ------------------------------------------------------------------ facet share of compression (Adams and Hutton 1980)
def facet_share_rows(literature_path, compression_path, sd=FACET_SHARE_ASSUMED_SD) -> pd.DataFrame:
    """The posed facet-share row: measured (erect posture) and the model's share [%] of a FACET_SHARE_FORCE_N
    follower load (the compression table's ``facet_share``, as the scoreboard reads it), z with the assumed SD."""
    lit = pd.read_csv(literature_path)
    r = lit[(lit["quantity"] == "facet_share_of_compression") & (lit["load"] == "erect standing posture")]
    if r.empty:
        raise DiscoveryInputError(f"{literature_path}: no row quantity facet_share_of_compression, load 'erect standing "
                                  f"posture'")
    t = pd.read_csv(compression_path)
    at = t[np.isclose(t["force_n"].astype(float), FACET_SHARE_FORCE_N)]
    if at.empty:
        raise DiscoveryInputError(f"{compression_path}: no row at force_n = {FACET_SHARE_FORCE_N:g}")
    if "facet_share" not in at.columns:
        raise DiscoveryInputError(f"{compression_path}: column 'facet_share' missing (the facets' share of the "
                                  f"compressive load, lumbar.experiments.load_sharing.axial_compression_curve)")
    model = 100.0 * float(at["facet_share"].iloc[0])
    meas = float(r["value"].iloc[0])
    return pd.DataFrame({"posture": ["erect standing posture"], "load_n": [FACET_SHARE_FORCE_N],
                         "measured_pct": [meas], "model_pct": [model], "sd_pct": [sd], "z": [(model - meas) / sd],
                         "source": [str(r["source"].iloc[0])]})


# ------------------------------------------------------------------ running a case
def localise(problem: Problem, base: np.ndarray) -> tuple[str, float]:
    """Label (the row's keys) and z = (model - measured) / sigma of the row with the largest |z|."""
    z = (np.asarray(base, float) - problem.y) / problem.sigma
    if not np.isfinite(z).any():
        return "", float("nan")
    i = int(np.nanargmax(np.abs(z)))
    k = problem.keys.iloc[i]
    return ", ".join(f"{c} {k[c]}" for c in problem.keys.columns), float(z[i])


def with_spread(problem: Problem, factor: float) -> Problem:
    """The problem with its assumed spread scaled by ``factor`` (the model's posterior band unchanged)."""
    a = problem.meta.get("sigma_assumed", problem.sigma)
    m = problem.meta.get("model_sd", np.zeros(problem.n))
    return dataclasses.replace(problem, sigma=np.hypot(factor * np.asarray(a, float), np.asarray(m, float)),
                               meta=dict(problem.meta))


def run_case(case: str, problem: Problem, config, out_dir, measured_label: str, cache=None) -> dict:
    """Discover on ``problem`` at every factor of SPREAD_FACTORS (grids shared through ``cache``), write the case's
    outputs (lumbar.discovery.outputs.write_outputs, at the assumed spread) and ``real_case.json`` (the summary row's
    posing fields). Returns the real-case record."""
    s = discovery_settings(config)
    cache = {} if cache is None else cache
    outs = {f: discover(with_spread(problem, f), s, cache=cache) for f in SPREAD_FACTORS}
    out = outs[1.0]
    where, z = localise(out["problem"], _base_from(out))
    base = _base_from(out)
    sourced = sourced_candidates(problem, out["result"], base)
    sourced_power(problem, sourced, s, cache=cache)
    rec = case_record(case, out["result"], problem.meta.get("spread", ""), where, z,
                      {f: outs[f]["result"]["decision"] for f in SPREAD_FACTORS}, config, sourced)
    sens = candidate_sensitivity(problem, base)
    rec["candidates_tried"] = ", ".join(f"{c} (largest |dz| {v['largest_abs_dz']:.2g} at {v['value']:.3g} "
                                        f"{fx.EFFECTS[c].unit}{_sourced_text(sourced.get(c))})"
                                        for c, v in sens.items())
    rec["candidate_sensitivity"] = sens
    rec["sourced_ranges"] = sourced
    rec["gap_by_group"] = gap_by_group(problem, base)
    out["result"]["real_data"] = rec
    write_outputs(out, out_dir, measured_label)
    write_json_atomic(jsonable(rec), Path(out_dir) / "real_case.json", allow_nan=True)
    return rec


def candidate_sensitivity(problem: Problem, base: np.ndarray) -> dict:
    """Per candidate: how far it moves the compared rows at its first benchmark magnitude (one forward batch), in
    units of the rows' sigma: {name: {value, largest_abs_dz, rows_moved (|dz| > 0.1)}}. A candidate that moves no
    row cannot explain the miss here (nor be judged on these rows)."""
    cands = [c for c in problem.candidates if fx.EFFECTS[c].magnitudes]
    if not cands:
        return {}
    vals = {c: float(fx.EFFECTS[c].magnitudes[0]) for c in cands}
    G = len(cands)
    P = problem.forward({c: np.where(np.arange(G) == i, vals[c], 0.0) for i, c in enumerate(cands)})
    dz = (P - np.asarray(base, float)[None, :]) / problem.sigma[None, :]
    out = {}
    for i, c in enumerate(cands):
        a = np.abs(dz[i])
        out[c] = {"value": vals[c], "largest_abs_dz": float(np.nanmax(a)) if np.isfinite(a).any() else float("nan"),
                  "rows_moved": int(np.sum(a > 0.1))}
    return out


def sourced_candidates(problem: Problem, result: dict, base: np.ndarray) -> dict:
    """Per candidate of ``problem`` with a sourced magnitude range (lumbar.experiments.effects.sourced_range): the range
    and its source, the discovery's estimate (its refit on these rows), whether the estimate lies inside the range, and
    the rows the estimate makes worse (|z| up by more than 0.1 against the nominal model ``base``; one forward batch).
    A candidate is adoptable only if named with an estimate inside its range and no row it moves gets worse."""
    est = result.get("estimates") or {}
    z0 = (np.asarray(base, float) - problem.y) / problem.sigma
    out = {}
    for c in problem.candidates:
        rng = fx.sourced_range(c)
        if rng is None:
            continue
        lo, hi, src = rng
        e = est.get(c)
        e = None if e is None or not np.isfinite(float(e)) else float(e)
        rec = {"lo": lo, "hi": hi, "source": src, "estimate": e, "inside": e is not None and lo <= e <= hi,
               "rows_worse_at_estimate": []}
        if e is not None:
            z1 = (problem.forward({c: np.array([e])})[0] - problem.y) / problem.sigma
            worse = np.flatnonzero(np.abs(z1) > np.abs(z0) + 0.1)
            rec["rows_worse_at_estimate"] = [", ".join(f"{k} {problem.keys.iloc[i][k]}" for k in problem.keys.columns)
                                             for i in worse]
        out[c] = rec
    return out


def sourced_power(problem: Problem, sourced: dict, settings: dict, n_tables: int = SOURCED_POWER_TABLES,
                  cache=None) -> dict:
    """Could the discovery name a sourced candidate on these rows? Per entry of ``sourced`` (sourced_candidates, edited
    in place: key ``power``): tables planted with the candidate at the end of its sourced range farthest from 0 (the
    most detectable size a source allows) and at the discovery's estimate, each the model's prediction plus Gaussian
    noise at the rows' sigma (``n_tables`` seeds from the configuration's seed), decided with the case's settings;
    ``named`` counts the tables that name the candidate. None named at the sourced size means the rows cannot show the
    candidate at a size a source allows, whatever the decision on the measured table."""
    seed = int(settings.get("seed", 0))
    for c, rec in sourced.items():
        sizes = {"sourced_bound": rec["hi"] if abs(rec["hi"]) >= abs(rec["lo"]) else rec["lo"]}
        if rec["estimate"] is not None:
            sizes["estimate"] = rec["estimate"]
        rec["power"] = {}
        for label, m in sizes.items():
            pred = problem.forward({c: np.array([float(m)])})[0]
            named = 0
            for k in range(int(n_tables)):
                y = pred + np.random.default_rng([seed, k]).normal(0.0, problem.sigma)
                r = discover(dataclasses.replace(problem, y=y), settings, cache=cache)["result"]
                named += r.get("named_effect") == c
            rec["power"][label] = {"magnitude": float(m), "named": int(named), "tables": int(n_tables)}
    return sourced


def _sourced_text(r) -> str:
    """'; sourced range [lo, hi], estimate e (inside|outside)' of a sourced_candidates entry ('' without one)."""
    if not r:
        return ""
    e = "none" if r["estimate"] is None else f"{r['estimate']:.3g} ({'inside' if r['inside'] else 'outside'})"
    return f"; sourced range [{r['lo']:.3g}, {r['hi']:.3g}] ({r['source']}), estimate {e}"


def gap_by_group(problem: Problem, base: np.ndarray) -> dict:
    """RMS z of the nominal model per value of the problem's row key (per level for the other levels' ROM)."""
    z = (np.asarray(base, float) - problem.y) / problem.sigma
    g = problem.keys[problem.row_key].astype(str).to_numpy() if problem.row_key in problem.keys else \
        np.full(problem.n, "all")
    return {k: float(np.sqrt(np.nanmean(z[g == k] ** 2))) for k in dict.fromkeys(g)}


def _base_from(out) -> np.ndarray:
    """The nominal model's prediction per row, from the scenarios table (column ``model_before``)."""
    sc = out["scenarios"]
    return sc["model_before"].to_numpy(float)


def adopted_effects(config) -> list:
    """The configuration's ``adopted_effects`` (validated by the schema; empty by default)."""
    return list((config or {}).get("adopted_effects") or [])


def why_not_named(r: dict, decisions: dict, role: str, sourced: dict | None = None) -> str:
    """Why a case names nothing, by kind: circularity (a calibration target), power (too few rows; a table the null
    hypothesis explains), spread (the decision changes within half to double the assumed spread), or no candidate
    (the library's candidates do not account for the miss)."""
    if role.startswith("calibration target"):
        return "circularity: the calibration was fitted to these rows"
    if r.get("named_effect"):
        return ""
    out = []
    if r.get("too_few_rows"):
        out.append(f"power: {r.get('n_scenarios')} row(s), fewer than discovery.min_rows")
    elif "unexplained" in str(r.get("decision", "")):
        best = r.get("best_candidate")
        out.append("no candidate: the table differs from the model beyond its spread and no library candidate "
                   "or nuisance explanation accounts for it"
                   + (f" (best {best}, p = {r.get('p_value'):.3g})" if best and r.get("p_value") is not None else "")
                   + ("; the candidate(s) with a sourced magnitude range, tried: " + "; ".join(
                       f"{c} (estimate {'none' if v['estimate'] is None else format(v['estimate'], '.3g')} "
                       f"{'inside' if v['inside'] else 'outside'} its sourced range [{v['lo']:.3g}, {v['hi']:.3g}]"
                       + (f"; worse at the estimate: {' / '.join(v['rows_worse_at_estimate'])}"
                          if v.get("rows_worse_at_estimate") else "")
                       + "".join(f"; planted at its {k.replace('_', ' ')} {w['magnitude']:.3g}, named in {w['named']} "
                                 f"of {w['tables']} tables" for k, w in (v.get("power") or {}).items()) + ")"
                       for c, v in sourced.items())
                      if sourced else "; no candidate with a sourced magnitude range was found for the mechanisms "
                                      "that could"))
    else:
        out.append("power: the table does not differ from the model beyond its spread")
    if len(set(decisions.values())) > 1:
        out.append("spread: the decision changes between half and double the assumed spread")
    return "; ".join(out)


def case_record(case, r: dict, spread: str, where: str, z: float, decisions: dict, config,
                sourced: dict | None = None) -> dict:
    meta = REAL_CASES.get(case, {"role": "", "what_would_decide": ""})
    adopted = adopted_effects(config)
    return {"dataset": case, "role": meta["role"], "spread": spread, "largest_miss": where, "largest_z": z,
            "decision": r.get("decision", ""), "decision_half_spread": decisions.get(0.5, ""),
            "decision_double_spread": decisions.get(2.0, ""),
            "adopted": bool(r.get("named_effect")) and r.get("named_effect") in adopted,
            "candidates_tried": ", ".join(r.get("estimates") or {}),
            "why_not_named": why_not_named(r, decisions, meta["role"], sourced),
            "what_would_decide": meta["what_would_decide"]}


def facet_share_case(literature_path, compression_path, out_dir, config) -> dict:
    """The facet-share case: one posable row, decided "too few rows" by the discovery's own rule (min_rows), its z
    at the assumed SD and at half and double; rows.csv and real_case.json in ``out_dir``."""
    s = discovery_settings(config)
    rows = facet_share_rows(literature_path, compression_path)
    z = {f: float((rows["model_pct"].iloc[0] - rows["measured_pct"].iloc[0]) / (f * FACET_SHARE_ASSUMED_SD))
         for f in SPREAD_FACTORS}
    n = len(rows)
    dec = (f"nothing named: too few rows: {n} row(s), at least {int(s['min_rows'])} needed"
           if n < int(s["min_rows"]) else "")
    r = {"decision": dec, "too_few_rows": n < int(s["min_rows"]), "n_scenarios": n, "estimates": {}}
    rec = case_record("facet_share", r, f"assumed {FACET_SHARE_ASSUMED_SD:g} percentage points (none published)",
                      f"posture {rows['posture'].iloc[0]}, load {FACET_SHARE_FORCE_N:g} N", z[1.0],
                      {f: dec for f in SPREAD_FACTORS}, config)
    # the library has no candidate that acts on the facets' share of a compressive load: say so, not an empty cell
    rec["candidates_tried"] = "none: no library candidate acts on the facet share of a compressive load"
    rec |= {"n_rows": n, "gap_before": abs(z[1.0]), "z_half_spread": z[0.5], "z_double_spread": z[2.0],
            "note": (f"model {rows['model_pct'].iloc[0]:.3g} % of a {FACET_SHARE_FORCE_N:g} N follower load vs "
                     f"about {rows['measured_pct'].iloc[0]:g} % measured; |z| {abs(z[0.5]):.2f} / {abs(z[1.0]):.2f} / "
                     f"{abs(z[2.0]):.2f} at half / assumed / double spread; the flexed-posture row (0 %) is not posed "
                     f"(no flexion angle or moment in the source, no flexed state under compression in the model); no "
                     f"library candidate acts on the facet share [{rows['source'].iloc[0]}]")}
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    write_table_atomic(rows, d / "rows.csv", float_format="%.6g")
    write_json_atomic(jsonable(rec), d / "real_case.json", allow_nan=True)
    return rec


# ------------------------------------------------------------------ the summary
def _localise_scenarios(path) -> tuple[str, float]:
    """Label and z of the row with the largest |z_before| of a case's scenarios.csv ("" and NaN without one)."""
    p = Path(path)
    if not p.is_file():
        return "", float("nan")
    sc = pd.read_csv(p)
    z = sc["z_before"].to_numpy(float)
    if not np.isfinite(z).any():
        return "", float("nan")
    i = int(np.nanargmax(np.abs(z)))
    keys = [c for c in sc.columns if c == "measured" or c in ("sigma",)]
    cols = list(sc.columns[: list(sc.columns).index(keys[0])]) if keys else []
    return ", ".join(f"{c} {sc[c].iloc[i]}" for c in cols), float(z[i])


def real_misses_summary(discovery_paths, real_case_paths, config) -> pd.DataFrame:
    """One row per real dataset: the real-data summary's columns (lumbar.discovery.outputs.real_data_summary) of every
    ``discovery.json`` in ``discovery_paths`` and beside a ``real_case.json``, joined with the posing fields of the
    ``real_case.json`` when the case has one; a case without one (run by the older rules) gets its role, its largest
    miss from its scenarios.csv and the decision at other spreads where it cannot change (too few rows at any spread;
    the calibration target, "calibration target: not posed"). Cases with a ``real_case.json`` only (facet share) get
    its fields."""
    real_case_paths = [Path(p) for p in real_case_paths]
    recs = {json.loads(p.read_text())["dataset"]: json.loads(p.read_text()) for p in real_case_paths}
    runs = [Path(p) for p in discovery_paths] + [p.parent / "discovery.json" for p in real_case_paths
                                                 if (p.parent / "discovery.json").is_file()]
    base = real_data_summary(runs)
    by_case = {p.parent.name: p for p in runs}
    rows = []
    adopted = adopted_effects(config)
    for row in base.to_dict("records"):
        case = row["dataset"]
        rec = recs.pop(case, None)
        meta = REAL_CASES.get(case, {"role": "", "what_would_decide": ""})
        if rec is None:
            r = json.loads(by_case[case].read_text())
            where, z = _localise_scenarios(by_case[case].parent / "scenarios.csv")
            same = r.get("decision", "") if r.get("too_few_rows") else ""
            rec = case_record(case, r, "as configured for this case's rule", where, z, {0.5: same, 2.0: same},
                              config)
            if not same:
                rec["decision_half_spread"] = rec["decision_double_spread"] = "not rerun (see in_vivo_lying)" \
                    if case == "in_vivo" else "not rerun"
        if meta["role"].startswith("calibration target"):
            rec["decision"] = rec["decision_half_spread"] = rec["decision_double_spread"] = \
                "calibration target: not posed"
            row["note"] = f"discovery run kept for reference: {row['decision']}; " + row["note"]
        row.update({k: v for k, v in rec.items() if k in SUMMARY_COLUMNS and k not in ("dataset", "note")})
        if rec.get("gap_by_group") and len(rec["gap_by_group"]) > 1:
            row["note"] = "gap (RMS z) by " + ", ".join(f"{k} {v:.2f}" for k, v in rec["gap_by_group"].items()) + \
                "; " + row["note"]
        rows.append(row)
    for case, rec in recs.items():
        rows.append({c: rec.get(c, "") for c in SUMMARY_COLUMNS} | {"dataset": case})
    out = pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))
    out["adopted"] = out["adopted"].astype(bool)
    if not adopted:
        out["note"] = out["note"].astype(str) + "; adopted: no (config adopted_effects is empty: nothing was named with " \
                                                "an estimate inside a sourced range)"
    return out
