"""Discrepancy discovery (issue 6): where do model and measurement disagree, and which missing effect explains it?

``python -m lumbar.discover --config CONFIG --measured FILE.csv --out DIR``

1. The experiment is detected from the table's columns (:data:`lumbar.tables.MEASURED`): stepwise-reduction ROM
   (``stage, direction, moment_nm, rom_mean_deg, ...``), L2-S1 IDP (``muscle_setup, load_case,
   idp_mean_mpa, idp_sd_mpa, ...``), in-vivo validation (``activity, idp_sim_mpa, idp_in_vivo_mpa, ...``;
   moments from the muscle model's segment loads) or the neutral lordotic angle per reduction stage
   (``stage, lordosis_deg, ...``: the vertebral-arch artefact). Bad files and columns are rejected before
   any computation.
2. Residuals ``z = (model - measured) / sigma`` per scenario, sigma = the uncertainty of the measured mean:
   ROM: (max - min) / d2(n) / sqrt(n) (range -> SD with the expected range of n normal samples), rows
   without a range ``no_range_sd_deg``; IDP: SD / sqrt(n); in vivo and neutral angle: configured SDs
   (none published). ``gap`` = RMS of z. Disagreement map: z by stage x (direction, moment), set-up x
   load case, activity, or stage.
3. Every candidate effect of :mod:`lumbar.effects` acting on the experiment is fitted (one bounded
   parameter): one batched forward solve on a coarse parameter grid for all candidates together, a cubic
   spline per scenario, ``scipy.optimize.minimize_scalar`` (bounded), one batched solve on a fine grid
   around each optimum, and one exact solve at the estimates (3 batches in total).
4. Decision (issue 15): the likelihood-ratio statistic of each candidate against "no effect",
   ``T_c = (chi2_none - chi2_c) / c`` with the overdispersion of the no-effect model
   ``c = max(1, chi2_none / (n - 1))``; its null distribution from a parametric bootstrap
   (``n_bootstrap`` datasets from the project's generator around the nominal model: per row n virtual
   specimens with the row's per-specimen spread, summarised as the experiment's table is; only the cached
   grid solves are reused, no new forward solve); p-value = single-step max-T over the candidates
   (corrected for their number). ``confidence`` = probability of the named effect among the candidates
   (weights exp(-chi2_c / 2 c_best)); null when nothing is named. QAICc and grouped cross-validation are
   reported as diagnostics.
5. Naming rule: an effect is named only if the data have at least ``min_rows`` compared scenarios (fewer:
   "too few rows", nothing named), gap_before > ``min_gap``, p < ``alpha`` and the refit reduces the gap by
   ``min_gap_reduction``. Estimates on a bound (``at_bound``) and a gap after the refit still above
   ``min_gap`` (``gap_after_above_threshold``) are flagged.
6. Identifiability: the correlation of every pair of candidates' sensitivity vectors on the experiment; a
   pair with |r| >= ``max_correlation`` is reported as not separable, with the ``n_next`` load cases of the
   experiment's design space that separate it best ("measure next").

Outputs in DIR: discovery.json, scenarios.csv, disagreement_map.png, ranking.png, before_after.png,
section.md. The benchmark (hidden-effect fixtures) is :func:`make_hidden_effect_dataset` /
:func:`run_benchmark_cases` / :func:`summarise_benchmark`.
"""
from __future__ import annotations

import argparse
import functools
import json
import logging
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from . import effects as fx
from .config import schema_defaults
from .idp import DISC_AREA_M2, idp_per_newton
from .io import TableError, read_table, subplots
from .stepwise_reduction import read_experiment_table
from .tables import MEASURED, SEGMENT_LOAD_COLUMNS

log = logging.getLogger(__name__)

# expected range of n normal samples in SDs (d2 of quality control), n = 2..10
D2 = {2: 1.128, 3: 1.693, 4: 2.059, 5: 2.326, 6: 2.534, 7: 2.704, 8: 2.847, 9: 2.970, 10: 3.078}

#: discovery settings that are not configuration keys; every other setting and its default is owned by the
#: ``discovery`` section of the configuration schema (:func:`lumbar.config.schema_defaults`)
INTERNAL_SETTINGS = dict(seed=0, fine_candidates=2)


class DiscoveryInputError(ValueError):
    """A measured file that cannot be used (message names file, column and the expected form)."""


# ------------------------------------------------------------------ configuration
def default_settings() -> dict:
    """The discovery settings of an empty configuration: the schema's ``discovery`` defaults (without the
    benchmark section) and :data:`INTERNAL_SETTINGS`."""
    s = schema_defaults("discovery")
    s.pop("benchmark", None)
    return s | INTERNAL_SETTINGS


def discovery_settings(config: dict | None) -> dict:
    s = default_settings()
    s.update({k: v for k, v in ((config or {}).get("discovery") or {}).items() if k != "benchmark"})
    s["seed"] = int((config or {}).get("seed", 0))
    return s


# ------------------------------------------------------------------ reading and schema detection
def detect_experiment(columns, path="<table>") -> str:
    """The experiment of a table with ``columns`` (:data:`lumbar.tables.MEASURED`, in its order: the first one
    whose signature columns are all present; then every column it uses must be)."""
    cols = set(columns)
    for name, kind in MEASURED.items():
        if set(kind.columns[: kind.signature]) <= cols:
            missing = [c for c in kind.columns if c not in cols]
            if missing:
                raise DiscoveryInputError(
                    f"{path}: looks like a {name} table but column(s) {missing} are missing; "
                    f"expected columns {list(kind.columns)}")
            return name
    forms = "; ".join(f"{k}: {list(v.columns)}" for k, v in MEASURED.items())
    raise DiscoveryInputError(f"{path}: columns {sorted(cols)} match no experiment schema; expected one of {forms}")


def _check_ragged(p):
    """Every data row has as many fields as the header (pandas pads short rows silently)."""
    import csv
    with open(p, newline="", encoding="utf-8", errors="replace") as f:
        rows = list(csv.reader(f))
    if not rows:
        return
    head = rows[0]
    for i, r in enumerate(rows[1:], 1):
        if r and len(r) != len(head):
            col = head[len(r)] if len(r) < len(head) else None
            where = f"row {i}" + (f", column '{col}'" if col else "")
            raise DiscoveryInputError(f"{p}, {where}: {len(r)} field(s) but the header has {len(head)}; expected one "
                                      f"value per header column {head} (a ragged row)")


def read_measured(path) -> tuple[str, pd.DataFrame]:
    """(experiment, validated table) of a measured/surrogate/fixture file; DiscoveryInputError if unusable.

    Every schema goes through :func:`lumbar.io.read_table`: a bad cell names the file, the 1-based data row, the
    column and the expected form; ragged rows are rejected."""
    p = Path(path)
    if not p.is_file():
        raise DiscoveryInputError(f"measured file not found: {p}")
    try:
        head = pd.read_csv(p, nrows=5)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as e:
        raise DiscoveryInputError(f"{p}: not a readable CSV table ({type(e).__name__}); expected a CSV file with a "
                                  f"header row") from e
    exp = detect_experiment(head.columns, p)
    _check_ragged(p)
    try:
        if exp == "stepwise_rom":
            df = read_experiment_table(p)
        else:
            df = read_table(p, MEASURED[exp].schema)
    except TableError as e:
        raise DiscoveryInputError(str(e)) from e
    if len(df) == 0:
        raise DiscoveryInputError(f"{p}: no data rows; expected one row per scenario")
    if exp == "neutral_angle" and "lordosis_sd_deg" in df:
        sd = df["lordosis_sd_deg"].to_numpy(float)
        bad = np.flatnonzero(sd == 0)
        if len(bad):
            raise DiscoveryInputError(f"{p}, row {bad[0] + 1}, column 'lordosis_sd_deg': got 0, a zero uncertainty; "
                                      f"expected a finite number > 0 [deg] (or empty for discovery.neutral_sd_deg)")
    if exp == "in_vivo":
        df["converged"] = df["converged"].str.lower() == "true"
        bad = np.flatnonzero(df["converged"].to_numpy(bool) & ~np.isfinite(df["idp_sim_mpa"].to_numpy(float)))
        if len(bad):
            raise DiscoveryInputError(f"{p}, row {bad[0] + 1}, column 'idp_sim_mpa': empty on a converged row; "
                                      f"expected a finite number in [0, 100] (empty only where converged is False)")
    if exp == "neutral_angle" and len(df) < 2:
        raise DiscoveryInputError(f"{p}: a neutral-angle table needs >= 2 stages (the first is the reference); "
                                  f"got {len(df)}")
    return exp, df


# ------------------------------------------------------------------ problems (measured data + batched forward model)
@dataclass
class Problem:
    experiment: str
    keys: pd.DataFrame                       # scenario labels
    y: np.ndarray                            # measured (physical unit)
    sigma: np.ndarray                        # uncertainty of the measured value
    unit: str
    forward: Callable                        # forward({effect: (G,)}) -> (G, n) predictions (one batch)
    candidates: list
    row_key: str
    col_keys: list
    folds: np.ndarray                        # CV fold per scenario
    meta: dict = field(default_factory=dict)

    @property
    def n(self):
        return len(self.y)


def _rom_sigma(df, s):
    n = df["n_specimens"].to_numpy(int)
    lo, hi = df["rom_min_deg"].to_numpy(float), df["rom_max_deg"].to_numpy(float)
    d2 = np.array([D2.get(int(k), 3.078 if k > 10 else np.nan) for k in n])
    sd = (hi - lo) / d2
    sig = np.where(np.isfinite(sd) & (n > 1), sd / np.sqrt(np.maximum(n, 1)), s["no_range_sd_deg"])
    return np.maximum(sig, s["sigma_floor_deg"])


@functools.lru_cache(maxsize=4)
def _fsu_variants(geometry_kind, geometry_path, level, set_name, data_dir, facet_k, k_shear, calibrated_dir=None):
    from .fsu import build_fsu
    from .geometry import load_geometry
    geo = load_geometry(geometry_kind, path=geometry_path if geometry_kind == "visible_human" else None, levels=[level])
    cs = _charset(set_name, data_dir, calibrated_dir)
    return fx.FsuVariants(build_fsu(geo, cs, level, facet_stiffness=facet_k, k_shear=k_shear))


def fsu_variants_from_config(config):
    g, f = config.get("geometry", {}), config.get("fsu", {})
    s = discovery_settings(config)
    return _fsu_variants(g.get("kind", "default"), g.get("path"), f.get("level", "L4-L5"), s["characteristic_set"],
                         (config.get("characteristics") or {}).get("data_dir"), f.get("facet_stiffness_n_per_m"),
                         f.get("disc_shear_stiffness_n_per_m"),
                         (config.get("characteristics") or {}).get("calibrated_dir"))


def _charset(name, data_dir, calibrated_dir):
    """The one resolver (lumbar.characteristics.resolve_characteristic_set): "calibrated" from the workflow's
    calibration output when it exists, else the published tables."""
    from .characteristics import resolve_characteristic_set
    return resolve_characteristic_set(name, data_dir=data_dir, calibrated_dir=calibrated_dir)


def _grouped_folds(labels, k):
    cats = list(dict.fromkeys(labels))
    idx = {c: i % max(1, min(k, len(cats))) for i, c in enumerate(cats)}
    return np.array([idx[c] for c in labels])


def _candidates(s, experiment):
    names = fx.effect_names(experiment)
    if s.get("effects"):
        names = [n for n in s["effects"] if n in names]
    return names


def rom_problem(df, config, solver_kw=None) -> Problem:
    s = discovery_settings(config)
    fv = fsu_variants_from_config(config)
    keys = df[["stage", "direction", "moment_nm"]].reset_index(drop=True)
    kw = solver_kw or {}

    def forward(values):
        rom, conv, _, _ = fv.simulate(keys, values, **kw)
        return np.where(conv, rom, np.nan)

    cells = [f"{a}/{b}" for a, b in zip(keys["stage"], keys["direction"])]
    d0 = df.reset_index(drop=True)
    has_range = (np.isfinite(d0["rom_max_deg"].to_numpy(float) - d0["rom_min_deg"].to_numpy(float))
                 & (d0["n_specimens"].to_numpy(int) > 1))
    from .fsu import MAIN_DIRECTIONS, STAGES
    from .stepwise_reduction import scenario_grid
    moments = sorted(set(map(float, keys["moment_nm"])) | set(map(float, benchmark_settings(config)["moments_nm"])))
    design = scenario_grid(STAGES, MAIN_DIRECTIONS, moments).reset_index(drop=True)

    def design_forward(values):
        rom, conv, _, _ = fv.simulate(design, values, **kw)
        return np.where(conv, rom, np.nan)

    return Problem("stepwise_rom", keys, d0["rom_mean_deg"].to_numpy(float), _rom_sigma(d0, s),
                   "deg", forward, _candidates(s, "stepwise_rom"), "stage", ["direction", "moment_nm"],
                   _grouped_folds(cells, s["cv_folds"]),
                   meta={"n_per_row": d0["n_specimens"].to_numpy(int), "has_range": has_range,
                         "sigma_floor": float(s["sigma_floor_deg"]),
                         "design_keys": design, "design_forward": design_forward})


def neutral_problem(df, config) -> Problem:
    s = discovery_settings(config)
    fv = fsu_variants_from_config(config)
    stages = list(df["stage"])
    y = df["lordosis_deg"].to_numpy(float)
    sd = df["lordosis_sd_deg"].to_numpy(float) if "lordosis_sd_deg" in df else np.full(len(df), np.nan)
    sd = np.where(np.isfinite(sd), sd, s["neutral_sd_deg"])
    # the first stage is the reference: changes relative to it are compared (the model has no absolute
    # lordosis of the specimens); sigma of a difference of two independent values
    ref_sd = sd[0]

    def forward(values):
        lord, conv = fv.neutral_lordosis(stages, values)
        d = lord[:, 1:] - lord[:, :1]
        return np.where(conv[:, 1:] & conv[:, :1], d, np.nan)

    keys = pd.DataFrame({"stage": stages[1:], "reference_stage": stages[0]})
    from .fsu import STAGES
    dstages = [stages[0]] + [x for x in STAGES if x != stages[0]]

    def design_forward(values):
        lord, conv = fv.neutral_lordosis(dstages, values)
        d = lord[:, 1:] - lord[:, :1]
        return np.where(conv[:, 1:] & conv[:, :1], d, np.nan)

    return Problem("neutral_angle", keys, y[1:] - y[0], np.hypot(sd[1:], ref_sd), "deg", forward,
                   _candidates(s, "neutral_angle"), "reference_stage", ["stage"], np.arange(len(stages) - 1),
                   meta={"design_keys": pd.DataFrame({"stage": dstages[1:], "reference_stage": stages[0]}),
                         "design_forward": design_forward})


_IDP_MODEL_CACHE: dict = {}


def idp_model_table(config):
    """Internal loads + IDP of the nominal L2-S1 model (49 scenarios): the configured file, else solved once per
    process and configuration (cached: the nominal solve dominates an IDP discovery's time)."""
    s = discovery_settings(config)
    p = s.get("idp_model_table")
    if p and Path(p).is_file():
        return pd.read_csv(p)
    key = json.dumps({k: (config or {}).get(k) for k in ("geometry", "characteristics", "fsu", "l2s1")}
                     | {"set": s["characteristic_set"]}, sort_keys=True, default=str)
    if key not in _IDP_MODEL_CACHE:
        _IDP_MODEL_CACHE[key] = solve_idp_model(config)
    return _IDP_MODEL_CACHE[key].copy()


def solve_idp_model(config):
    from .geometry import load_geometry
    from .l2s1 import LEVELS, derive_cables, run_set
    s = discovery_settings(config)
    g, l2 = config.get("geometry", {}), config.get("l2s1", {})
    geo = load_geometry(g.get("kind", "default"), path=g.get("path") if g.get("kind") == "visible_human" else None,
                        levels=list(LEVELS))
    data_dir = (config.get("characteristics") or {}).get("data_dir")
    cs = _charset(s["characteristic_set"], data_dir, (config.get("characteristics") or {}).get("calibrated_dir"))
    sim, _ = run_set(geo, cs, derive_cables(l2.get("cables")), idp_formula=l2.get("idp_formula", "paper1"),
                     k_shear=(config.get("fsu") or {}).get("disc_shear_stiffness_n_per_m"),
                     moment_nm=l2.get("moment_nm", 3.75))
    sim["idp_per_newton_pa"] = idp_per_newton(l2.get("idp_formula", "paper1"), geo.levels["L4-L5"].disc_csa,
                                               l2.get("disc_area_m2", DISC_AREA_M2))
    return sim


def idp_problem(df, config, model=None) -> Problem:
    s = discovery_settings(config)
    model = idp_model_table(config) if model is None else model
    d = df.reset_index(drop=True).merge(model, on=["muscle_setup", "load_case"], how="left", validate="one_to_one")
    miss = d["idp_mpa"].isna() & ~d["disc_axial_force_n"].isna()
    base = d["idp_mpa"].to_numpy(float) * 1e6
    M = d["disc_moment_sagittal_nm"].to_numpy(float)
    per_n = float(np.nanmedian(d["idp_per_newton_pa"])) if "idp_per_newton_pa" in d else float(
        np.nanmedian(base / d["disc_axial_force_n"].to_numpy(float)))
    if miss.any():
        log.warning("%d scenario(s) without model equilibrium", int(miss.sum()))

    def forward(values):
        return _idp_forward(values, base, M, per_n) / 1e6

    n = d["n_specimens"].to_numpy(float)
    sig = np.maximum(d["idp_sd_mpa"].to_numpy(float) / np.sqrt(np.maximum(n, 1)), s["sigma_floor_mpa"])
    mk = model[np.isfinite(model["idp_mpa"].to_numpy(float))].reset_index(drop=True)
    dbase, dM = mk["idp_mpa"].to_numpy(float) * 1e6, mk["disc_moment_sagittal_nm"].to_numpy(float)

    def design_forward(values):
        return _idp_forward(values, dbase, dM, per_n) / 1e6

    return Problem("idp_invitro", d[["muscle_setup", "load_case"]], d["idp_mean_mpa"].to_numpy(float), sig, "MPa",
                   forward, _candidates(s, "idp_invitro"), "muscle_setup", ["load_case"],
                   _grouped_folds(list(d["muscle_setup"]), s["cv_folds"]),
                   meta={"idp_per_newton_pa": per_n, "n_per_row": n.astype(int), "has_range": n > 1,
                         "sigma_floor": float(s["sigma_floor_mpa"]),
                         "design_keys": mk[["muscle_setup", "load_case"]], "design_forward": design_forward})


def _idp_forward(values, base, M, per_n):
    G = len(next(iter(values.values()))) if values else 1
    out = np.broadcast_to(base, (G, len(base))).copy()
    for name, v in values.items():
        v = np.asarray(v, float)[:, None]
        # effects act one at a time per variant row (the others are 0 there), so applying them in turn is exact
        out = fx.idp_delta(name, v, out, M[None, :], per_n)
    return out


def read_segment_loads(path, level):
    p = Path(path)
    if not p.is_file():
        raise DiscoveryInputError(f"segment-load table not found: {p} (config discovery.in_vivo_segment_loads); "
                                  f"the in-vivo discovery needs the muscle model's segment loads with columns "
                                  f"{list(SEGMENT_LOAD_COLUMNS)}")
    sl = pd.read_csv(p)
    miss = [c for c in SEGMENT_LOAD_COLUMNS if c not in sl.columns]
    if miss:
        raise DiscoveryInputError(f"{p}: column(s) {miss} missing; expected columns {list(SEGMENT_LOAD_COLUMNS)}")
    sl = sl[sl["level"] == level]
    if sl.empty:
        raise DiscoveryInputError(f"{p}: no rows with level {level!r} (config discovery.in_vivo_level)")
    return sl


def in_vivo_problem(df, config, segment_loads=None) -> Problem:
    s = discovery_settings(config)
    sl = read_segment_loads(s["in_vivo_segment_loads"], s["in_vivo_level"]) if segment_loads is None else \
        segment_loads[segment_loads["level"] == s["in_vivo_level"]]
    conv = df["converged"].astype(str).str.lower().isin(["true", "1"])   # read_measured: bool
    d = df[conv].reset_index(drop=True).merge(sl[["activity", "compressive_n", "moment_nm"]], on="activity", how="left")
    if d["moment_nm"].isna().any():
        a = d["activity"][d["moment_nm"].isna()].iat[0]
        raise DiscoveryInputError(f"segment loads: no {s['in_vivo_level']} row for activity {a!r}; expected one row "
                                  f"per activity of the in-vivo table")
    base = d["idp_sim_mpa"].to_numpy(float) * 1e6
    M = d["moment_nm"].to_numpy(float)
    F = d["compressive_n"].to_numpy(float)
    ok = F > 0
    per_n = float(np.median(base[ok] / F[ok])) if ok.any() else idp_per_newton("paper2")

    def forward(values):
        return _idp_forward(values, base, M, per_n) / 1e6

    # design space: every activity of the segment-load table (IDP of activities without a simulated value from
    # the force part, per_n * F: an approximation used only to rank where to measure next)
    sim = dict(zip(d["activity"], base))
    dsl = sl.drop_duplicates("activity").reset_index(drop=True)
    dbase = np.array([sim.get(a, per_n * f) for a, f in zip(dsl["activity"], dsl["compressive_n"].to_numpy(float))])
    dM = dsl["moment_nm"].to_numpy(float)

    def design_forward(values):
        return _idp_forward(values, dbase, dM, per_n) / 1e6

    return Problem("in_vivo", d[["activity"]], d["idp_in_vivo_mpa"].to_numpy(float),
                   np.full(len(d), float(s["in_vivo_sd_mpa"])), "MPa", forward, _candidates(s, "in_vivo"),
                   "experiment", ["activity"], np.arange(len(d)),
                   meta={"idp_per_newton_pa": per_n, "design_keys": dsl[["activity"]], "design_forward": design_forward})


def build_problem(experiment, df, config, **kw) -> Problem:
    if experiment == "stepwise_rom":
        return rom_problem(df, config, kw.get("solver_kw"))
    if experiment == "neutral_angle":
        return neutral_problem(df, config)
    if experiment == "idp_invitro":
        return idp_problem(df, config, kw.get("idp_model"))
    if experiment == "in_vivo":
        return in_vivo_problem(df, config, kw.get("segment_loads"))
    raise ValueError(f"unknown experiment {experiment!r}")


# ------------------------------------------------------------------ fitting and scoring
def _batch(problem, plan):
    """One forward batch: plan = [(effect, values array)], -> list of (len(values), n) predictions."""
    if not plan:
        return []
    sizes = [len(v) for _, v in plan]
    G = sum(sizes)
    values, o = {}, 0
    for name, v in plan:
        arr = values.setdefault(name, np.zeros(G))
        arr[o:o + len(v)] = v
        o += len(v)
    P = problem.forward(values)
    return np.split(P, np.cumsum(sizes)[:-1], axis=0)


def _spline_fit(theta, P, y, w, lo, hi, mask=None):
    """argmin over [lo, hi] of sum w (spline(theta) - y)^2 (per-scenario cubic splines through the grid)."""
    from scipy.interpolate import CubicSpline
    from scipy.optimize import minimize_scalar
    ok = np.isfinite(P).all(0) & (mask if mask is not None else True)
    if ok.sum() == 0:
        return np.nan, np.inf
    cs = CubicSpline(theta, P[:, ok], axis=0)

    def f(t):
        return float((w[ok] * (cs(t) - y[ok]) ** 2).sum())

    vals = [f(t) for t in theta]
    k = int(np.argmin(vals))
    a, b = theta[max(k - 1, 0)], theta[min(k + 1, len(theta) - 1)]
    r = minimize_scalar(f, bounds=(max(a, lo), min(b, hi)), method="bounded", options={"xatol": 1e-6 * (hi - lo)})
    return (float(r.x), float(r.fun)) if r.fun <= vals[k] else (float(theta[k]), float(vals[k]))


def _qaicc(chi2, k, n, c):
    pen = 2 * k + (2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else 0.0)
    return chi2 / c + pen


def _curve(theta_parts, P_parts, lo, hi):
    """Merged, sorted, de-duplicated (theta, P) of a candidate's grids."""
    th = np.concatenate(theta_parts)
    P = np.vstack(P_parts)
    o = np.argsort(th, kind="stable")
    th, P = th[o], P[o]
    keep = np.r_[True, np.diff(th) > 1e-12 * (hi - lo)]
    return th[keep], P[keep]


def _dense(th, P, lo, hi, n_dense=241):
    """Predictions on a dense parameter grid (cubic spline per scenario; scenarios with a missing
    equilibrium somewhere on the grid: nearest grid point, NaN stays NaN)."""
    from scipy.interpolate import CubicSpline
    td = np.unique(np.r_[np.linspace(lo, hi, n_dense), th])
    ok = np.isfinite(P).all(0)
    D = np.full((len(td), P.shape[1]), np.nan)
    if ok.any() and len(th) >= 2:
        D[:, ok] = CubicSpline(th, P[:, ok], axis=0)(td)
    if (~ok).any():
        near = np.abs(td[:, None] - th[None, :]).argmin(1)
        D[:, ~ok] = P[near][:, ~ok]
    return td, D


def _chi2_surface(D, Y, W, valid, penalty=100.0):
    """chi2[d, b] = sum_i W[b,i] (D[d,i] - Y[b,i])^2 over valid scenarios; a missing prediction costs
    ``penalty`` (a 10-sigma residual)."""
    fin = np.isfinite(D) & valid[None, :]
    Df = np.where(fin, D, 0.0)
    Wv = np.where(valid[None, :], W, 0.0)
    Yv = np.where(valid[None, :], Y, 0.0)
    F = fin.astype(float)
    chi = (Df ** 2) @ Wv.T - 2.0 * Df @ (Wv * Yv).T + F @ (Wv * Yv ** 2).T
    chi += penalty * ((~np.isfinite(D)) & valid[None, :]).sum(1)[:, None]
    return np.maximum(chi, 0.0)


def _resample(problem, center, scale, B, rng):
    """B null datasets of ``problem`` around ``center`` with the project's generator (lumbar.discover.
    make_hidden_effect_dataset): per row n virtual specimens, Gaussian noise of one per-specimen SD pooled over the
    rows (RMS of sigma * sqrt(n), times ``scale``), summarised exactly as the experiment's table is (ROM:
    mean, min, max -> sigma from the range, values below 0 deg set to 0; IDP: mean and SD). Rows with a fixed
    uncertainty (no range, in vivo, neutral angle): mean + sigma * scale * N(0, 1). Returns (Y, SIG), (B, n)."""
    y0 = np.where(np.isfinite(center), center, 0.0)
    sig = problem.sigma
    n = len(y0)
    Y = y0[None, :] + scale * sig[None, :] * rng.standard_normal((B, n))
    SIG = np.broadcast_to(sig, (B, n)).copy()
    npr = problem.meta.get("n_per_row")
    hr = problem.meta.get("has_range")
    if npr is None or hr is None:
        return Y, SIG
    # the generator's noise is one SD for every specimen and row: pooled from the rows' spreads
    pooled = float(np.sqrt(np.mean((sig[hr] * np.sqrt(npr[hr])) ** 2))) if hr.any() else 0.0
    for k in np.unique(npr[hr]):
        cols = np.flatnonzero(hr & (npr == k))
        sd = np.full(len(cols), scale * pooled)
        A = y0[cols][None, None, :] + sd[None, None, :] * rng.standard_normal((B, int(k), len(cols)))
        if problem.experiment == "stepwise_rom":
            A = np.maximum(A, 0.0)
            Y[:, cols] = A.mean(1)
            d2 = D2.get(int(k), 3.078)
            SIG[:, cols] = np.maximum((A.max(1) - A.min(1)) / d2 / np.sqrt(k), problem.meta.get("sigma_floor", 0.0))
        else:
            Y[:, cols] = A.mean(1)
            SIG[:, cols] = np.maximum(A.std(1, ddof=1) / np.sqrt(k), problem.meta.get("sigma_floor", 0.0))
    return Y, SIG


def _lr_statistics(curves, Y, W, valid, base):
    """LR statistic of every candidate against "none" per dataset (rows of Y): T = (chi2_none - min chi2_c) / c,
    c = max(1, chi2_none / (n - 1)) the overdispersion of the no-effect model. Returns ({c: T (B,)},
    {c: argmin theta (B,)}, chi2_none (B,))."""
    nv = int(valid.sum())
    chi0 = _chi2_surface(base[None, :], Y, W, valid)[0]
    c0 = np.maximum(1.0, chi0 / max(nv - 1, 1))
    T, th = {}, {}
    for c, (td, D) in curves.items():
        chi = _chi2_surface(D, Y, W, valid)
        k = chi.argmin(0)
        T[c] = np.maximum(chi0 - chi[k, np.arange(chi.shape[1])], 0.0) / c0
        th[c] = td[k]
    return T, th, chi0


def _sensitivities(curves, cands, sig, valid):
    """Sensitivity vector of every candidate on the experiment: (prediction at its reference magnitude - no
    effect) / sigma, from the candidate's grid spline."""
    S = {}
    for c in cands:
        td, D = curves[c]
        ref = float(np.clip(fx.EFFECTS[c].magnitudes[0] if fx.EFFECTS[c].magnitudes else 0.5 * fx.EFFECTS[c].bounds[1],
                            *fx.EFFECTS[c].bounds))
        i0, i1 = np.abs(td).argmin(), np.abs(td - ref).argmin()
        v = (D[i1] - D[i0]) / sig
        S[c] = np.where(valid & np.isfinite(v), v, 0.0)
    return S


def _identifiability(problem, cands, S, s, cache):
    """Pairwise correlation (cosine) of the candidates' sensitivity vectors; for every pair above
    ``max_correlation`` the load cases of the experiment's design space that separate them best: the second
    effect is scaled to mimic the first on the given experiment (least squares), and the design's scenarios are
    ranked by what is left, |s_a - alpha s_b| in units of the experiment's typical sigma."""
    # a candidate that moves no compared row by 1e-3 standard errors at its reference magnitude acts on nothing here
    S = {c: (v if np.linalg.norm(v) > 1e-3 else np.zeros_like(v)) for c, v in S.items()}
    corr = {}
    for i, a in enumerate(cands):
        for b in cands[i + 1:]:
            na, nb = np.linalg.norm(S[a]), np.linalg.norm(S[b])
            corr[(a, b)] = float(S[a] @ S[b] / (na * nb)) if na > 0 and nb > 0 else float("nan")
    thr = float(s["max_correlation"])
    pairs = [(a, b) for (a, b), r in corr.items() if not (np.isfinite(r) and abs(r) < thr)]
    out = {"correlation": {f"{a} | {b}": r for (a, b), r in corr.items()}, "max_correlation": thr,
           "non_separable": []}
    if not pairs:
        return out
    dk, dfwd = problem.meta.get("design_keys"), problem.meta.get("design_forward")
    refs = {c: float(np.clip(fx.EFFECTS[c].magnitudes[0], *fx.EFFECTS[c].bounds)) for c in cands}
    Dsens = None
    if dk is not None and dfwd is not None:
        key = ("design", problem.experiment, tuple(cands), len(dk))
        if cache is not None and key in cache:
            Dsens = cache[key]
        else:
            plan = [(cands[0], np.zeros(1))] + [(c, np.array([refs[c]])) for c in cands]
            sizes = [1] * len(plan)
            values = {}
            for j, (name, v) in enumerate(plan):
                arr = values.setdefault(name, np.zeros(len(plan)))
                arr[j] = v[0]
            P = dfwd(values)
            Dsens = {c: P[j + 1] - P[0] for j, c in enumerate(cands)}
            del sizes
            if cache is not None:
                cache[key] = Dsens
    typ = float(np.nanmedian(problem.sigma))
    measured = set(map(tuple, problem.keys[[c for c in dk.columns if c in problem.keys]].astype(str).to_numpy())) \
        if dk is not None else set()
    for a, b in pairs:
        item = {"pair": [a, b], "correlation": corr[(a, b)], "measure_next": []}
        inert = [c for c in (a, b) if not np.linalg.norm(S[c]) > 0]
        if inert:
            item["inert"] = inert
            item["note"] = f"{' and '.join(inert)} change(s) no compared row of this experiment: not identifiable here"
        if Dsens is not None:
            sa, sb = S[a], S[b]
            alpha = float(sa @ sb / (sb @ sb)) if sb @ sb > 0 else 0.0
            beta = float(sa @ sb / (sa @ sa)) if sa @ sa > 0 else 0.0
            # what is left after either effect mimics the other on the given experiment
            r = np.fmax(np.abs(Dsens[a] - alpha * Dsens[b]), np.abs(Dsens[b] - beta * Dsens[a])) / typ
            order = [i for i in np.argsort(-np.nan_to_num(np.abs(r), nan=-1.0)) if np.isfinite(r[i])]
            for i in order[: int(s["n_next"])]:
                row = {k: (v.item() if hasattr(v, "item") else v) for k, v in dk.iloc[i].items()}
                row["separation_z"] = float(abs(r[i]))
                row["already_measured"] = tuple(str(v) for k, v in dk.iloc[i].items()
                                                if k in problem.keys.columns) in measured
                item["measure_next"].append(row)
            item["how"] = (f"each effect at its reference magnitude ({a} {refs[a]:g} {fx.EFFECTS[a].unit}, {b} "
                           f"{refs[b]:g} {fx.EFFECTS[b].unit}) scaled by least squares to mimic the other on this "
                           f"experiment; separation_z = the larger difference left at a load case of the experiment's "
                           f"design space, in units of its median sigma ({typ:.3g} {problem.unit})")
        out["non_separable"].append(item)
    return out


def discover(problem: Problem, settings: dict | None = None, cache: dict | None = None) -> dict:
    """Rank the candidate effects, name the best one when its bootstrap p-value clears the level, refit
    (see module doc)."""
    s = default_settings()
    s.update(settings or {})
    t0 = time.perf_counter()
    y, sig = problem.y, problem.sigma
    w = 1.0 / sig**2
    cands = list(problem.candidates)
    n_batches = 0
    # batch 1: no-effect model and the coarse grid of every candidate
    grids = {c: np.unique(np.r_[np.linspace(*fx.EFFECTS[c].bounds, int(s["grid_points"])), 0.0]) for c in cands}
    key = ("coarse", problem.experiment, tuple(map(tuple, problem.keys.astype(str).to_numpy())),
           tuple(cands), int(s["grid_points"]))
    if cache is not None and key in cache:
        base, coarse = cache[key]
    else:
        if cands:
            out = _batch(problem, [(cands[0], np.zeros(1))] + [(c, grids[c]) for c in cands])
        else:
            out = [problem.forward({})]
        base, coarse = out[0][0], dict(zip(cands, out[1:]))
        n_batches += 1
        if cache is not None:
            cache[key] = (base, coarse)
    valid = np.isfinite(base) & np.isfinite(y) & np.isfinite(sig)
    z0 = (base - y) / sig
    chi0 = float((z0[valid] ** 2).sum())
    nv = int(valid.sum())
    gap_before = float(np.sqrt(np.mean(z0[valid] ** 2))) if nv else float("nan")
    # coarse estimates, then batch 2: fine grid around each optimum
    est, fine_theta, coarse_chi = {}, {}, {}
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        est[c], coarse_chi[c] = _spline_fit(grids[c], coarse[c], y, w, lo, hi, valid)
    # the fine grid only for the leading candidates (``fine_candidates`` lowest coarse chi2): it refines the
    # estimate that can be named; the others keep their coarse-spline estimate
    lead = sorted([c for c in cands if np.isfinite(est[c])], key=lambda c: coarse_chi[c])[: int(s["fine_candidates"])]
    for c in lead:
        lo, hi = fx.EFFECTS[c].bounds
        step = (hi - lo) / (int(s["grid_points"]) - 1)
        t = est[c]
        fine_theta[c] = np.unique(np.clip(np.linspace(t - step, t + step, int(s["fine_points"])), lo, hi))
    fine = dict(zip(fine_theta, _batch(problem, list(fine_theta.items()))))
    n_batches += bool(fine_theta)
    curves_raw = {}
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        th, P = _curve([grids[c]] + ([fine_theta[c]] if c in fine else []),
                       [coarse[c]] + ([fine[c]] if c in fine else []), lo, hi)
        curves_raw[c] = (th, P)
        if c in fine:
            est[c], _ = _spline_fit(th, P, y, w, lo, hi, valid)
    # batch 3: exact model at every estimate (the refit)
    fin = [(c, np.array([est[c]])) for c in cands if np.isfinite(est[c])]
    exact = {c: p[0] for (c, _), p in zip(fin, _batch(problem, fin))}
    n_batches += bool(fin)
    chi = {"none": chi0}
    for c in exact:
        ok = valid & np.isfinite(exact[c])
        z = (exact[c] - y) / sig
        # a scenario that loses its equilibrium under the effect counts as a large residual (10 sigma)
        chi[c] = float((np.where(ok, z, 10.0)[valid] ** 2).sum())
    # ---- decision statistic: LR vs "none", overdispersion of the no-effect model, parametric bootstrap
    curves = {c: _dense(*curves_raw[c], *fx.EFFECTS[c].bounds) for c in cands}
    T_obs, _, _ = _lr_statistics(curves, y[None, :], w[None, :], valid, base)
    T_obs = {c: float(v[0]) for c, v in T_obs.items()}
    too_few = nv < int(s["min_rows"])
    B = int(s["n_bootstrap"])
    c_hat0 = max(1.0, chi0 / max(nv - 1, 1))
    p_adj, p_raw, Tmax_null = {}, {}, np.array([])
    if cands and not too_few and B > 0:
        rng = np.random.default_rng([int(s.get("seed", 0)), 15])
        Yb, Sb = _resample(problem, base, np.sqrt(c_hat0), B, rng)
        Tb, _, _ = _lr_statistics(curves, Yb, 1.0 / Sb ** 2, valid, base)
        Tmax_null = np.max(np.vstack([Tb[c] for c in cands]), axis=0)
        for c in cands:
            p_raw[c] = float((1 + np.sum(Tb[c] >= T_obs[c] - 1e-12)) / (B + 1))
            p_adj[c] = float((1 + np.sum(Tmax_null >= T_obs[c] - 1e-12)) / (B + 1))
    # ---- ranking (by the LR statistic), confidence among the candidates, diagnostics
    cand_rank = sorted(cands, key=lambda c: -T_obs[c])
    best = cand_rank[0] if cand_rank else None
    chat = max(1.0, min(chi.values()) / max(nv - 1, 1))
    score = {m: _qaicc(v, 0 if m == "none" else 1, nv, chat) for m, v in chi.items()}
    c_best = max(1.0, chi[best] / max(nv - 1, 1)) if best in chi else 1.0
    cw = {c: np.exp(-0.5 * (chi[c] - min(chi[k] for k in exact)) / c_best) for c in exact}
    tot = sum(cw.values())
    cw = {c: float(v / tot) for c, v in cw.items()} if tot > 0 else {}
    cv = _cross_validate(problem, cands, grids, coarse, fine_theta, fine, exact, y, w, sig, valid, gap_before) \
        if nv >= 3 else {"none": gap_before}
    gap_after_best = float("nan")
    if best is not None and best in exact:
        zb = (exact[best] - y) / sig
        gap_after_best = float(np.sqrt(np.mean(np.where(np.isfinite(zb), zb, 10.0)[valid] ** 2)))
    reasons = []
    alpha = float(s["alpha"])
    if best is None:
        reasons.append("no candidate effect acts on this experiment")
    elif too_few:
        reasons.append(f"too few rows: {nv} scenario(s) compared, at least {int(s['min_rows'])} needed to test "
                       f"{len(cands)} candidate(s) against the measurement noise; nothing can be named from these data")
    else:
        if not gap_before > s["min_gap"]:
            reasons.append(f"gap_before {gap_before:.2f} <= min_gap {s['min_gap']:g}: model and data agree within "
                           f"the measurement uncertainty")
        if not p_adj.get(best, 1.0) < alpha:
            reasons.append(f"p = {p_adj.get(best, float('nan')):.3g} for {best} (max-T over {len(cands)} candidates, "
                           f"{B} bootstrap null datasets) is not below alpha {alpha:g}")
        red = 1 - gap_after_best / gap_before if gap_before > 0 else 0.0
        if not red >= s["min_gap_reduction"]:
            reasons.append(f"refit reduces the gap by {100 * red:.0f}% < {100 * s['min_gap_reduction']:.0f}%")
    named = best if best is not None and not reasons else None
    after = exact[named] if named else base
    z1 = (after - y) / sig
    gap_after = gap_after_best if named else gap_before
    rms_phys0 = float(np.sqrt(np.mean((base - y)[valid] ** 2))) if nv else float("nan")
    dev1 = np.where(np.isfinite(after), after - y, np.nan)[valid]
    rms_phys1 = float(np.sqrt(np.mean(dev1 ** 2))) if nv else float("nan")
    scen = problem.keys.copy()
    scen["measured"] = y
    scen["sigma"] = sig
    scen["model_before"] = base
    scen["z_before"] = z0
    scen["model_after"] = after
    scen["z_after"] = z1
    scen["unit"] = problem.unit
    eff = fx.EFFECTS.get(named) if named else None

    def at_bound(c):
        lo, hi = fx.EFFECTS[c].bounds
        return bool(np.isfinite(est[c]) and min(est[c] - lo, hi - est[c]) <= 1e-3 * (hi - lo))

    ident = _identifiability(problem, cands, _sensitivities(curves, cands, sig, valid), s, cache) \
        if len(cands) >= 2 and nv >= 1 else {"correlation": {}, "max_correlation": float(s["max_correlation"]),
                                             "non_separable": []}
    ranking = [["none", 0.0]] + [[c, T_obs[c]] for c in cand_rank]
    ranking = sorted(ranking, key=lambda kv: -kv[1])
    res = {
        "experiment": problem.experiment,
        "n_scenarios": nv,
        "unit": problem.unit,
        "named_effect": named,
        "parameter_estimate": ({"effect": named, "parameter": eff.parameter, "value": est[named], "unit": eff.unit,
                                "at_bound": at_bound(named)} if named else None),
        "p_value": p_adj.get(best) if best is not None and not too_few else None,
        "p_value_method": (f"single-step max-T (Westfall-Young): share of {B} parametric-bootstrap null datasets "
                           f"(no effect, the project's generator around the nominal model, noise x sqrt(c) with "
                           f"c = {c_hat0:.3g} the no-effect model's overdispersion) whose largest LR statistic over "
                           f"the {len(cands)} candidates reaches the observed one, (1 + k) / (B + 1); corrected for "
                           f"the number of candidates"),
        "alpha": alpha,
        "null_distribution_size": int(len(Tmax_null)),
        "null_lr_quantiles": ({q: float(np.quantile(Tmax_null, float(q))) for q in ("0.5", "0.95", "0.99")}
                              if len(Tmax_null) else None),
        "lr_statistic": T_obs,
        "p_values_adjusted": p_adj,
        "p_values_unadjusted": p_raw,
        "gap_before": gap_before, "gap_after": gap_after,
        "gap_after_above_threshold": bool(np.isfinite(gap_after) and gap_after > s["min_gap"]),
        "gap_before_rms": rms_phys0, "gap_after_rms": rms_phys1,
        "gap_reduction": (1 - gap_after / gap_before) if gap_before > 0 else 0.0,
        "ranking": ranking,
        "confidence": cw.get(named) if named else None,
        "confidence_definition": ("probability of the named effect among the candidates: weights exp(-chi2_c / "
                                  "(2 c_best)) normalised over the candidates (each has one parameter); null when "
                                  "nothing is named"),
        "candidate_weights": cw,
        "best_candidate": best,
        "best_candidate_estimate": est.get(best) if best else None,
        "best_candidate_gap_after": gap_after_best,
        "estimates": {c: est[c] for c in cands},
        "at_bound": {c: at_bound(c) for c in cands},
        "bounds": {c: list(fx.EFFECTS[c].bounds) for c in cands},
        "too_few_rows": bool(too_few),
        "identifiability": ident,
        "qaicc": score,
        "cv_rms_z": cv,
        "overdispersion_none": c_hat0,
        "decision": ("named: p below alpha, gap above min_gap, refit reduces it by min_gap_reduction" if named
                     else "nothing named: " + "; ".join(reasons)),
        "criterion": ("LR statistic T_c = (chi2_none - chi2_c) / c, c = max(1, chi2_none / (n - 1)); p-value by "
                      "parametric bootstrap (max-T over candidates); gap = RMS of z"),
        "margins": {k: s[k] for k in ("alpha", "min_gap", "min_gap_reduction", "min_rows", "n_bootstrap")},
        "forward_batches": n_batches,
        "seconds": time.perf_counter() - t0,
    }
    return {"result": res, "scenarios": scen, "problem": problem}


def _cross_validate(problem, cands, grids, coarse, fine_theta, fine, exact, y, w, sig, valid, gap_before):
    """Grouped cross-validation of the RMS z (held-out folds; on the coarse + fine splines). Diagnostic only."""
    from scipy.interpolate import CubicSpline
    cv = {"none": gap_before}
    folds = problem.folds
    if len(np.unique(folds[valid])) < 2:
        return cv
    for c in exact:
        zc = np.full(len(y), np.nan)
        lo, hi = fx.EFFECTS[c].bounds
        th, P = _curve([grids[c], fine_theta.get(c, np.empty(0))],
                       [coarse[c], fine.get(c, np.empty((0, len(y))))], lo, hi)
        okc = np.isfinite(P).all(0)
        for f in np.unique(folds[valid]):
            tr, te = valid & (folds != f), valid & (folds == f)
            t, _ = _spline_fit(th, P, y, w, lo, hi, tr)
            pred = np.full(len(y), np.nan)
            if np.isfinite(t):
                pred[okc] = CubicSpline(th, P[:, okc], axis=0)(t)
            zc[te] = np.where(np.isfinite(pred[te]), (pred[te] - y[te]) / sig[te], 10.0)
        cv[c] = float(np.sqrt(np.nanmean(zc[valid] ** 2)))
    return cv


# ------------------------------------------------------------------ figures (object API, no pyplot), report section
def _save(fig, path):
    from .io import atomic_writer
    with atomic_writer(path, "wb", encoding=None, newline=None) as f:
        fig.savefig(f, format="png", dpi=110, metadata={"Software": None})


def _col_label(vals, keys):
    return " ".join(f"{v} N*m" if k == "moment_nm" else str(v) for k, v in zip(keys, vals))


def _pivot(scen, problem, col):
    rows = list(dict.fromkeys(scen[problem.row_key].astype(str))) if problem.row_key in scen else ["all"]
    ck = problem.col_keys
    cc = [_col_label(v, ck) for v in scen[ck].astype(str).to_numpy()]
    cols = list(dict.fromkeys(cc))
    M = np.full((len(rows), len(cols)), np.nan)
    rk = scen[problem.row_key].astype(str) if problem.row_key in scen else pd.Series(["all"] * len(scen))
    for r, c, v in zip(rk, cc, scen[col]):
        M[rows.index(r), cols.index(c)] = v
    return rows, cols, M


def _heat(ax, rows, cols, M, vmax, title):
    im = ax.imshow(M, cmap="RdBu_r", vmin=-vmax, vmax=vmax, aspect="auto")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(rows, fontsize=7)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels(cols, fontsize=6, rotation=70, ha="right")
    ax.set_title(title, fontsize=8, wrap=True)
    if M.size <= 200:
        for i in range(M.shape[0]):
            for j in range(M.shape[1]):
                if np.isfinite(M[i, j]):
                    # dark text on pale cells, white on saturated ones
                    col = "white" if abs(M[i, j]) > 0.6 * vmax else "black"
                    ax.text(j, i, f"{M[i, j]:.1f}", ha="center", va="center", fontsize=6, color=col)
    return im


def _map_size(rows, cols):
    return max(6.5, min(16, 2.5 + 0.4 * len(cols))), 2.2 + 0.35 * len(rows)


def plot_disagreement_map(out, path):
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M = _pivot(scen, p, "z_before")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M), 95))) if np.isfinite(M).any() else 3.0
    fig, ax = subplots(figsize=_map_size(rows, cols), constrained_layout=True)
    im = _heat(ax, rows, cols, M, vmax, f"{p.experiment}: z = (model - measured) / sigma\n"
               f"gap (RMS z) = {r['gap_before']:.2f}; RMS {r['gap_before_rms']:.3g} {p.unit}")
    fig.colorbar(im, ax=ax, label="z (standard errors; + model above measurement)")
    _save(fig, path)


def plot_ranking(out, path):
    r = out["result"]
    items = [(m, v) for m, v in r["ranking"] if m != "none"]
    fig, ax = subplots(figsize=(7.5, 1.6 + 0.4 * max(1, len(items))), constrained_layout=True)
    names = [m for m, _ in items][::-1]
    vals = [v for _, v in items][::-1]
    colors = ["tab:green" if m == r["named_effect"] else "0.6" for m in names]
    ax.barh(names, vals, color=colors)
    q = r.get("null_lr_quantiles") or {}
    if q.get("0.99") is not None:
        ax.axvline(q["0.99"], color="k", ls="--", lw=0.8, label="99 % of the bootstrap null (max over candidates)")
        ax.legend(fontsize=7, loc="lower right")
    for i, m in enumerate(names):
        pa = (r.get("p_values_adjusted") or {}).get(m)
        ps = f"p={pa:.3g}" if pa is not None else "p: not tested"
        est = r["estimates"].get(m)
        est_s = "nan" if est is None else f"{est:.3g} {fx.EFFECTS[m].unit}"
        ax.text(max(vals[i], 0), i, f" {ps}, est={est_s}", va="center", fontsize=7)
    ax.set_xlabel("LR statistic vs no effect, (chi2_none - chi2_effect) / c  [-]")
    if r["named_effect"]:
        t = f"named: {r['named_effect']} (p = {r['p_value']:.3g}, confidence {r['confidence']:.2f})"
    elif r.get("too_few_rows"):
        t = f"nothing named: too few rows ({r['n_scenarios']})"
    else:
        pv = r.get("p_value")
        t = f"nothing named (best {r['best_candidate']}, p = {pv:.3g})" if pv is not None else "nothing named"
    ax.set_title(t, fontsize=9)
    ax.set_xlim(0, max(vals + [1.0]) * 1.6)
    _save(fig, path)


def plot_before_after(out, path):
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M0 = _pivot(scen, p, "z_before")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M0), 95))) if np.isfinite(M0).any() else 3.0
    w, h = _map_size(rows, cols)
    if not r["named_effect"]:
        # nothing added: one map and the reason (not the same map twice)
        fig, ax = subplots(figsize=(w, h + 0.6), constrained_layout=True)
        im = _heat(ax, rows, cols, M0, vmax, f"nothing named, the model is unchanged: gap {r['gap_before']:.2f} "
                   f"(RMS {r['gap_before_rms']:.3g} {p.unit})")
        ax.set_xlabel("; ".join(r["decision"].split(": ", 1)[-1].split("; ")[:1])[:110], fontsize=7)
        fig.colorbar(im, ax=ax, label="z (standard errors)")
        _save(fig, path)
        return
    _, _, M1 = _pivot(scen, p, "z_after")
    fig, axes = subplots(2, 1, figsize=(w, 2 * h + 0.4), constrained_layout=True)
    _heat(axes[0], rows, cols, M0, vmax, f"before: gap {r['gap_before']:.2f} (RMS {r['gap_before_rms']:.3g} {p.unit})")
    im = _heat(axes[1], rows, cols, M1, vmax, f"after adding {r['named_effect']}: "
               f"gap {r['gap_after']:.2f} (RMS {r['gap_after_rms']:.3g} {p.unit})")
    fig.colorbar(im, ax=axes, label="z (standard errors)")
    _save(fig, path)


def _fmt(v, spec=".3g"):
    return "n/a" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


def section_markdown(out, measured_path) -> str:
    r = out["result"]
    pe = r["parameter_estimate"]
    lines = [f"## Discrepancy discovery: `{measured_path}`", "",
             f"Experiment **{r['experiment']}**, {r['n_scenarios']} scenarios. Residuals are scaled by the "
             f"measurement uncertainty of each row (z, in standard errors); the gap is the RMS of z.", "",
             f"- gap before: **{r['gap_before']:.2f}** (RMS {r['gap_before_rms']:.3g} {r['unit']})",
             f"- named effect: **{r['named_effect'] or 'none'}**"
             + (f", {pe['parameter']} = {pe['value']:.4g} {pe['unit']}"
                + (" (AT ITS BOUND)" if pe["at_bound"] else "")
                + f"; p = {r['p_value']:.3g}; confidence among the candidates {r['confidence']:.2f}"
                if r["named_effect"] else ""),
             f"- gap after: **{r['gap_after']:.2f}** (RMS {r['gap_after_rms']:.3g} {r['unit']}; "
             f"reduction {100 * r['gap_reduction']:.0f}%)"
             + (" - still above the threshold min_gap" if r["gap_after_above_threshold"] else ""),
             f"- decision: {r['decision']}", "",
             "| rank | effect | LR statistic | p (adjusted) | estimate | at bound | CV RMS z |",
             "|---|---|---|---|---|---|---|"]
    k = 0
    for m, v in r["ranking"]:
        if m == "none":
            continue
        k += 1
        est = r["estimates"].get(m)
        est_s = "" if est is None else f"{est:.4g} {fx.EFFECTS[m].unit}"
        lines.append(f"| {k} | {m} | {v:.2f} | {_fmt(r['p_values_adjusted'].get(m))} | {est_s} | "
                     f"{'yes' if r['at_bound'].get(m) else 'no'} | {_fmt(r['cv_rms_z'].get(m), '.2f')} |")
    ns = r["identifiability"]["non_separable"]
    lines += ["", f"Identifiability (correlation of sensitivity vectors; pairs with |r| >= "
                  f"{r['identifiability']['max_correlation']:g} are not separable on this experiment):"]
    if not ns:
        lines.append("every pair of candidates is separable here.")
    for it in ns:
        nxt = "; ".join(", ".join(f"{kk}={vv}" for kk, vv in m.items() if kk not in ("separation_z",
                                                                                      "already_measured"))
                        + f" (separation {m['separation_z']:.2g} z" + (", already measured" if m["already_measured"]
                                                                       else "") + ")"
                        for m in it["measure_next"])
        lines.append(f"- {it['pair'][0]} vs {it['pair'][1]}: r = {_fmt(it['correlation'], '.3f')}"
                     + (f" ({it['note']})" if it.get("note") else "") + f"; measure next: {nxt or 'n/a'}")
    lines += ["", "![disagreement map](disagreement_map.png)", "", "![ranking](ranking.png)", "",
              "![before/after](before_after.png)", "",
              f"Naming rule: {json.dumps(r['margins'])}; criterion: {r['criterion']}.", ""]
    return "\n".join(lines)


def write_outputs(out, out_dir, measured_path):
    from .io import write_json_atomic, write_table_atomic, write_text_atomic
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    res = dict(out["result"])
    log.info("discovery on %s took %.2f s (%d forward batches)", measured_path, res.pop("seconds", float("nan")),
             res["forward_batches"])      # timings stay out of the result files (deterministic outputs)
    res["measured"] = str(measured_path)
    res = _jsonable(res)
    write_json_atomic(res, d / "discovery.json", allow_nan=True)
    write_table_atomic(out["scenarios"], d / "scenarios.csv")
    plot_disagreement_map(out, d / "disagreement_map.png")
    plot_ranking(out, d / "ranking.png")
    plot_before_after(out, d / "before_after.png")
    write_text_atomic(section_markdown(out, measured_path), d / "section.md")
    return d / "discovery.json"


def _jsonable(o):
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, np.integer):
        return int(o)
    return o


def run(config, measured, out_dir, segment_loads=None, idp_model=None, cache=None):
    """Read, build the problem, discover, write outputs; returns the result dict."""
    exp, df = read_measured(measured)
    prob = build_problem(exp, df, config, segment_loads=segment_loads, idp_model=idp_model)
    if not prob.candidates:
        raise DiscoveryInputError(f"no candidate effect of config discovery.effects acts on experiment {exp}; "
                                  f"effects acting there: {fx.effect_names(exp)}")
    out = discover(prob, discovery_settings(config), cache=cache)
    write_outputs(out, out_dir, measured)
    return out["result"]


# ------------------------------------------------------------------ real measurements (issue 15)
REAL_DATA_COLUMNS = ("dataset", "n_rows", "gap_before", "named_effect", "p_value", "estimate", "gap_after", "note")


def real_data_summary(paths) -> pd.DataFrame:
    """One row per discovery run on real measurements (its ``discovery.json``): dataset (= run directory),
    n_rows, gap_before, named_effect ("" = nothing named), p_value, estimate (with unit), gap_after and a note
    (the reason when nothing is named; bounds and residual gaps flagged)."""
    rows = []
    for p in paths:
        p = Path(p)
        r = json.loads(p.read_text())
        pe = r.get("parameter_estimate")
        notes = []
        if r.get("named_effect"):
            notes.append(f"named at p = {r['p_value']:.3g} (alpha {r['margins']['alpha']:g}); confidence among the "
                         f"candidates {r['confidence']:.2f}")
            if pe and pe.get("at_bound"):
                notes.append("estimate AT ITS BOUND")
            if r.get("gap_after_above_threshold"):
                notes.append("gap after the refit still above min_gap: more is missing")
        else:
            notes.append(r["decision"])
            if r.get("best_candidate") and not r.get("too_few_rows"):
                notes.append(f"best candidate {r['best_candidate']} (estimate {r['best_candidate_estimate']:.4g})")
        ns = (r.get("identifiability") or {}).get("non_separable") or []
        if ns:
            notes.append("not separable here: " + ", ".join(" vs ".join(i["pair"]) for i in ns))
        rows.append({"dataset": p.parent.name, "n_rows": r["n_scenarios"], "gap_before": r["gap_before"],
                     "named_effect": r.get("named_effect") or "", "p_value": r.get("p_value"),
                     "estimate": f"{pe['value']:.4g} {pe['unit']}" if pe else "",
                     "gap_after": r["gap_after"], "note": "; ".join(notes) + f" [{r.get('measured', '')}]"})
    return pd.DataFrame(rows, columns=list(REAL_DATA_COLUMNS))


# ------------------------------------------------------------------ benchmark with hidden effects (fixtures)
def benchmark_settings(config) -> dict:
    """The ``discovery.benchmark`` settings: the schema's defaults updated by ``config``."""
    b = schema_defaults("discovery", "benchmark")
    b.update(((config or {}).get("discovery") or {}).get("benchmark") or {})
    return b


def benchmark_magnitudes(name, b) -> list[tuple[str, float]]:
    """(label, magnitude) of one effect: the first n_magnitudes of lumbar.effects.EFFECTS[name].magnitudes
    ("m1", "m2") and near-threshold ones, factor x the smallest ("near0.25")."""
    e = fx.check_effect(name)
    mags = [(f"m{j + 1}", float(m)) for j, m in enumerate(e.magnitudes[: int(b["n_magnitudes"])])]
    mags += [(f"near{f:g}", float(f) * float(min(e.magnitudes))) for f in b.get("near_threshold_factors") or []]
    return mags


def benchmark_cases(config) -> pd.DataFrame:
    """Every benchmark case: (case, experiment, hidden_effect, magnitude_label, magnitude, seed); n_seeds per
    effect and magnitude, n_null null datasets alternating between the experiments."""
    b = benchmark_settings(config)
    seed = int((config or {}).get("seed", 0))
    names = b["effects"] or [n for n, e in fx.EFFECTS.items() if e.experiments]
    rows = []
    for name in names:
        e = fx.check_effect(name)
        exps = [x for x in e.experiments if x in ("stepwise_rom", "idp_invitro") and
                (not b["experiments"] or x in b["experiments"])]
        for x in exps:
            for lab, mag in benchmark_magnitudes(name, b):
                for k in range(int(b["n_seeds"])):
                    rows.append((f"{name}_{x}_{lab}_s{k + 1}", x, name, lab, mag))
    exps = [x for x in ("stepwise_rom", "idp_invitro") if not b["experiments"] or x in b["experiments"]]
    for k in range(int(b["n_null"])):
        x = exps[k % len(exps)]
        rows.append((f"null_{x}_{k + 1}", x, "none", "none", 0.0))
    df = pd.DataFrame(rows, columns=["case", "experiment", "hidden_effect", "magnitude_label", "magnitude"])
    df["seed"] = [seed + 1000 + i for i in range(len(df))]
    return df


def make_hidden_effect_dataset(config, experiment, effect, magnitude, seed, idp_model=None) -> pd.DataFrame:
    """A measured-schema table with ``effect`` hidden at ``magnitude`` and measurement noise (a TEST FIXTURE).

    Generated from the nominal model's batch directly (documented shortcut for speed): the ROM (or IDP)
    of the calibration model with the effect switched on, measured on ``n_specimens`` virtual specimens
    that differ only by Gaussian measurement noise (``noise_sd_deg`` / ``noise_sd_mpa``); the table keeps
    the experiment's schema (mean, min/max or SD, n) with kind ``surrogate`` and a source naming it a
    fixture. ``lumbar.virtual_experiment.stepwise_reduction_table(effects=...)`` /
    ``idp_table(effects=...)`` make the same with full specimen variation.
    """
    b = benchmark_settings(config)
    rng = np.random.default_rng(int(seed))
    n = int(b["n_specimens"])
    vals = {} if effect == "none" else {effect: np.array([float(magnitude)])}
    src = (f"TEST FIXTURE (benchmark): hidden effect {effect} = {magnitude:g} "
           f"{fx.EFFECTS[effect].unit if effect != 'none' else ''}, seed {seed}, {n} noisy measurements of the "
           f"calibration model (lumbar.discover.make_hidden_effect_dataset); not data")
    if experiment == "stepwise_rom" and b.get("generator") == "virtual_specimens":
        out = _virtual_specimen_rom(config, b, effect, magnitude, seed)
        out["source"] = src.replace("noisy measurements of the calibration model",
                                    "virtual specimens (lumbar.virtual_experiment.stepwise_reduction_table)")
        return out
    if experiment == "stepwise_rom":
        from .fsu import MAIN_DIRECTIONS, STAGES
        from .stepwise_reduction import scenario_grid
        scen = scenario_grid(b["stages"] or STAGES, MAIN_DIRECTIONS, b["moments_nm"])
        fv = fsu_variants_from_config(config)
        if effect != "none" and effect not in fx.SOLVER_EFFECTS:
            raise ValueError(f"effect {effect!r} does not act on stepwise_rom")
        rom, conv, _, _ = fv.simulate(scen, vals)
        A = rom[0][None, :] + rng.normal(0.0, b["noise_sd_deg"], (n, len(scen)))
        A = np.maximum(A, 0.0)
        keep = conv[0]
        out = scen[keep].reset_index(drop=True)
        A = A[:, keep]
        out["rom_mean_deg"], out["rom_min_deg"], out["rom_max_deg"] = A.mean(0), A.min(0), A.max(0)
        out["n_specimens"] = n
    elif experiment == "idp_invitro":
        model = idp_model_table(config) if idp_model is None else idp_model
        base = model["idp_mpa"].to_numpy(float) * 1e6
        idp = _idp_forward(vals, base, model["disc_moment_sagittal_nm"].to_numpy(float),
                           float(np.nanmedian(model["idp_per_newton_pa"])))[0] / 1e6
        A = idp[None, :] + rng.normal(0.0, b["noise_sd_mpa"], (n, len(idp)))
        out = model[["muscle_setup", "load_case"]].copy()
        out["idp_mean_mpa"], out["idp_sd_mpa"] = A.mean(0), A.std(0, ddof=1)
        out["n_specimens"] = n
    else:
        raise ValueError(f"no hidden-effect generator for experiment {experiment!r}")
    out["kind"] = "surrogate"
    out["source"] = src
    return out


def _virtual_specimen_rom(config, b, effect, magnitude, seed):
    """ROM fixture with full specimen variation (geometry, ligaments, disc, facets): slower, harder nulls."""
    from .fsu import STAGES
    from .geometry import load_geometry
    from .virtual_experiment import stepwise_reduction_table
    g, f = config.get("geometry", {}), config.get("fsu", {})
    level = f.get("level", "L4-L5")
    geo = load_geometry(g.get("kind", "default"), path=g.get("path") if g.get("kind") == "visible_human" else None,
                        levels=[level])
    cs = _charset(discovery_settings(config)["characteristic_set"], (config.get("characteristics") or {}).get("data_dir"),
                  (config.get("characteristics") or {}).get("calibrated_dir"))
    df = stepwise_reduction_table(geo, cs, int(seed), n_specimens=int(b["n_specimens"]), noise_sd_deg=b["noise_sd_deg"],
                                  effects=None if effect == "none" else {effect: float(magnitude)},
                                  moments_nm=tuple(b["moments_nm"]), level=level,
                                  k_shear=f.get("disc_shear_stiffness_n_per_m"))
    return df[df["stage"].isin(b["stages"] or STAGES)].reset_index(drop=True)


def run_benchmark_cases(config, cases: pd.DataFrame, fixture_dir, out_dir=None, idp_model=None,
                        worked_cases=0) -> pd.DataFrame:
    """Generate each case's fixture (``hidden_effect_<name>_<mag>_..._fixture.csv``), discover, score.

    All outputs of the discovery (figures, section.md) are written for every case to ``out_dir/<case>`` when
    it is given, else for the first ``worked_cases`` cases to ``fixture_dir/<case>`` (worked examples)."""
    from .io import write_table_atomic
    fixture_dir = Path(fixture_dir)
    fixture_dir.mkdir(parents=True, exist_ok=True)
    cache = {}
    rows = []
    s = discovery_settings(config)
    need_idp = (cases["experiment"] == "idp_invitro").any()
    if need_idp and idp_model is None:
        idp_model = idp_model_table(config)
    for c in cases.itertuples(index=False):
        df = make_hidden_effect_dataset(config, c.experiment, c.hidden_effect, c.magnitude, c.seed, idp_model)
        fname = fixture_dir / f"hidden_effect_{c.hidden_effect}_{c.magnitude:.6g}_{c.experiment}_seed{c.seed}_fixture.csv"
        write_table_atomic(df, fname, float_format="%.9g")
        t = time.perf_counter()
        prob = build_problem(c.experiment, df, config, idp_model=idp_model)
        out = discover(prob, s, cache=cache)
        r = out["result"]
        if out_dir is not None or len(rows) < worked_cases:
            write_outputs(out, Path(out_dir or fixture_dir) / c.case, fname)
        named = r["named_effect"] or "none"
        est = r["parameter_estimate"]["value"] if r["parameter_estimate"] else np.nan
        if c.hidden_effect != "none" and named != c.hidden_effect:
            est = r["estimates"].get(c.hidden_effect, np.nan)
        rows.append(dict(case=c.case, experiment=c.experiment, hidden_effect=c.hidden_effect,
                         magnitude_label=getattr(c, "magnitude_label", ""), magnitude=c.magnitude,
                         named_effect=named, correct=named == c.hidden_effect,
                         param_true=c.magnitude if c.hidden_effect != "none" else np.nan, param_est=est,
                         p_value=r["p_value"] if r["p_value"] is not None else np.nan,
                         best_candidate=r["best_candidate"] or "none",
                         at_bound=bool(r["at_bound"].get(named, False)) if named != "none" else False,
                         gap_before=r["gap_before"], gap_after=r["gap_after"],
                         confidence=r["confidence"] if r["confidence"] is not None else np.nan,
                         seconds=time.perf_counter() - t, fixture=fname.name))
        log.info("benchmark %s: hidden %s -> named %s (gap %.2f -> %.2f)", c.case, c.hidden_effect, named,
                 r["gap_before"], r["gap_after"])
    return pd.DataFrame(rows)


TARGETS = {"false_positive_rate_max": 0.05, "power_at_larger_magnitude_min": 0.9}


def _interval(k, n, level=0.95):
    """Clopper-Pearson (exact binomial) interval of k successes in n."""
    from scipy.stats import beta
    if n == 0:
        return [float("nan"), float("nan")]
    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return [lo, hi]


def summarise_benchmark(bench: pd.DataFrame, generator="batch") -> dict:
    """False-positive rate over the nulls (with its 95 % Clopper-Pearson interval), detection power and
    parameter error per effect and magnitude, and the targets of issue 15."""
    hid = bench[bench["hidden_effect"] != "none"]
    nul = bench[bench["hidden_effect"] == "none"]
    k_fp = int((nul["named_effect"] != "none").sum())
    rel = (np.abs(hid["param_est"] - hid["param_true"]) / np.abs(hid["param_true"])).to_numpy(float)
    m = {"n_cases": int(len(bench)), "n_hidden": int(len(hid)), "n_null": int(len(nul)),
         "false_positives": k_fp,
         "false_positive_rate": k_fp / len(nul) if len(nul) else float("nan"),
         "false_positive_rate_95ci": _interval(k_fp, len(nul)),
         "null_named": dict(nul.loc[nul["named_effect"] != "none", "named_effect"].value_counts().sort_index()),
         "naming_accuracy": float(hid["correct"].mean()) if len(hid) else float("nan")}
    power = []
    lab_col = "magnitude_label" if "magnitude_label" in hid else None
    for (eff, mag), g in hid.groupby(["hidden_effect", "magnitude"], sort=True):
        r = (np.abs(g["param_est"] - g["param_true"]) / np.abs(g["param_true"])).to_numpy(float)
        ok = g["correct"].to_numpy(bool)
        power.append({"effect": eff, "magnitude": float(mag), "unit": fx.EFFECTS[eff].unit,
                      "label": str(g[lab_col].iat[0]) if lab_col else "",
                      "n": int(len(g)), "detected": int(ok.sum()), "power": float(ok.mean()),
                      "power_95ci": _interval(int(ok.sum()), len(g)),
                      "wrong_effect_named": int(((g["named_effect"] != "none") & ~ok).sum()),
                      "median_param_rel_error": float(np.nanmedian(r[ok])) if ok.any() else float("nan"),
                      "max_param_rel_error": float(np.nanmax(r[ok])) if ok.any() else float("nan")})
    m["power"] = power
    larger = [p for p in power if p["magnitude"] == max(q["magnitude"] for q in power if q["effect"] == p["effect"])]
    m["power_at_larger_magnitude"] = {p["effect"]: p["power"] for p in larger}
    m["median_param_rel_error_detected"] = float(np.nanmedian(rel[hid["correct"].to_numpy(bool)])) \
        if hid["correct"].any() else float("nan")
    m["pass"] = {"false_positive_rate_max": bool(len(nul) > 0 and m["false_positive_rate"] <= TARGETS[
        "false_positive_rate_max"]),
                 "power_at_larger_magnitude_min": bool(larger) and all(p["power"] >= TARGETS[
                     "power_at_larger_magnitude_min"] for p in larger)}
    m["targets"] = dict(TARGETS)
    m["all_pass"] = all(m["pass"].values())
    m["not_benchmarked"] = {n: "acts on no available experiment: no scenario loads the L4-L5 disc in tension"
                            for n, e in fx.EFFECTS.items() if not e.experiments}
    m["generator"] = {"batch": "ROM and IDP fixtures from the calibration model's batch directly + Gaussian "
                               "measurement noise per virtual specimen (no geometric/material specimen variation), "
                               "for speed",
                      "virtual_specimens": "ROM fixtures from virtual specimens with full variation "
                                           "(lumbar.virtual_experiment.stepwise_reduction_table); IDP fixtures from "
                                           "the batch + noise"}[generator]
    return _jsonable(m)


def plot_benchmark(bench: pd.DataFrame, summary: dict, path):
    fig, axes = subplots(1, 3, figsize=(15, 4.8), constrained_layout=True)
    labels = sorted(set(bench["hidden_effect"]) | set(bench["named_effect"]))
    C = np.zeros((len(labels), len(labels)))
    for h, n in zip(bench["hidden_effect"], bench["named_effect"]):
        C[labels.index(h), labels.index(n)] += 1
    axes[0].imshow(C, cmap="Greens")
    for i in range(len(labels)):
        for j in range(len(labels)):
            if C[i, j]:
                axes[0].text(j, i, int(C[i, j]), ha="center", va="center", fontsize=8,
                             color="white" if C[i, j] > 0.6 * C.max() else "black")
    axes[0].set_xticks(range(len(labels)))
    axes[0].set_xticklabels(labels, rotation=60, ha="right", fontsize=7)
    axes[0].set_yticks(range(len(labels)))
    axes[0].set_yticklabels(labels, fontsize=7)
    axes[0].set_xlabel("named (count of cases)")
    axes[0].set_ylabel("hidden")
    ci = summary["false_positive_rate_95ci"]
    axes[0].set_title(f"false positives {summary['false_positives']}/{summary['n_null']} nulls\n"
                      f"(rate {_fmt(summary['false_positive_rate'], '.0%')}, 95 % CI {_fmt(ci[0], '.0%')}-"
                      f"{_fmt(ci[1], '.0%')})", fontsize=9)
    pw = summary["power"]
    effs = sorted({p["effect"] for p in pw})
    for i, e in enumerate(effs):
        ps = sorted([p for p in pw if p["effect"] == e], key=lambda p: p["magnitude"])
        mags = [p["magnitude"] / max(q["magnitude"] for q in ps) for p in ps]
        axes[1].plot(mags, [p["power"] for p in ps], "o-", label=e, color=f"C{i}")
    axes[1].axhline(TARGETS["power_at_larger_magnitude_min"], color="k", ls="--", lw=0.8)
    axes[1].set_xlabel("magnitude / larger benchmark magnitude [-]")
    axes[1].set_ylabel("detection power (share named correctly) [-]")
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].legend(fontsize=6)
    axes[1].set_title("power per effect and magnitude", fontsize=9)
    for i, e in enumerate(effs):
        ps = sorted([p for p in pw if p["effect"] == e], key=lambda p: p["magnitude"])
        mags = [p["magnitude"] / max(q["magnitude"] for q in ps) for p in ps]
        err = [np.nan if p["median_param_rel_error"] is None else 100 * p["median_param_rel_error"] for p in ps]
        axes[2].plot(mags, err, "o-", label=e, color=f"C{i}")     # None: no correct detection at that magnitude
    axes[2].axhline(20, color="k", ls="--", lw=0.8)
    axes[2].set_xlabel("magnitude / larger benchmark magnitude [-]")
    axes[2].set_ylabel("median |parameter error| of detections [%]")
    axes[2].set_title("parameter error", fontsize=9)
    _save(fig, path)


# ------------------------------------------------------------------ command line
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m lumbar.discover", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True, help="workflow config YAML (config/config.yaml)")
    ap.add_argument("--measured", required=True, help="measured table in a project experiment schema (CSV)")
    ap.add_argument("--out", required=True, help="output directory")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    from .config import ConfigError, load_config
    try:
        cfg = load_config(a.config)
        r = run(cfg, a.measured, a.out)
    except (DiscoveryInputError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(json.dumps({k: r[k] for k in ("experiment", "named_effect", "parameter_estimate", "gap_before",
                                        "gap_after", "confidence")}, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
