"""Fitting and scoring the candidate effects of a discovery problem: batched grid solves, splines, the
bootstrap likelihood-ratio test, the naming rule, identifiability and cross-validation (:func:`discover`)."""
from __future__ import annotations

import time

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from ..experiments import effects as fx
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


def discover(problem: Problem, settings: dict | None = None, cache: dict | None = None) -> dict:
    """Rank the candidate effects and the nuisance explanations, test them against the null hypothesis with
    specimens in it and against each other, and decide (see the package doc)."""
    s = default_settings()
    s.update(settings or {})
    t_start = time.perf_counter()
    y, sig = problem.y, problem.sigma
    w = 1.0 / sig**2
    cands = list(problem.candidates)
    n_batches = 0
    # batch 1: no-effect model and the coarse grid of every candidate
    grids = {c: coarse_grid(*fx.EFFECTS[c].bounds, int(s["grid_points"])) for c in cands}
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
    # the null hypothesis' prediction: the mean of virtual specimens of the nominal model (specimen-mean shift)
    bank = problem.meta.get("bank")
    r = np.where(np.isfinite(bank.mean), bank.mean, np.nan) if bank is not None else base.copy()
    shift = r - base
    valid = np.isfinite(base) & np.isfinite(y) & np.isfinite(sig) & np.isfinite(r)
    # the null model's name among the explanations, and what the null tables are made of
    none_label = "specimen-mean shift" if bank is not None else "nominal model"
    null_text = ("the nominal model with specimen variation" if bank is not None else
                 "the nominal model and the measurement noise")
    yr = y - np.where(valid, shift, 0.0)           # the data relative to the shift: the candidates' grids fit it
    z0 = (base - y) / sig
    chi_nominal = float((z0[valid] ** 2).sum())
    nv = int(valid.sum())
    gap_before = float(np.sqrt(np.mean(z0[valid] ** 2))) if nv else float("nan")
    # coarse estimates, then batch 2: fine grid around each optimum
    est, fine_theta, coarse_chi = {}, {}, {}
    for c in cands:
        lo, hi = fx.EFFECTS[c].bounds
        est[c], coarse_chi[c] = _spline_fit(grids[c], coarse[c], yr, w, lo, hi, valid)
    # the fine grid only for the leading candidates (``fine_candidates`` lowest coarse chi2): it refines the
    # estimate that can be named; the others keep their coarse-spline estimate
    lead = sorted([c for c in cands if np.isfinite(est[c])], key=lambda c: coarse_chi[c])[: int(s["fine_candidates"])]
    for c in lead:
        lo, hi = fx.EFFECTS[c].bounds
        g = grids[c]
        j = int(np.clip(np.searchsorted(g, est[c]), 1, len(g) - 1))
        step = g[j] - g[j - 1]
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
            est[c], _ = _spline_fit(th, P, yr, w, lo, hi, valid)
    # ---- statistics of every model on the data (dense spline curves on top of the specimen-mean shift)
    curves = {c: (lambda td, D: (td, D + shift))(*_dense(*curves_raw[c], *fx.EFFECTS[c].bounds)) for c in cands}
    too_few = int(valid.sum()) < int(s["min_rows"])
    nuis = families(problem, valid) if not too_few else []
    # the metric of the tests: the table's standard errors, decorrelated by the specimens' correlation (the bank's,
    # shrunk, with the fitted noise); independent rows without a bank
    null_model = None
    if bank is not None:
        null_model = fit_null_noise(problem.meta.get("spec_sd", np.full(len(y), np.nan)), bank, valid)
    decorrelate = s["test_metric"] == "specimen_correlation"
    metric = (specimen_metric(bank, null_model, sig, valid) if decorrelate and bank is not None and valid.sum() >= 3
              else Metric(valid, sig))
    normalise = bool(s["lr_normalise"]) or bank is None
    r0 = np.where(valid, r, 0.0)
    curves_w = {c: (td, metric(np.where(np.isfinite(D), D, r0 + 10.0 * sig))) for c, (td, D) in curves.items()}
    r_w = metric(r0)[0]
    nuis_w = {nu.name: (nu, metric(nu.columns(r0).T).T) for nu in nuis}

    def stats(Y, cands_=None, nuis_=None):
        cw_ = curves_w if cands_ is None else {c: curves_w[c] for c in cands_}
        nw_ = nuis_w if nuis_ is None else {n: nuis_w[n] for n in nuis_}
        return _statistics(cw_, nw_, r_w, metric(np.where(np.isfinite(Y), Y, r0)), normalise=normalise)

    obs = stats(y[None, :])
    T_obs = {c: float(v[0]) for c, v in obs["T_c"].items()}
    cand_rank = sorted(cands, key=lambda c: -T_obs[c])
    best = cand_rank[0] if cand_rank else None
    # the estimates in the metric of the tests: the spline's chi-square minimised around the dense grid's optimum
    y_w = metric(np.where(np.isfinite(y), y, r0))[0]
    for c in cands:
        th, P = curves_raw[c]
        ok = np.isfinite(P).all(0)
        if ok.all() and len(th) >= 2:
            spline = CubicSpline(th, P, axis=0)
            lo, hi = fx.EFFECTS[c].bounds
            t0 = float(obs["th_c"][c][0])
            j = int(np.searchsorted(th, t0))
            a, b = th[max(j - 1, 0)], th[min(j + 1, len(th) - 1)]

            def f(t, spline=spline):
                return float(((metric(spline(t) + shift) - y_w) ** 2).sum())

            res = minimize_scalar(f, bounds=(max(a, lo), min(b, hi)), method="bounded",
                                  options={"xatol": 1e-6 * (hi - lo)})
            est[c] = float(res.x) if res.fun <= f(t0) else t0
    # batch 3: the exact model at the best candidate's estimate (its refit), on top of the specimen-mean shift; the
    # other candidates' refits are their splines at their estimates
    exact = {}
    for c in cands:
        if np.isfinite(est[c]):
            th, P = curves_raw[c]
            ok = np.isfinite(P).all(0)
            e = np.full(len(y), np.nan)
            e[ok] = CubicSpline(th, P[:, ok], axis=0)(est[c])
            exact[c] = e + shift
    if best is not None and np.isfinite(est[best]):
        exact[best] = _batch(problem, [(best, np.array([est[best]]))])[0][0] + shift
        n_batches += 1
    chi = {"none": float(((r - y)[valid] ** 2 * w[valid]).sum())}
    for c in exact:
        ok = valid & np.isfinite(exact[c])
        z = (exact[c] - y) / sig
        # a scenario that loses its equilibrium under the effect counts as a large residual (10 sigma)
        chi[c] = float((np.where(ok, z, 10.0)[valid] ** 2).sum())
    too_few = nv < int(s["min_rows"])
    B = int(s["n_bootstrap"])
    c_hat0 = float(obs["c0"][0])
    rng = np.random.default_rng([int(s.get("seed", 0)), 15])
    p_adj, p_raw, Tmax_null, boot, Yb, Sb, Yf, Sf, fit0 = {}, {}, np.array([]), None, None, None, None, None, None
    p_nuis, p_fit = {}, {}
    if not too_few and B > 0 and nv >= 2:
        if bank is not None:
            # the reference path when the problem carries new specimens for every null table (tests)
            Yb, Sb = null_datasets(problem, bank, null_model, B, rng, fresh=problem.meta.get("null_fresh"))
        else:
            Yb, Sb = _resample(problem, r, np.sqrt(c_hat0), B, rng)
        # the goodness-of-fit (adequacy) tests take the null at face value: without specimens, the table's stated
        # noise (the LR tests above use it x sqrt(c), robust to a table noisier than it says); with specimens the
        # same null tables
        Yf, Sf = (Yb, Sb) if bank is not None else _resample(problem, r, 1.0, B, rng)
        fit0 = stats(Yf, cands_=[], nuis_=[]) if bank is None else None
        boot = stats(Yb)
        if cands:
            Tmax_null = np.max(np.vstack([boot["T_c"][c] for c in cands]), axis=0)
            for c in cands:
                p_raw[c] = _p(boot["T_c"][c], T_obs[c])
                p_adj[c] = _p(Tmax_null, T_obs[c])
        if nuis:
            Tn_max = np.max(np.vstack([boot["T_n"][nu.name] for nu in nuis]), axis=0)
            p_nuis = {nu.name: _p(Tn_max, float(obs["T_n"][nu.name][0])) for nu in nuis}
        p_fit["specimen_mean"] = _p((boot if fit0 is None else fit0)["chi_r"], float(obs["chi_r"][0]))
    # ---- nuisance models: refits, the best one (AIC with the overdispersion of "none"), equivalence with candidates
    S = _sensitivities(curves, cands, sig, valid)
    S_w = {c: (lambda td, D: D[np.abs(td - _ref_value(c)).argmin()] - D[np.abs(td).argmin()])(*curves_w[c])
           for c in cands}
    aic = {none_label: float(obs["chi_r"][0]) / c_hat0}
    nres = {}
    for nu in nuis:
        par = obs["par_n"][nu.name][0]
        pred = nu.predict(np.where(valid, r, 0.0), par)
        aic[nu.name] = float(obs["chi_n"][nu.name][0]) / c_hat0 + 2 * nu.k
        zn = (pred - y) / sig
        nres[nu.name] = {"description": nu.describe(par, problem.unit), "k": nu.k,
                         "parameters": dict(zip(nu.labels, map(float, par))), "chi2": float(obs["chi_n"][nu.name][0]),
                         "aic": aic[nu.name], "lr_statistic": float(obs["T_n"][nu.name][0]),
                         "p_value": p_nuis.get(nu.name), "gap": float(np.sqrt(np.mean(zn[valid] ** 2))) if nv else None,
                         "equivalent_candidates": []}
    ncorr = {c: {nu.name: multiple_correlation(S_w[c], nuis_w[nu.name][1]) for nu in nuis} for c in cands}
    equiv = {c: [n for n, m in ncorr[c].items() if np.isfinite(m) and m >= float(s["max_correlation"])]
             for c in cands}
    for c, names in equiv.items():
        for nm in names:
            nres[nm]["equivalent_candidates"].append(c)
    best_nuisance = min(aic, key=lambda k: (aic[k], k != none_label))
    # ---- ranking (by the LR statistic), confidence among the candidates, diagnostics
    chat = max(1.0, min(chi.values()) / max(nv - 1, 1))
    score = {m: _qaicc(v, 0 if m == "none" else 1, nv, chat) for m, v in chi.items()}
    c_best = max(1.0, chi[best] / max(nv - 1, 1)) if best in chi else 1.0
    cw = {c: np.exp(-0.5 * (chi[c] - min(chi[k] for k in exact)) / c_best) for c in exact}
    tot = sum(cw.values())
    cw = {c: float(v / tot) for c, v in cw.items()} if tot > 0 else {}
    cv = _cross_validate(problem, cands, grids, coarse, fine_theta, fine, exact, yr, w, sig, valid, gap_before) \
        if nv >= 3 else {"none": gap_before}
    # the naming margins in the metric of the tests: the RMS of the decorrelated residuals against the null
    # prediction r and after the best candidate's exact refit (with specimens, a table's correlated deviations,
    # which no effect explains, weigh there as what they are; without, these are the RMS z)
    gap_null = float(np.sqrt(obs["chi_r"][0] / nv)) if nv else float("nan")
    chi_null_obs = float(obs["chi_r"][0])
    gap_after_best, gap_after_best_w = float("nan"), float("nan")
    if best is not None and best in exact:
        zb = (exact[best] - y) / sig
        gap_after_best = float(np.sqrt(np.mean(np.where(np.isfinite(zb), zb, 10.0)[valid] ** 2)))
        eb = np.where(np.isfinite(exact[best]), exact[best], r0 + 10.0 * sig)
        gap_after_best_w = float(np.sqrt(((metric(eb) - y_w) ** 2).sum() / nv))
    # ---- the best candidate against the best nuisance it is not equivalent to, by the same bootstrap LR test;
    # the adequacy of each explanation: its residual chi2 against its own bootstrap
    versus, p_vs, D_obs = None, None, None
    fam = {nu.name: nu for nu in nuis}
    if best is not None and boot is not None:
        allowed = {k: v for k, v in aic.items() if k not in equiv.get(best, [])}
        versus = min(allowed, key=lambda k: (allowed[k], k != none_label))
        if versus == none_label:
            p_vs, D_obs = p_adj.get(best), T_obs[best]
        else:
            nu = fam[versus]
            Yn, _ = nu.transform(Yb, Sb, r, obs["par_n"][versus][0])
            bn = stats(Yn, nuis_=[versus])

            def dstat(st):
                cn = np.maximum(1.0, st["chi_n"][versus] / max(nv - 1 - nu.k, 1)) if normalise else 1.0
                return (st["chi_n"][versus] - np.min(np.vstack([st["chi_c"][c] for c in cands]), axis=0)) / cn

            D_obs = float(dstat(obs)[0])
            p_vs = _p(dstat(bn), D_obs)
        # adequacy of the best candidate: null tables shifted by its refit effect, refitted
        if best in exact and np.isfinite(exact[best][valid]).all():
            Yc = Yf + (exact[best] - r)[None, :]
            bc = stats(Yc, cands_=[best], nuis_=[])
            p_fit["best_candidate"] = _p(bc["chi_c"][best], float(obs["chi_c"][best][0]))
    if boot is not None and best_nuisance != none_label:
        nu = fam[best_nuisance]
        Yn, _ = nu.transform(Yf, Sf, r, obs["par_n"][best_nuisance][0])
        bn = stats(Yn, cands_=[], nuis_=[best_nuisance])
        p_fit["best_nuisance"] = _p(bn["chi_n"][best_nuisance], float(obs["chi_n"][best_nuisance][0]))
    elif "specimen_mean" in p_fit:
        p_fit["best_nuisance"] = p_fit["specimen_mean"]
    # the share of the discrepancy the best candidate's refit explains: its chi2 drop (metric of the tests) over the
    # excess of the observed chi2 above its expectation under the null (the null tables taken at face value); the
    # null's own discrepancy (specimens, noise) is no effect's to explain
    chi_after_obs = gap_after_best_w ** 2 * nv if np.isfinite(gap_after_best_w) else float("nan")
    null_chi = (boot if fit0 is None else fit0) if boot is not None else None     # fit0: tables without specimens
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
    # ---- decision
    alpha = float(s["alpha"])
    reasons = []
    if best is None:
        reasons.append("no candidate effect acts on this experiment")
    elif too_few:
        reasons.append(f"too few rows: {nv} scenario(s) compared, at least {int(s['min_rows'])} needed to test "
                       f"{len(cands)} candidate(s) against the measurement noise; nothing can be named from these data")
    else:
        if not gap_before > s["min_gap"]:
            reasons.append(f"gap_before {gap_before:.2f} <= min_gap {s['min_gap']:g}: model and data agree within the "
                           f"measurement uncertainty")
        if not p_adj.get(best, 1.0) < alpha:
            reasons.append(f"p = {p_adj.get(best, float('nan')):.3g} for {best} (max-T over {len(cands)} candidates, "
                           f"{B} null tables{' of virtual specimens' if bank is not None else ''}) is not below alpha "
                           f"{alpha:g}")
        if not (p_vs if p_vs is not None else 1.0) < alpha:
            reasons.append(f"{best} does not beat the nuisance explanation '{versus}' (p = {fmt_p(p_vs)} by the same "
                           f"bootstrap LR test, tables of the nuisance hypothesis) below alpha {alpha:g}")
        if not p_fit.get("best_candidate", 0.0) >= alpha:
            reasons.append(f"the refit of {best} leaves a misfit the null tables do not have (p = "
                           f"{fmt_p(p_fit.get('best_candidate'))} < alpha {alpha:g}): part of the discrepancy is not "
                           f"this effect")
        red = explained
        if not red >= s["min_gap_reduction"]:
            reasons.append(f"the refit explains {100 * red:.0f}% < {100 * s['min_gap_reduction']:.0f}% of the "
                           f"discrepancy beyond what the null hypothesis gives (chi2 {chi_null_obs:.1f} -> "
                           f"{chi_after_obs:.1f}, {chi_null_expected:.1f} expected)")
    named = best if best is not None and not reasons else None
    if named:
        decision = f"named: {named}"
    elif too_few or best is None:
        decision = "nothing named: " + "; ".join(reasons)
    elif p_fit.get("specimen_mean", 0.0) >= alpha:
        shifted = bank is not None and gap_before > s["min_gap"]
        decision = "nuisance: specimen-mean shift" if shifted else "nothing named"
        reasons.append(f"the table is consistent with {null_text} (goodness of fit p = "
                       f"{fmt_p(p_fit.get('specimen_mean'))})" + (
                           f"; its gap to the nominal model ({gap_before:.2f}) is what the mean of varied specimens "
                           f"gives" if shifted else ""))
    elif (best_nuisance != none_label and p_nuis.get(best_nuisance, 1.0) < alpha
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
    nuis_pred = r if best_nuisance not in fam else fam[best_nuisance].predict(
        np.where(valid, r, np.nan), obs["par_n"][best_nuisance][0])
    after = exact[named] if named else base
    z1 = (after - y) / sig
    gap_after = gap_after_best if named else gap_before
    zr = (r - y) / sig
    zn = (nuis_pred - y) / sig
    rms_phys0 = float(np.sqrt(np.mean((base - y)[valid] ** 2))) if nv else float("nan")
    dev1 = np.where(np.isfinite(after), after - y, np.nan)[valid]
    rms_phys1 = float(np.sqrt(np.mean(dev1 ** 2))) if nv else float("nan")
    scen = problem.keys.copy()
    scen["measured"] = y
    scen["sigma"] = sig
    scen["model_before"] = base
    scen["z_before"] = z0
    scen["model_specimen_mean"] = r
    scen["z_specimen_mean"] = zr
    scen["model_nuisance"] = nuis_pred
    scen["z_nuisance"] = zn
    scen["model_after"] = after
    scen["z_after"] = z1
    scen["unit"] = problem.unit
    for k in ("quantity", "nominal_model"):      # what is compared, and with which model (when the problem says)
        if k in problem.meta:
            scen[k] = problem.meta[k]
    eff = fx.EFFECTS.get(named) if named else None

    def at_bound(c):
        lo, hi = fx.EFFECTS[c].bounds
        return bool(np.isfinite(est[c]) and min(est[c] - lo, hi - est[c]) <= 1e-3 * (hi - lo))

    ident = _identifiability(problem, cands, S, s, cache) \
        if len(cands) >= 2 and nv >= 1 else {"correlation": {}, "max_correlation": float(s["max_correlation"]),
                                             "non_separable": []}
    ident["nuisance_correlation"] = ncorr
    ranking = [["none", 0.0]] + [[c, T_obs[c]] for c in cand_rank]
    ranking = sorted(ranking, key=lambda kv: -kv[1])
    kind = ("virtual_specimens" if bank is not None else "gaussian")
    null_desc = ({"kind": kind, "specimens": bank.K, "bank": bank.source,
                  "correlation_shrinkage": metric.shrinkage} | null_model.describe(problem.unit)
                 if bank is not None else {"kind": kind, "noise_scale": float(np.sqrt(c_hat0))})
    gr = float(np.sqrt(np.mean(zr[valid] ** 2))) if nv else float("nan")
    res = {
        "experiment": problem.experiment,
        "n_scenarios": nv,
        "unit": problem.unit,
        "named_effect": named,
        "decision": decision,
        "decision_reasons": reasons,
        "parameter_estimate": ({"effect": named, "parameter": eff.parameter, "value": est[named], "unit": eff.unit,
                                "at_bound": at_bound(named)} if named else None),
        "named_equivalent_to": equiv.get(named, []) if named else [],
        "p_value": p_adj.get(best) if best is not None and not too_few else None,
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
        "specimen_mean": {"chi2": float(obs["chi_r"][0]), "gap": gr, "chi2_nominal": chi_nominal,
                          "p_fit": p_fit.get("specimen_mean")},
        "nuisance": nres,
        "best_nuisance": best_nuisance,
        "best_nuisance_description": nres[best_nuisance]["description"] if best_nuisance in nres else best_nuisance,
        "nuisance_test": {"candidate": best, "against": versus, "statistic": D_obs, "p_value": p_vs,
                          "equivalent_nuisance": equiv.get(best, []) if best else []},
        "adequacy_p": p_fit,
        "gap_before": gap_before, "gap_after": gap_after,
        "gap_after_above_threshold": bool(np.isfinite(gap_after) and gap_after > s["min_gap"]),
        "gap_before_rms": rms_phys0, "gap_after_rms": rms_phys1,
        "gap_specimen_mean": gr,
        "gap_nuisance": float(np.sqrt(np.mean(zn[valid] ** 2))) if nv else float("nan"),
        "gap_reduction": (1 - gap_after / gap_before) if named and gap_before > 0 else 0.0,
        "discrepancy_explained": explained,
        "gap_metric": {"null": gap_null, "after_best_candidate": gap_after_best_w,
                       "definition": "RMS of the residuals in the metric of the tests (standard errors of the table, "
                                     "decorrelated by the specimens' correlation; the RMS z without specimens): the "
                                     "naming margins min_gap and min_gap_reduction apply to it"},
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
        "input_warnings": list(problem.meta.get("input_warnings", [])),
        "criterion": ("LR statistic T_c = (chi2_0 - chi2_c) / c, chi2_0 of the specimen mean (nominal model + "
                      "specimen-mean shift), c = max(1, chi2_0 / (n - 1)); p-value by parametric bootstrap with "
                      "virtual specimens (max-T over candidates); named only if it also beats the best nuisance "
                      "explanation it is not equivalent to by the same test, and its refit is consistent with its own "
                      "null tables; gap = RMS of z against the nominal model"),
        "margins": {k: s[k] for k in ("alpha", "min_gap", "min_gap_reduction", "min_rows", "n_bootstrap")},
        "forward_batches": n_batches,
        "seconds": time.perf_counter() - t_start,
    }
    return {"result": res, "scenarios": scen, "problem": problem}


def fmt_p(p):
    return "n/a" if p is None else f"{p:.3g}"


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
