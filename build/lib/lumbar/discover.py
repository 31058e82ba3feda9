"""Discrepancy discovery (issue 6): where do model and measurement disagree, and which missing effect explains it?

``python -m lumbar.discover --config CONFIG --measured FILE.csv --out DIR``

1. The experiment is detected from the table's columns (:data:`SCHEMAS`): stepwise-reduction ROM
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
4. Score: QAICc (Burnham and Anderson 2002): ``chi2 / c + 2k + 2k(k+1)/(n-k-1)`` with the overdispersion
   ``c = max(1, min_j chi2_j / (n - 1))`` (AIC when n <= k + 1); confidence = Akaike weights over
   {none, candidates}; grouped cross-validation (held-out stage x direction cells, set-ups, activities)
   of the RMS z.
5. Naming rule (documented margin; nothing is named otherwise): the best effect is named only if
   gap_before > ``min_gap``, QAICc(none) - QAICc(best) >= ``min_delta_ic``, its cross-validated RMS z is
   at least ``min_cv_gain`` below the no-effect one (when >= 3 scenarios), and the refitted model's gap is
   at least ``min_gap_reduction`` smaller. The named effect is then added (refit = exact solve at the
   estimate) and the gap before/after reported per scenario and in total.

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

log = logging.getLogger(__name__)

SCHEMAS = {
    "stepwise_rom": ("stage", "direction", "moment_nm", "rom_mean_deg", "rom_min_deg", "rom_max_deg", "n_specimens"),
    "idp_invitro": ("muscle_setup", "load_case", "idp_mean_mpa", "idp_sd_mpa", "n_specimens"),
    "in_vivo": ("activity", "idp_sim_mpa", "idp_in_vivo_mpa", "converged"),
    "neutral_angle": ("stage", "lordosis_deg"),
}
SEGMENT_LOAD_COLUMNS = ("level", "activity", "compressive_n", "shear_n", "moment_nm", "converged")
# expected range of n normal samples in SDs (d2 of quality control), n = 2..10
D2 = {2: 1.128, 3: 1.693, 4: 2.059, 5: 2.326, 6: 2.534, 7: 2.704, 8: 2.847, 9: 2.970, 10: 3.078}

DEFAULTS = dict(
    characteristic_set="calibrated", effects=None, grid_points=9, fine_points=5,
    min_gap=1.5, min_delta_ic=10.0, min_gap_reduction=0.3, min_cv_gain=0.3, cv_folds=8,
    sigma_floor_deg=0.05, sigma_floor_mpa=0.005, no_range_sd_deg=0.5, neutral_sd_deg=0.3,
    in_vivo_sd_mpa=0.1, in_vivo_level="L4-L5",
    in_vivo_segment_loads="results/tables/muscle_model_segment_loads.csv",
    idp_model_table=None,
)


class DiscoveryInputError(ValueError):
    """A measured file that cannot be used (message names file, column and the expected form)."""


# ------------------------------------------------------------------ configuration
def discovery_settings(config: dict | None) -> dict:
    s = dict(DEFAULTS)
    s.update({k: v for k, v in ((config or {}).get("discovery") or {}).items() if k != "benchmark"})
    return s


# ------------------------------------------------------------------ reading and schema detection
def detect_experiment(columns, path="<table>") -> str:
    cols = set(columns)
    for name in ("stepwise_rom", "idp_invitro", "in_vivo", "neutral_angle"):
        key = SCHEMAS[name][:3] if name != "neutral_angle" else SCHEMAS[name]
        if set(key) <= cols:
            missing = [c for c in SCHEMAS[name] if c not in cols]
            if missing:
                raise DiscoveryInputError(
                    f"{path}: looks like a {name} table but column(s) {missing} are missing; "
                    f"expected columns {list(SCHEMAS[name])}")
            return name
    forms = "; ".join(f"{k}: {list(v)}" for k, v in SCHEMAS.items())
    raise DiscoveryInputError(f"{path}: columns {sorted(cols)} match no experiment schema; expected one of {forms}")


def read_measured(path) -> tuple[str, pd.DataFrame]:
    """(experiment, validated table) of a measured/surrogate/fixture file; DiscoveryInputError if unusable."""
    p = Path(path)
    if not p.is_file():
        raise DiscoveryInputError(f"measured file not found: {p}")
    try:
        head = pd.read_csv(p, nrows=5)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as e:
        raise DiscoveryInputError(f"{p}: not a readable CSV table ({type(e).__name__}); expected a CSV file with a "
                                  f"header row") from e
    exp = detect_experiment(head.columns, p)
    from .io import TableError
    try:
        if exp == "stepwise_rom":
            from .stepwise_reduction import read_experiment_table
            df = read_experiment_table(p)
        elif exp == "idp_invitro":
            from .io import read_table
            from .l2s1 import IDP_TABLE_SCHEMA
            df = read_table(p, IDP_TABLE_SCHEMA)
        else:
            df = pd.read_csv(p)
    except TableError as e:
        raise DiscoveryInputError(str(e)) from e
    if len(df) == 0:
        raise DiscoveryInputError(f"{p}: no data rows; expected one row per scenario")
    num = {"in_vivo": ("idp_sim_mpa", "idp_in_vivo_mpa"), "neutral_angle": ("lordosis_deg",)}.get(exp, ())
    for c in num:
        v = pd.to_numeric(df[c], errors="coerce")
        bad = np.flatnonzero(~np.isfinite(v.to_numpy(float)))
        if exp == "in_vivo" and c == "idp_sim_mpa":
            bad = [i for i in bad if str(df["converged"].iat[i]).lower() in ("true", "1")]
        if len(bad):
            raise DiscoveryInputError(f"{p}: row {bad[0] + 1}, column {c}: {df[c].iat[bad[0]]!r} is not a finite "
                                      f"number; expected a number")
        df[c] = v
    if exp == "neutral_angle" and len(df) < 2:
        raise DiscoveryInputError(f"{p}: a neutral-angle table needs >= 2 stages (the first is the reference); "
                                  f"got {len(df)}")
    if exp == "neutral_angle":
        from .fsu import STAGES
        badst = [s for s in df["stage"] if s not in STAGES]
        if badst:
            raise DiscoveryInputError(f"{p}: column stage: {badst[0]!r} is not a reduction stage; expected one of "
                                      f"{list(STAGES)}")
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
def _fsu_variants(geometry_kind, geometry_path, level, set_name, data_dir, facet_k, k_shear):
    from .characteristics import load_characteristic_set
    from .fsu import build_fsu
    from .geometry import load_geometry
    geo = load_geometry(geometry_kind, path=geometry_path if geometry_kind == "visible_human" else None, levels=[level])
    cs = load_characteristic_set(set_name, data_dir=data_dir)
    return fx.FsuVariants(build_fsu(geo, cs, level, facet_stiffness=facet_k, k_shear=k_shear))


def fsu_variants_from_config(config):
    g, f = config.get("geometry", {}), config.get("fsu", {})
    s = discovery_settings(config)
    return _fsu_variants(g.get("kind", "default"), g.get("path"), f.get("level", "L4-L5"), s["characteristic_set"],
                         (config.get("characteristics") or {}).get("data_dir"), f.get("facet_stiffness_n_per_m"),
                         f.get("disc_shear_stiffness_n_per_m"))


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
    return Problem("stepwise_rom", keys, df["rom_mean_deg"].to_numpy(float), _rom_sigma(df.reset_index(drop=True), s),
                   "deg", forward, _candidates(s, "stepwise_rom"), "stage", ["direction", "moment_nm"],
                   _grouped_folds(cells, s["cv_folds"]))


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
    return Problem("neutral_angle", keys, y[1:] - y[0], np.hypot(sd[1:], ref_sd), "deg", forward,
                   _candidates(s, "neutral_angle"), "reference_stage", ["stage"], np.arange(len(stages) - 1))


def idp_model_table(config):
    """Internal loads + IDP of the nominal L2-S1 model (49 scenarios): the configured file, else solved."""
    s = discovery_settings(config)
    p = s.get("idp_model_table")
    if p and Path(p).is_file():
        return pd.read_csv(p)
    return solve_idp_model(config)


def solve_idp_model(config):
    from .characteristics import load_characteristic_set
    from .geometry import load_geometry
    from .l2s1 import LEVELS, derive_cables, run_set
    s = discovery_settings(config)
    g, l2 = config.get("geometry", {}), config.get("l2s1", {})
    geo = load_geometry(g.get("kind", "default"), path=g.get("path") if g.get("kind") == "visible_human" else None,
                        levels=list(LEVELS))
    data_dir = (config.get("characteristics") or {}).get("data_dir")
    cs = load_characteristic_set(s["characteristic_set"], data_dir=data_dir)
    sim, _ = run_set(geo, cs, derive_cables(l2.get("cables")), idp_formula=l2.get("idp_formula", "paper1"),
                     k_shear=(config.get("fsu") or {}).get("disc_shear_stiffness_n_per_m"),
                     moment_nm=l2.get("moment_nm", 3.75))
    csa = geo.levels["L4-L5"].disc_csa
    if l2.get("idp_formula", "paper1") == "paper1":
        sim["idp_per_newton_pa"] = 1.68 / csa
    else:
        sim["idp_per_newton_pa"] = 0.85 / (l2.get("disc_area_m2", 18e-4) * 0.66)
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
    return Problem("idp_invitro", d[["muscle_setup", "load_case"]], d["idp_mean_mpa"].to_numpy(float), sig, "MPa",
                   forward, _candidates(s, "idp_invitro"), "muscle_setup", ["load_case"],
                   _grouped_folds(list(d["muscle_setup"]), s["cv_folds"]), meta={"idp_per_newton_pa": per_n})


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
    conv = df["converged"].astype(str).str.lower().isin(["true", "1"])
    d = df[conv].reset_index(drop=True).merge(sl[["activity", "compressive_n", "moment_nm"]], on="activity", how="left")
    if d["moment_nm"].isna().any():
        a = d["activity"][d["moment_nm"].isna()].iat[0]
        raise DiscoveryInputError(f"segment loads: no {s['in_vivo_level']} row for activity {a!r}; expected one row "
                                  f"per activity of the in-vivo table")
    base = d["idp_sim_mpa"].to_numpy(float) * 1e6
    M = d["moment_nm"].to_numpy(float)
    F = d["compressive_n"].to_numpy(float)
    ok = F > 0
    per_n = float(np.median(base[ok] / F[ok])) if ok.any() else 0.85 / (18e-4 * 0.66)

    def forward(values):
        return _idp_forward(values, base, M, per_n) / 1e6

    return Problem("in_vivo", d[["activity"]], d["idp_in_vivo_mpa"].to_numpy(float),
                   np.full(len(d), float(s["in_vivo_sd_mpa"])), "MPa", forward, _candidates(s, "in_vivo"),
                   "experiment", ["activity"], np.arange(len(d)), meta={"idp_per_newton_pa": per_n})


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


def discover(problem: Problem, settings: dict | None = None, cache: dict | None = None) -> dict:
    """Rank the candidate effects, name the best one when it clears the margins, refit (see module doc)."""
    s = dict(DEFAULTS)
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
    est, fine_theta = {}, {}
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        t, _ = _spline_fit(grids[c], coarse[c], y, w, lo, hi, valid)
        step = (hi - lo) / (int(s["grid_points"]) - 1)
        if np.isfinite(t):
            fine_theta[c] = np.unique(np.clip(np.linspace(t - step, t + step, int(s["fine_points"])), lo, hi))
        est[c] = t
    fine = dict(zip(fine_theta, _batch(problem, list(fine_theta.items()))))
    n_batches += bool(fine_theta)
    for c in fine:
        lo, hi = fx.EFFECTS[c].bounds
        th = np.unique(np.r_[fine_theta[c], grids[c]])
        P = np.vstack([fine[c], coarse[c]])
        order = np.argsort(np.r_[fine_theta[c], grids[c]], kind="stable")
        allth = np.r_[fine_theta[c], grids[c]][order]
        P = P[order]
        keep = np.r_[True, np.diff(allth) > 1e-12 * (hi - lo)]
        est[c], _ = _spline_fit(allth[keep], P[keep], y, w, lo, hi, valid)
        del th
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
    chat = max(1.0, min(chi.values()) / max(nv - 1, 1))
    score = {m: _qaicc(v, 0 if m == "none" else 1, nv, chat) for m, v in chi.items()}
    best_ic = min(score.values())
    wts = {m: np.exp(-0.5 * (v - best_ic)) for m, v in score.items()}
    tot = sum(wts.values())
    wts = {m: float(v / tot) for m, v in wts.items()}
    # grouped cross-validation (on the coarse + fine splines; cheap)
    cv = {"none": gap_before}
    folds = problem.folds
    if nv >= 3 and len(np.unique(folds[valid])) >= 2:
        for c in exact:
            zc = np.full(len(y), np.nan)
            for f in np.unique(folds[valid]):
                tr, te = valid & (folds != f), valid & (folds == f)
                lo, hi = fx.EFFECTS[c].bounds
                th = np.r_[grids[c], fine_theta.get(c, [])]
                P = np.vstack([coarse[c], fine.get(c, np.empty((0, len(y))))])
                o = np.argsort(th, kind="stable")
                th, P = th[o], P[o]
                keep = np.r_[True, np.diff(th) > 1e-12 * (hi - lo)]
                th, P = th[keep], P[keep]
                t, _ = _spline_fit(th, P, y, w, lo, hi, tr)
                from scipy.interpolate import CubicSpline
                okc = np.isfinite(P).all(0)
                pred = np.full(len(y), np.nan)
                if np.isfinite(t):
                    pred[okc] = CubicSpline(th, P[:, okc], axis=0)(t)
                zc[te] = np.where(np.isfinite(pred[te]), (pred[te] - y[te]) / sig[te], 10.0)
            cv[c] = float(np.sqrt(np.nanmean(zc[valid] ** 2)))
    ranking = sorted(score.items(), key=lambda kv: kv[1])
    cand_rank = [m for m, _ in ranking if m != "none"]
    best = cand_rank[0] if cand_rank else None
    gap_after_best = float("nan")
    if best is not None:
        zb = (exact[best] - y) / sig
        gap_after_best = float(np.sqrt(np.mean(np.where(np.isfinite(zb), zb, 10.0)[valid] ** 2)))
    reasons = []
    if best is None:
        reasons.append("no candidate effect acts on this experiment")
    else:
        if not gap_before > s["min_gap"]:
            reasons.append(f"gap_before {gap_before:.2f} <= min_gap {s['min_gap']:g}: model and data agree within "
                           f"the measurement uncertainty")
        d_ic = score["none"] - score[best]
        if not d_ic >= s["min_delta_ic"]:
            reasons.append(f"QAICc(none) - QAICc({best}) = {d_ic:.1f} < min_delta_ic {s['min_delta_ic']:g}")
        if best in cv and not cv[best] <= (1 - s["min_cv_gain"]) * cv["none"]:
            reasons.append(f"cross-validated RMS z {cv[best]:.2f} not {100 * s['min_cv_gain']:.0f}% below "
                           f"no-effect {cv['none']:.2f}")
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
    res = {
        "experiment": problem.experiment,
        "n_scenarios": nv,
        "unit": problem.unit,
        "named_effect": named,
        "parameter_estimate": ({"effect": named, "parameter": eff.parameter, "value": est[named], "unit": eff.unit}
                               if named else None),
        "gap_before": gap_before, "gap_after": gap_after,
        "gap_before_rms": rms_phys0, "gap_after_rms": rms_phys1,
        "gap_reduction": (1 - gap_after / gap_before) if gap_before > 0 else 0.0,
        "ranking": [[m, float(v)] for m, v in ranking],
        "confidence": wts.get(named, wts.get("none")) if named else wts.get("none"),
        "akaike_weights": wts,
        "best_candidate": best,
        "best_candidate_estimate": est.get(best) if best else None,
        "best_candidate_gap_after": gap_after_best,
        "estimates": {c: est[c] for c in cands},
        "cv_rms_z": cv,
        "overdispersion": chat,
        "decision": ("named: all margins cleared" if named else "nothing named: " + "; ".join(reasons)),
        "criterion": "QAICc (chi2/c + 2k + 2k(k+1)/(n-k-1)), c = max(1, min chi2/(n-1)); gap = RMS of z",
        "margins": {k: s[k] for k in ("min_gap", "min_delta_ic", "min_gap_reduction", "min_cv_gain")},
        "forward_batches": n_batches,
        "seconds": time.perf_counter() - t0,
    }
    return {"result": res, "scenarios": scen, "problem": problem}


# ------------------------------------------------------------------ figures and report section
def _plt():
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path):
    from .io import atomic_writer
    with atomic_writer(path, "wb", encoding=None, newline=None) as f:
        fig.savefig(f, format="png", dpi=110, metadata={"Software": None})


def _pivot(scen, problem, col):
    rows = list(dict.fromkeys(scen[problem.row_key].astype(str))) if problem.row_key in scen else ["all"]
    ck = problem.col_keys
    cols = list(dict.fromkeys(scen[ck].astype(str).agg(" ".join, axis=1)))
    M = np.full((len(rows), len(cols)), np.nan)
    rk = scen[problem.row_key].astype(str) if problem.row_key in scen else pd.Series(["all"] * len(scen))
    cc = scen[ck].astype(str).agg(" ".join, axis=1)
    for r, c, v in zip(rk, cc, scen[col]):
        M[rows.index(r), cols.index(c)] = v
    return rows, cols, M


def _heat(ax, rows, cols, M, vmax, title):
    im = ax.imshow(M, cmap="RdBu_r", vmin=-vmax, vmax=vmax, aspect="auto")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(rows, fontsize=7)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels(cols, fontsize=6, rotation=70, ha="right")
    ax.set_title(title, fontsize=8)
    if M.size <= 200:
        for i in range(M.shape[0]):
            for j in range(M.shape[1]):
                if np.isfinite(M[i, j]):
                    ax.text(j, i, f"{M[i, j]:.1f}", ha="center", va="center", fontsize=5)
    return im


def plot_disagreement_map(out, path):
    plt = _plt()
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M = _pivot(scen, p, "z_before")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M), 95))) if np.isfinite(M).any() else 3.0
    fig, ax = plt.subplots(figsize=(min(16, 2.5 + 0.4 * len(cols)), 1.8 + 0.35 * len(rows)))
    im = _heat(ax, rows, cols, M, vmax, f"{p.experiment}: scaled residual z = (model - measured) / sigma; "
               f"gap (RMS z) = {r['gap_before']:.2f}")
    fig.colorbar(im, ax=ax, label="z (+ model above measurement)")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def plot_ranking(out, path):
    plt = _plt()
    r = out["result"]
    none = dict(r["ranking"])["none"]
    items = [(m, none - v) for m, v in r["ranking"] if m != "none"]
    fig, ax = plt.subplots(figsize=(7, 1.2 + 0.4 * max(1, len(items))))
    names = [m for m, _ in items][::-1]
    vals = [v for _, v in items][::-1]
    colors = ["tab:green" if m == r["named_effect"] else "0.6" for m in names]
    ax.barh(names, vals, color=colors)
    ax.axvline(r["margins"]["min_delta_ic"], color="k", ls="--", lw=0.8, label="naming margin")
    for i, m in enumerate(names):
        ax.text(max(vals[i], 0), i, f" w={r['akaike_weights'].get(m, 0):.2f}, est={r['estimates'].get(m, np.nan):.3g}",
                va="center", fontsize=7)
    ax.set_xscale("symlog", linthresh=10)
    ax.set_xlabel("QAICc(no effect) - QAICc(effect)  (> 0: effect explains the residuals better)")
    ax.set_title(f"named: {r['named_effect'] or 'none'} (confidence {r['confidence']:.2f})", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def plot_before_after(out, path):
    plt = _plt()
    scen, p, r = out["scenarios"], out["problem"], out["result"]
    rows, cols, M0 = _pivot(scen, p, "z_before")
    _, _, M1 = _pivot(scen, p, "z_after")
    vmax = max(3.0, float(np.nanpercentile(np.abs(M0), 95))) if np.isfinite(M0).any() else 3.0
    fig, axes = plt.subplots(2, 1, figsize=(min(16, 2.5 + 0.4 * len(cols)), 4.0 + 0.7 * len(rows)),
                             constrained_layout=True)
    _heat(axes[0], rows, cols, M0, vmax, f"before: gap {r['gap_before']:.2f} (RMS {r['gap_before_rms']:.3g} {p.unit})")
    im = _heat(axes[1], rows, cols, M1, vmax, f"after adding {r['named_effect'] or 'nothing'}: "
               f"gap {r['gap_after']:.2f} (RMS {r['gap_after_rms']:.3g} {p.unit})")
    fig.colorbar(im, ax=axes, label="z")
    _save(fig, path)
    plt.close(fig)


def section_markdown(out, measured_path) -> str:
    r = out["result"]
    lines = [f"## Discrepancy discovery: `{measured_path}`", "",
             f"Experiment **{r['experiment']}**, {r['n_scenarios']} scenarios. Residuals are scaled by the "
             f"measurement uncertainty of each row (z); the gap is the RMS of z.", "",
             f"- gap before: **{r['gap_before']:.2f}** (RMS {r['gap_before_rms']:.3g} {r['unit']})",
             f"- named effect: **{r['named_effect'] or 'none'}**"
             + (f", {r['parameter_estimate']['parameter']} = {r['parameter_estimate']['value']:.4g} "
                f"{r['parameter_estimate']['unit']} (confidence, Akaike weight: {r['confidence']:.2f})"
                if r["named_effect"] else ""),
             f"- gap after: **{r['gap_after']:.2f}** (RMS {r['gap_after_rms']:.3g} {r['unit']}; "
             f"reduction {100 * r['gap_reduction']:.0f}%)",
             f"- decision: {r['decision']}", "",
             "| rank | effect | QAICc | delta to none | Akaike weight | estimate | CV RMS z |",
             "|---|---|---|---|---|---|---|"]
    none = dict(r["ranking"])["none"]
    for i, (m, v) in enumerate(r["ranking"], 1):
        est = r["estimates"].get(m)
        est_s = "" if est is None else f"{est:.4g} {fx.EFFECTS[m].unit}"
        lines.append(f"| {i} | {m} | {v:.1f} | {none - v:.1f} | {r['akaike_weights'][m]:.2f} | {est_s} | "
                     f"{r['cv_rms_z'].get(m, float('nan')):.2f} |")
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


# ------------------------------------------------------------------ benchmark with hidden effects (fixtures)
def benchmark_settings(config) -> dict:
    b = dict(effects=None, n_magnitudes=2, n_null=6, n_specimens=8, noise_sd_deg=0.3, noise_sd_mpa=0.02,
             moments_nm=[1.0, 2.5, 5.0, 7.5, 10.0], stages=None, experiments=None, generator="batch")
    b.update(((config or {}).get("discovery") or {}).get("benchmark") or {})
    return b


def benchmark_cases(config) -> pd.DataFrame:
    """Every benchmark case: (case, experiment, hidden_effect, magnitude, seed)."""
    b = benchmark_settings(config)
    seed = int((config or {}).get("seed", 0))
    names = b["effects"] or [n for n, e in fx.EFFECTS.items() if e.experiments]
    rows = []
    for name in names:
        e = fx.check_effect(name)
        exps = [x for x in e.experiments if x in ("stepwise_rom", "idp_invitro") and
                (not b["experiments"] or x in b["experiments"])]
        for x in exps:
            for j, mag in enumerate(e.magnitudes[: int(b["n_magnitudes"])]):
                rows.append((f"{name}_{x}_{j + 1}", x, name, float(mag)))
    exps = [x for x in ("stepwise_rom", "idp_invitro") if not b["experiments"] or x in b["experiments"]]
    for k in range(int(b["n_null"])):
        x = exps[k % len(exps)]
        rows.append((f"null_{x}_{k + 1}", x, "none", 0.0))
    df = pd.DataFrame(rows, columns=["case", "experiment", "hidden_effect", "magnitude"])
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
    from .characteristics import load_characteristic_set
    from .fsu import STAGES
    from .geometry import load_geometry
    from .virtual_experiment import stepwise_reduction_table
    g, f = config.get("geometry", {}), config.get("fsu", {})
    level = f.get("level", "L4-L5")
    geo = load_geometry(g.get("kind", "default"), path=g.get("path") if g.get("kind") == "visible_human" else None,
                        levels=[level])
    cs = load_characteristic_set(discovery_settings(config)["characteristic_set"],
                                 data_dir=(config.get("characteristics") or {}).get("data_dir"))
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
        fname = fixture_dir / f"hidden_effect_{c.hidden_effect}_{c.magnitude:g}_{c.experiment}_seed{c.seed}_fixture.csv"
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
        rows.append(dict(case=c.case, experiment=c.experiment, hidden_effect=c.hidden_effect, magnitude=c.magnitude,
                         named_effect=named, correct=named == c.hidden_effect,
                         param_true=c.magnitude if c.hidden_effect != "none" else np.nan, param_est=est,
                         gap_before=r["gap_before"], gap_after=r["gap_after"], confidence=r["confidence"],
                         seconds=time.perf_counter() - t, fixture=fname.name))
        log.info("benchmark %s: hidden %s -> named %s (gap %.2f -> %.2f)", c.case, c.hidden_effect, named,
                 r["gap_before"], r["gap_after"])
    return pd.DataFrame(rows)


TARGETS = {"naming_accuracy": 0.9, "null_specificity": 0.9, "param_within_20pct": 1.0, "median_gap_reduction": 0.7}


def summarise_benchmark(bench: pd.DataFrame, generator="batch") -> dict:
    hid = bench[bench["hidden_effect"] != "none"]
    nul = bench[bench["hidden_effect"] == "none"]
    rel = (np.abs(hid["param_est"] - hid["param_true"]) / np.abs(hid["param_true"])).to_numpy(float)
    red = (1 - hid["gap_after"] / hid["gap_before"]).to_numpy(float)
    m = {
        "n_cases": int(len(bench)), "n_hidden": int(len(hid)), "n_null": int(len(nul)),
        "naming_accuracy": float(hid["correct"].mean()) if len(hid) else float("nan"),
        "null_specificity": float((nul["named_effect"] == "none").mean()) if len(nul) else float("nan"),
        "param_within_20pct": float(np.mean(np.nan_to_num(rel, nan=np.inf) <= 0.2)) if len(hid) else float("nan"),
        "median_param_rel_error": float(np.nanmedian(rel)) if len(hid) else float("nan"),
        "max_param_rel_error": float(np.nanmax(rel)) if len(hid) else float("nan"),
        "median_gap_reduction": float(np.nanmedian(red)) if len(hid) else float("nan"),
        "min_gap_reduction": float(np.nanmin(red)) if len(hid) else float("nan"),
    }
    m["pass"] = {k: bool(np.isfinite(m[k]) and m[k] >= t) for k, t in TARGETS.items()}
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
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    labels = sorted(set(bench["hidden_effect"]) | set(bench["named_effect"]))
    C = np.zeros((len(labels), len(labels)))
    for h, n in zip(bench["hidden_effect"], bench["named_effect"]):
        C[labels.index(h), labels.index(n)] += 1
    axes[0].imshow(C, cmap="Greens")
    for i in range(len(labels)):
        for j in range(len(labels)):
            if C[i, j]:
                axes[0].text(j, i, int(C[i, j]), ha="center", va="center", fontsize=8)
    axes[0].set_xticks(range(len(labels)))
    axes[0].set_xticklabels(labels, rotation=60, ha="right", fontsize=7)
    axes[0].set_yticks(range(len(labels)))
    axes[0].set_yticklabels(labels, fontsize=7)
    axes[0].set_xlabel("named")
    axes[0].set_ylabel("hidden")
    axes[0].set_title(f"naming accuracy {summary['naming_accuracy']:.0%}, "
                      f"nulls clean {summary['null_specificity']:.0%}",
                      fontsize=9)
    hid = bench[bench["hidden_effect"] != "none"]
    rel = 100 * (hid["param_est"] - hid["param_true"]) / hid["param_true"]
    axes[1].axhspan(-20, 20, color="0.9", zorder=0)
    axes[1].bar(range(len(hid)), rel.to_numpy(float), color="tab:blue", zorder=2)
    axes[1].axhline(0, color="k", lw=0.5)
    lim = max(25.0, float(np.nanmax(np.abs(rel.to_numpy(float)), initial=0)) * 1.1)
    axes[1].set_ylim(-lim, lim)
    axes[1].set_xticks(range(len(hid)))
    axes[1].set_xticklabels(hid["case"], rotation=70, ha="right", fontsize=6)
    axes[1].set_ylabel("parameter error [%]")
    axes[1].set_title(f"within 20%: {summary['param_within_20pct']:.0%}", fontsize=9)
    x = np.arange(len(bench))
    axes[2].bar(x - 0.2, bench["gap_before"], 0.4, label="before")
    axes[2].bar(x + 0.2, bench["gap_after"], 0.4, label="after")
    axes[2].set_yscale("log")
    axes[2].set_xticks(x)
    axes[2].set_xticklabels(bench["case"], rotation=70, ha="right", fontsize=6)
    axes[2].set_ylabel("gap (RMS z)")
    axes[2].legend(fontsize=7)
    axes[2].set_title(f"median gap reduction {summary['median_gap_reduction']:.0%}", fontsize=9)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


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
