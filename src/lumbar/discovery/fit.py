"""Fitting and scoring the candidate effects of a discovery problem: batched grid solves, splines, the
bootstrap likelihood-ratio test, the naming rule, identifiability and cross-validation (:func:`discover`).

:func:`discover` runs named phases, each a function with a dataclass result that can be run and tested on its own:
grid (:func:`fit_grids`: the coarse parameter grid of every candidate in one forward batch), the null prediction
(:func:`null_prediction`), refinement (:func:`refine`: spline estimates and the fine grid; :func:`scorer`, the metric
of the tests; :func:`refit`: estimates in that metric and the exact refit of the best candidate), null tests
(:func:`null_tests`: the parametric bootstrap, max-T p-values), nuisance comparison (:func:`nuisance_refits`,
:func:`compare_nuisance`), :func:`diagnostics`, :func:`explained_share`, decision (:func:`decide` on an
:class:`Evidence`) and the record (:func:`result_record`); the last three live in :mod:`lumbar.discovery.decision`
and are imported here."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from ..experiments import effects as fx
from .decision import Decision, Evidence, decide, explained_share, fmt_p, result_record  # noqa: F401 - public here too
from .detect import default_settings
from .nuisance import families, multiple_correlation
from .problems import Problem
from .specimens import D2, NON_NEGATIVE, Metric, fit_null_noise, null_datasets, specimen_metric


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


def coarse_grid(lo, hi, n, power=1.5):
    """The coarse parameter grid of a candidate: ``n`` values from ``lo`` to ``hi`` (and 0), spaced as
    ``|u|^power`` (u uniform in [-1, 1] across a bound pair around 0, in [0, 1] otherwise), denser near 0 where the
    effects' plausible sizes and responses that bend (a ligament going taut) lie: on the default stepwise-reduction
    scenarios a 13-value grid's cubic spline reproduces the exact ROM of every ROM effect within 0.09 deg
    (0.04 deg for 99 % of the values) from 0.1 x to 2 x the benchmark magnitudes, against 0.19 deg (ITL) with
    uniform spacing."""
    if lo < 0 < hi:
        u = np.linspace(-1.0, 1.0, n)
        g = np.sign(u) * np.abs(u) ** power
        g = np.where(g < 0, -g * lo, g * hi)
    else:
        g = lo + (hi - lo) * np.linspace(0.0, 1.0, n) ** power
    return np.unique(np.r_[g, 0.0])


def _spline_fit(theta, P, y, w, lo, hi, mask=None):
    """argmin over [lo, hi] of sum w (spline(theta) - y)^2 (per-scenario cubic splines through the grid)."""
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
    """B null datasets of ``problem`` around ``center`` with the project's generator (lumbar.discovery.
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
        if problem.experiment in NON_NEGATIVE:
            A = np.maximum(A, 0.0)
        if problem.experiment == "stepwise_rom":
            Y[:, cols] = A.mean(1)
            d2k = D2.get(int(k), 3.078)
            SIG[:, cols] = np.maximum((A.max(1) - A.min(1)) / d2k / np.sqrt(k), problem.meta.get("sigma_floor", 0.0))
        else:
            Y[:, cols] = A.mean(1)
            SIG[:, cols] = np.maximum(A.std(1, ddof=1) / np.sqrt(k), problem.meta.get("sigma_floor", 0.0))
    return Y, SIG


def _statistics(curves_w, nuis_w, r_w, Y_w, normalise=True):
    """Every model's fit to the tables Y_w (B, p), all in the metric's space (:class:`lumbar.discovery.specimens.
    Metric`: the chi-square is a plain sum of squares there): the null prediction r ("none": chi2_r and the
    overdispersion c0 = max(1, chi2_r / (p - 1)), 1 without ``normalise``), each candidate (best value of its dense
    curve: chi2, theta, LR statistic T_c = (chi2_r - chi2_c) / c0) and each nuisance family (least-squares
    parameters, chi2, T)."""
    nv = Y_w.shape[1]
    chi_r = ((Y_w - r_w) ** 2).sum(1)
    c0 = np.maximum(1.0, chi_r / max(nv - 1, 1)) if normalise else np.ones_like(chi_r)
    out = {"chi_r": chi_r, "c0": c0, "chi_c": {}, "th_c": {}, "T_c": {}, "chi_n": {}, "par_n": {}, "T_n": {}}
    ones, allv = np.ones_like(Y_w), np.ones(nv, bool)
    for c, (td, D) in curves_w.items():
        chi = _chi2_surface(D, Y_w, ones, allv)
        k = chi.argmin(0)
        out["chi_c"][c] = chi[k, np.arange(chi.shape[1])]
        out["th_c"][c] = td[k]
        out["T_c"][c] = np.maximum(chi_r - out["chi_c"][c], 0.0) / c0
    for name, (nu, X_w) in nuis_w.items():
        target = Y_w if nu.kind == "scale" else Y_w - r_w
        p, *_ = np.linalg.lstsq(X_w, target.T, rcond=None)
        chi = ((target.T - X_w @ p) ** 2).sum(0)
        out["par_n"][name], out["chi_n"][name] = p.T, chi
        out["T_n"][name] = np.maximum(chi_r - chi, 0.0) / c0
    return out


def _p(null, obs):
    """Bootstrap p-value (1 + #{null >= obs}) / (B + 1)."""
    return float((1 + np.sum(null >= obs - 1e-12)) / (len(null) + 1))


def _ref_value(c):
    """A candidate's reference magnitude (its first benchmark magnitude, or half its upper bound)."""
    e = fx.EFFECTS[c]
    return float(np.clip(e.magnitudes[0] if e.magnitudes else 0.5 * e.bounds[1], *e.bounds))


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


# ------------------------------------------------------------------ the phases of discover()
@dataclass
class Grids:
    """Phase 1 (grid): every candidate's coarse parameter grid and its predictions, with the no-effect model's, from
    one batched forward solve (or the cache)."""
    grids: dict          # candidate -> parameter values (coarse_grid)
    base: np.ndarray     # (n,) the nominal model's prediction
    coarse: dict         # candidate -> (len(grid), n) predictions
    batches: int = 0     # forward batches solved here (0: from the cache)


def fit_grids(problem: Problem, cands: list, settings: dict, cache: dict | None = None) -> Grids:
    """Phase 1: the no-effect model and the coarse grid (``grid_points`` values) of every candidate in one batch."""
    grids = {c: coarse_grid(*fx.EFFECTS[c].bounds, int(settings["grid_points"])) for c in cands}
    key = ("coarse", problem.experiment, tuple(map(tuple, problem.keys.astype(str).to_numpy())),
           tuple(cands), int(settings["grid_points"]))
    batches = 0
    if cache is not None and key in cache:
        base, coarse = cache[key]
    else:
        if cands:
            out = _batch(problem, [(cands[0], np.zeros(1))] + [(c, grids[c]) for c in cands])
        else:
            out = [problem.forward({})]
        base, coarse = out[0][0], dict(zip(cands, out[1:]))
        batches = 1
        if cache is not None:
            cache[key] = (base, coarse)
    return Grids(grids, base, coarse, batches)


@dataclass
class NullPrediction:
    """The null hypothesis' prediction r (the mean of virtual specimens of the nominal model, or the nominal model
    without a bank), the rows compared, and the gap of the nominal model to the data."""
    bank: object | None       # the problem's SpecimenBank, or None
    r: np.ndarray             # (n,) the null prediction
    shift: np.ndarray         # r - base: the specimen-mean shift
    valid: np.ndarray         # rows with a finite model, datum, sigma and r
    yr: np.ndarray            # the data relative to the shift: the candidates' grids fit it
    z0: np.ndarray            # (base - y) / sigma
    chi_nominal: float
    nv: int                   # number of rows compared
    gap_before: float         # RMS z of the nominal model over the valid rows

    @property
    def none_label(self) -> str:
        """The null model's name among the explanations."""
        return "specimen-mean shift" if self.bank is not None else "nominal model"

    @property
    def null_text(self) -> str:
        """What the null tables are made of."""
        return ("the nominal model with specimen variation" if self.bank is not None else
                "the nominal model and the measurement noise")


def null_prediction(problem: Problem, base: np.ndarray) -> NullPrediction:
    """The null model's prediction and the compared rows of ``problem`` (``base``: the nominal model's prediction)."""
    y, sig = problem.y, problem.sigma
    bank = problem.meta.get("bank")
    r = np.where(np.isfinite(bank.mean), bank.mean, np.nan) if bank is not None else base.copy()
    shift = r - base
    valid = np.isfinite(base) & np.isfinite(y) & np.isfinite(sig) & np.isfinite(r)
    yr = y - np.where(valid, shift, 0.0)
    z0 = (base - y) / sig
    nv = int(valid.sum())
    gap_before = float(np.sqrt(np.mean(z0[valid] ** 2))) if nv else float("nan")
    return NullPrediction(bank, r, shift, valid, yr, z0, float((z0[valid] ** 2).sum()), nv, gap_before)


@dataclass
class Refinement:
    """Phase 2 (refinement): each candidate's estimate on its spline, the fine grids around the leading candidates'
    optima and every candidate's merged (theta, predictions) curve."""
    est: dict            # candidate -> estimate (nan: no finite fit)
    fine_theta: dict     # leading candidate -> fine grid
    fine: dict           # leading candidate -> its predictions on the fine grid
    curves_raw: dict     # candidate -> (theta, P) of the coarse and fine grids, sorted
    batches: int = 0


def refine(problem: Problem, cands: list, grids: Grids, null: NullPrediction, settings: dict) -> Refinement:
    """Phase 2: coarse spline estimates, then one batch of a fine grid (``fine_points``) around the optimum of the
    ``fine_candidates`` lowest coarse chi2 (it refines the estimate that can be named; the others keep their
    coarse-spline estimate), and the refined estimates on the merged curves."""
    w = 1.0 / problem.sigma ** 2
    est, fine_theta, coarse_chi = {}, {}, {}
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        est[c], coarse_chi[c] = _spline_fit(grids.grids[c], grids.coarse[c], null.yr, w, lo, hi, null.valid)
    lead = sorted([c for c in cands if np.isfinite(est[c])],
                  key=lambda c: coarse_chi[c])[: int(settings["fine_candidates"])]
    for c in lead:
        lo, hi = fx.EFFECTS[c].bounds
        g = grids.grids[c]
        j = int(np.clip(np.searchsorted(g, est[c]), 1, len(g) - 1))
        step = g[j] - g[j - 1]
        t = est[c]
        fine_theta[c] = np.unique(np.clip(np.linspace(t - step, t + step, int(settings["fine_points"])), lo, hi))
    fine = dict(zip(fine_theta, _batch(problem, list(fine_theta.items()))))
    curves_raw = {}
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        th, P = _curve([grids.grids[c]] + ([fine_theta[c]] if c in fine else []),
                       [grids.coarse[c]] + ([fine[c]] if c in fine else []), lo, hi)
        curves_raw[c] = (th, P)
        if c in fine:
            est[c], _ = _spline_fit(th, P, null.yr, w, lo, hi, null.valid)
    return Refinement(est, fine_theta, fine, curves_raw, int(bool(fine_theta)))


@dataclass
class Scorer:
    """Every model's statistics on tables (:func:`_statistics`) in the metric of the tests: the table's standard
    errors, decorrelated by the specimens' correlation (the bank's, shrunk, with the fitted noise); independent rows
    without a bank. ``scorer(Y, cands, nuis)`` scores tables Y (B, n) by the given candidates and nuisance families
    (None: all)."""
    metric: Metric
    curves: dict          # candidate -> (dense theta, predictions on top of the specimen-mean shift)
    curves_w: dict        # the same in the metric
    nuis: list            # nuisance families (none with too few rows)
    nuis_w: dict          # family name -> (family, its columns in the metric)
    r0: np.ndarray        # the null prediction, 0 outside the valid rows
    r_w: np.ndarray       # r0 in the metric
    normalise: bool       # LR statistics divided by the overdispersion c0
    null_model: object    # the fitted null noise (fit_null_noise) with a bank, else None
    too_few: bool         # fewer than min_rows rows compared

    def __call__(self, Y, cands_=None, nuis_=None):
        cw_ = self.curves_w if cands_ is None else {c: self.curves_w[c] for c in cands_}
        nw_ = self.nuis_w if nuis_ is None else {n: self.nuis_w[n] for n in nuis_}
        return _statistics(cw_, nw_, self.r_w, self.metric(np.where(np.isfinite(Y), Y, self.r0)),
                           normalise=self.normalise)


def scorer(problem: Problem, cands: list, refinement: Refinement, null: NullPrediction, settings: dict) -> Scorer:
    """The dense spline curves of the candidates on top of the specimen-mean shift, the nuisance families and the
    metric of the tests (``test_metric``, ``lr_normalise``)."""
    y, sig, valid, bank = problem.y, problem.sigma, null.valid, null.bank
    curves = {c: (lambda td, D: (td, D + null.shift))(*_dense(*refinement.curves_raw[c], *fx.EFFECTS[c].bounds))
              for c in cands}
    too_few = int(valid.sum()) < int(settings["min_rows"])
    nuis = families(problem, valid) if not too_few else []
    null_model = None
    if bank is not None:
        null_model = fit_null_noise(problem.meta.get("spec_sd", np.full(len(y), np.nan)), bank, valid)
    decorrelate = settings["test_metric"] == "specimen_correlation"
    metric = (specimen_metric(bank, null_model, sig, valid) if decorrelate and bank is not None and valid.sum() >= 3
              else Metric(valid, sig))
    normalise = bool(settings["lr_normalise"]) or bank is None
    r0 = np.where(valid, null.r, 0.0)
    curves_w = {c: (td, metric(np.where(np.isfinite(D), D, r0 + 10.0 * sig))) for c, (td, D) in curves.items()}
    nuis_w = {nu.name: (nu, metric(nu.columns(r0).T).T) for nu in nuis}
    return Scorer(metric, curves, curves_w, nuis, nuis_w, r0, metric(r0)[0], normalise, null_model, too_few)


def refit(problem: Problem, cands: list, best: str | None, refinement: Refinement, null: NullPrediction,
          score: Scorer, obs: dict) -> tuple[dict, dict, int]:
    """The estimates in the metric of the tests (each candidate's spline chi-square minimised around the dense grid's
    optimum ``obs["th_c"]``) and the refits on top of the specimen-mean shift: the exact model at the ``best``
    candidate's estimate (one forward batch), the others' splines at theirs. Returns (estimates, refits, batches)."""
    y = problem.y
    est = dict(refinement.est)
    y_w = score.metric(np.where(np.isfinite(y), y, score.r0))[0]
    for c in cands:
        th, P = refinement.curves_raw[c]
        ok = np.isfinite(P).all(0)
        if ok.all() and len(th) >= 2:
            spline = CubicSpline(th, P, axis=0)
            lo, hi = fx.EFFECTS[c].bounds
            t0 = float(obs["th_c"][c][0])
            j = int(np.searchsorted(th, t0))
            a, b = th[max(j - 1, 0)], th[min(j + 1, len(th) - 1)]

            def f(t, spline=spline):
                return float(((score.metric(spline(t) + null.shift) - y_w) ** 2).sum())

            res = minimize_scalar(f, bounds=(max(a, lo), min(b, hi)), method="bounded",
                                  options={"xatol": 1e-6 * (hi - lo)})
            est[c] = float(res.x) if res.fun <= f(t0) else t0
    exact = {}
    for c in cands:
        if np.isfinite(est[c]):
            th, P = refinement.curves_raw[c]
            ok = np.isfinite(P).all(0)
            e = np.full(len(y), np.nan)
            e[ok] = CubicSpline(th, P[:, ok], axis=0)(est[c])
            exact[c] = e + null.shift
    batches = 0
    if best is not None and np.isfinite(est[best]):
        exact[best] = _batch(problem, [(best, np.array([est[best]]))])[0][0] + null.shift
        batches = 1
    return est, exact, batches


@dataclass
class NullTests:
    """Phase 3 (null tests): the parametric bootstrap under the null hypothesis and its p-values."""
    B: int                      # null tables asked for (n_bootstrap)
    c_hat0: float               # overdispersion of the null model on the data
    p_adj: dict = field(default_factory=dict)       # candidate -> max-T p-value
    p_raw: dict = field(default_factory=dict)       # candidate -> its own bootstrap p-value
    Tmax_null: np.ndarray = field(default_factory=lambda: np.array([]))
    boot: dict | None = None    # the statistics of the null tables (None: no bootstrap)
    Yb: np.ndarray | None = None   # null tables of the LR tests and their sigmas
    Sb: np.ndarray | None = None
    Yf: np.ndarray | None = None   # null tables of the goodness-of-fit tests and their sigmas
    Sf: np.ndarray | None = None
    fit0: dict | None = None    # statistics of the goodness-of-fit tables without specimens
    p_nuis: dict = field(default_factory=dict)      # nuisance family -> max-T p-value among the families
    p_fit: dict = field(default_factory=dict)       # explanation -> goodness-of-fit p-value


def null_tests(problem: Problem, cands: list, null: NullPrediction, score: Scorer, obs: dict,
               settings: dict) -> NullTests:
    """Phase 3: ``n_bootstrap`` null tables (virtual specimens of the bank, or the null prediction plus Gaussian noise
    x sqrt(c0)), every candidate's LR statistic on them, the single-step max-T p-values (candidates, and nuisance
    families among themselves) and the null model's goodness of fit. None of it with too few rows or B = 0."""
    T_obs = {c: float(v[0]) for c, v in obs["T_c"].items()}
    out = NullTests(int(settings["n_bootstrap"]), float(obs["c0"][0]))
    rng = np.random.default_rng([int(settings.get("seed", 0)), 15])
    bank, r = null.bank, null.r
    if score.too_few or out.B <= 0 or null.nv < 2:
        return out
    if bank is not None:
        # the reference path when the problem carries new specimens for every null table (tests)
        out.Yb, out.Sb = null_datasets(problem, bank, score.null_model, out.B, rng,
                                       fresh=problem.meta.get("null_fresh"))
    else:
        out.Yb, out.Sb = _resample(problem, r, np.sqrt(out.c_hat0), out.B, rng)
    # the goodness-of-fit (adequacy) tests take the null at face value: without specimens, the table's stated
    # noise (the LR tests above use it x sqrt(c), robust to a table noisier than it says); with specimens the
    # same null tables
    out.Yf, out.Sf = (out.Yb, out.Sb) if bank is not None else _resample(problem, r, 1.0, out.B, rng)
    out.fit0 = score(out.Yf, cands_=[], nuis_=[]) if bank is None else None
    out.boot = boot = score(out.Yb)
    if cands:
        out.Tmax_null = np.max(np.vstack([boot["T_c"][c] for c in cands]), axis=0)
        for c in cands:
            out.p_raw[c] = _p(boot["T_c"][c], T_obs[c])
            out.p_adj[c] = _p(out.Tmax_null, T_obs[c])
    if score.nuis:
        Tn_max = np.max(np.vstack([boot["T_n"][nu.name] for nu in score.nuis]), axis=0)
        out.p_nuis = {nu.name: _p(Tn_max, float(obs["T_n"][nu.name][0])) for nu in score.nuis}
    out.p_fit["specimen_mean"] = _p((boot if out.fit0 is None else out.fit0)["chi_r"], float(obs["chi_r"][0]))
    return out


@dataclass
class NuisanceRefits:
    """Phase 4a: the nuisance explanations refitted to the data, the best one, and which candidates act on the
    experiment as a nuisance family does."""
    aic: dict            # explanation (the null model's label, each family) -> AIC with the overdispersion c0
    nres: dict           # family -> its description, parameters, chi2, p-value, gap, equivalent candidates
    ncorr: dict          # candidate -> family -> multiple correlation of their effects
    equiv: dict          # candidate -> families it is equivalent to (multiple correlation >= max_correlation)
    best_nuisance: str   # lowest AIC (ties: the null model)
    fam: dict            # family name -> family


def nuisance_refits(problem: Problem, cands: list, null: NullPrediction, score: Scorer, obs: dict,
                    tests: NullTests, settings: dict) -> NuisanceRefits:
    """Phase 4a: every nuisance family's closed-form refit, its AIC (with the overdispersion of the null model) and
    its multiple correlation with each candidate's effect in the metric of the tests."""
    y, sig, valid, nv = problem.y, problem.sigma, null.valid, null.nv
    S_w = {c: (lambda td, D: D[np.abs(td - _ref_value(c)).argmin()] - D[np.abs(td).argmin()])(*score.curves_w[c])
           for c in cands}
    aic = {null.none_label: float(obs["chi_r"][0]) / tests.c_hat0}
    nres = {}
    for nu in score.nuis:
        par = obs["par_n"][nu.name][0]
        pred = nu.predict(np.where(valid, null.r, 0.0), par)
        aic[nu.name] = float(obs["chi_n"][nu.name][0]) / tests.c_hat0 + 2 * nu.k
        zn = (pred - y) / sig
        nres[nu.name] = {"description": nu.describe(par, problem.unit), "k": nu.k,
                         "parameters": dict(zip(nu.labels, map(float, par))), "chi2": float(obs["chi_n"][nu.name][0]),
                         "aic": aic[nu.name], "lr_statistic": float(obs["T_n"][nu.name][0]),
                         "p_value": tests.p_nuis.get(nu.name),
                         "gap": float(np.sqrt(np.mean(zn[valid] ** 2))) if nv else None,
                         "equivalent_candidates": []}
    ncorr = {c: {nu.name: multiple_correlation(S_w[c], score.nuis_w[nu.name][1]) for nu in score.nuis} for c in cands}
    equiv = {c: [n for n, m in ncorr[c].items() if np.isfinite(m) and m >= float(settings["max_correlation"])]
             for c in cands}
    for c, names in equiv.items():
        for nm in names:
            nres[nm]["equivalent_candidates"].append(c)
    best_nuisance = min(aic, key=lambda k: (aic[k], k != null.none_label))
    return NuisanceRefits(aic, nres, ncorr, equiv, best_nuisance, {nu.name: nu for nu in score.nuis})


@dataclass
class Diagnostics:
    """Ranking and diagnostics of the refits: chi2 per model, QAICc, the candidates' weights, cross-validation, and
    the naming margins in the metric of the tests."""
    chi: dict                 # "none" and every refitted candidate -> chi2 (RMS z basis, 10 sigma per lost row)
    score: dict               # QAICc
    cw: dict                  # candidate weights (confidence)
    cv: dict                  # grouped cross-validation RMS z
    gap_null: float           # RMS of the null prediction's residuals in the metric
    chi_null_obs: float       # its chi2 in the metric
    gap_after_best: float     # RMS z after the best candidate's exact refit
    gap_after_best_w: float   # the same in the metric of the tests


def diagnostics(problem: Problem, cands: list, best: str | None, exact: dict, grids: Grids, refinement: Refinement,
                null: NullPrediction, score: Scorer, obs: dict) -> Diagnostics:
    """Every refit's chi2, QAICc, weights among the candidates and cross-validation (diagnostics), and the gap
    against the null prediction and after the best candidate's refit in the metric of the tests (with specimens, a
    table's correlated deviations, which no effect explains, weigh there as what they are; without, the RMS z)."""
    y, sig, valid, nv, r = problem.y, problem.sigma, null.valid, null.nv, null.r
    w = 1.0 / sig ** 2
    chi = {"none": float(((r - y)[valid] ** 2 * w[valid]).sum())}
    for c in exact:
        ok = valid & np.isfinite(exact[c])
        z = (exact[c] - y) / sig
        # a scenario that loses its equilibrium under the effect counts as a large residual (10 sigma)
        chi[c] = float((np.where(ok, z, 10.0)[valid] ** 2).sum())
    chat = max(1.0, min(chi.values()) / max(nv - 1, 1))
    qaicc = {m: _qaicc(v, 0 if m == "none" else 1, nv, chat) for m, v in chi.items()}
    c_best = max(1.0, chi[best] / max(nv - 1, 1)) if best in chi else 1.0
    cw = {c: np.exp(-0.5 * (chi[c] - min(chi[k] for k in exact)) / c_best) for c in exact}
    tot = sum(cw.values())
    cw = {c: float(v / tot) for c, v in cw.items()} if tot > 0 else {}
    cv = _cross_validate(problem, cands, grids.grids, grids.coarse, refinement.fine_theta, refinement.fine, exact,
                         null.yr, w, sig, valid, null.gap_before) if nv >= 3 else {"none": null.gap_before}
    gap_null = float(np.sqrt(obs["chi_r"][0] / nv)) if nv else float("nan")
    gap_after_best, gap_after_best_w = float("nan"), float("nan")
    if best is not None and best in exact:
        zb = (exact[best] - y) / sig
        gap_after_best = float(np.sqrt(np.mean(np.where(np.isfinite(zb), zb, 10.0)[valid] ** 2)))
        eb = np.where(np.isfinite(exact[best]), exact[best], score.r0 + 10.0 * sig)
        y_w = score.metric(np.where(np.isfinite(y), y, score.r0))[0]
        gap_after_best_w = float(np.sqrt(((score.metric(eb) - y_w) ** 2).sum() / nv))
    return Diagnostics(chi, qaicc, cw, cv, gap_null, float(obs["chi_r"][0]), gap_after_best, gap_after_best_w)


@dataclass
class NuisanceComparison:
    """Phase 4b: the best candidate against the best nuisance explanation it is not equivalent to, and the adequacy
    of the best candidate's and the best nuisance's refits."""
    versus: str | None = None     # the explanation the best candidate is tested against
    p_vs: float | None = None     # bootstrap p-value of that test
    D_obs: float | None = None    # its observed statistic
    p_fit: dict = field(default_factory=dict)   # the null tests' p_fit with best_candidate and best_nuisance added


def compare_nuisance(cands: list, best: str | None, exact: dict, null: NullPrediction, score: Scorer, obs: dict,
                     tests: NullTests, refits: NuisanceRefits) -> NuisanceComparison:
    """Phase 4b: the best candidate against the best nuisance it is not equivalent to (lowest AIC), by the same
    bootstrap LR test on tables of the nuisance hypothesis (the null tables moved by the nuisance's refit); the
    adequacy of each explanation: its residual chi2 against its own null tables."""
    out = NuisanceComparison(p_fit=dict(tests.p_fit))
    T_obs = {c: float(v[0]) for c, v in obs["T_c"].items()}
    r, valid, nv = null.r, null.valid, null.nv
    fam, aic, equiv, best_nuisance = refits.fam, refits.aic, refits.equiv, refits.best_nuisance
    if best is not None and tests.boot is not None:
        allowed = {k: v for k, v in aic.items() if k not in equiv.get(best, [])}
        out.versus = versus = min(allowed, key=lambda k: (allowed[k], k != null.none_label))
        if versus == null.none_label:
            out.p_vs, out.D_obs = tests.p_adj.get(best), T_obs[best]
        else:
            nu = fam[versus]
            Yn, _ = nu.transform(tests.Yb, tests.Sb, r, obs["par_n"][versus][0])
            bn = score(Yn, nuis_=[versus])

            def dstat(st):
                cn = np.maximum(1.0, st["chi_n"][versus] / max(nv - 1 - nu.k, 1)) if score.normalise else 1.0
                return (st["chi_n"][versus] - np.min(np.vstack([st["chi_c"][c] for c in cands]), axis=0)) / cn

            out.D_obs = float(dstat(obs)[0])
            out.p_vs = _p(dstat(bn), out.D_obs)
        # adequacy of the best candidate: null tables shifted by its refit effect, refitted
        if best in exact and np.isfinite(exact[best][valid]).all():
            Yc = tests.Yf + (exact[best] - r)[None, :]
            bc = score(Yc, cands_=[best], nuis_=[])
            out.p_fit["best_candidate"] = _p(bc["chi_c"][best], float(obs["chi_c"][best][0]))
    if tests.boot is not None and best_nuisance != null.none_label:
        nu = fam[best_nuisance]
        Yn, _ = nu.transform(tests.Yf, tests.Sf, r, obs["par_n"][best_nuisance][0])
        bn = score(Yn, cands_=[], nuis_=[best_nuisance])
        out.p_fit["best_nuisance"] = _p(bn["chi_n"][best_nuisance], float(obs["chi_n"][best_nuisance][0]))
    elif "specimen_mean" in out.p_fit:
        out.p_fit["best_nuisance"] = out.p_fit["specimen_mean"]
    return out


def discover(problem: Problem, settings: dict | None = None, cache: dict | None = None) -> dict:
    """Rank the candidate effects and the nuisance explanations, test them against the null hypothesis with
    specimens in it and against each other, and decide (see the package doc). The phases: :func:`fit_grids`,
    :func:`null_prediction`, :func:`refine`, :func:`scorer` and :func:`refit`, :func:`null_tests`,
    :func:`nuisance_refits`, :func:`diagnostics`, :func:`compare_nuisance`, :func:`explained_share`, :func:`decide`;
    :func:`result_record` writes the result."""
    s = default_settings()
    s.update(settings or {})
    t_start = time.perf_counter()
    cands = list(problem.candidates)
    grids = fit_grids(problem, cands, s, cache)
    null = null_prediction(problem, grids.base)
    refinement = refine(problem, cands, grids, null, s)
    score = scorer(problem, cands, refinement, null, s)
    obs = score(problem.y[None, :])
    T_obs = {c: float(v[0]) for c, v in obs["T_c"].items()}
    cand_rank = sorted(cands, key=lambda c: -T_obs[c])
    best = cand_rank[0] if cand_rank else None
    est, exact, refit_batches = refit(problem, cands, best, refinement, null, score, obs)
    tests = null_tests(problem, cands, null, score, obs, s)
    refits = nuisance_refits(problem, cands, null, score, obs, tests, s)
    diag = diagnostics(problem, cands, best, exact, grids, refinement, null, score, obs)
    comparison = compare_nuisance(cands, best, exact, null, score, obs, tests, refits)
    explained, chi_after_obs, chi_null_expected = explained_share(diag.gap_after_best_w, null.nv, diag.chi_null_obs,
                                                                  tests)
    evidence = Evidence(best, null.nv, len(cands), null.gap_before, score.too_few, tests.p_adj, tests.B,
                        null.bank is not None, comparison.versus, comparison.p_vs, comparison.p_fit, explained,
                        diag.chi_null_obs, chi_after_obs, chi_null_expected, null.null_text, null.none_label,
                        refits.best_nuisance, tests.p_nuis, refits.nres)
    decision = decide(evidence, s)
    S = _sensitivities(score.curves, cands, problem.sigma, null.valid)
    ident = _identifiability(problem, cands, S, s, cache) \
        if len(cands) >= 2 and null.nv >= 1 else {"correlation": {}, "max_correlation": float(s["max_correlation"]),
                                                  "non_separable": []}
    ident["nuisance_correlation"] = refits.ncorr
    batches = grids.batches + refinement.batches + refit_batches
    res, scen = result_record(problem, s, cands, cand_rank, best, est, exact, grids, null, score, obs, tests, refits,
                              diag, comparison, evidence, decision, ident)
    res["forward_batches"] = batches
    res["seconds"] = time.perf_counter() - t_start
    return {"result": res, "scenarios": scen, "problem": problem}


def _cross_validate(problem, cands, grids, coarse, fine_theta, fine, exact, y, w, sig, valid, gap_before):
    """Grouped cross-validation of the RMS z (held-out folds; on the coarse + fine splines; ``y`` relative to the
    specimen-mean shift). Diagnostic only."""
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
