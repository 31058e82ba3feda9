"""The muscle model's sensitivity studies (paper 2, Sect. 3.2): one parameter at a time against the paper's
statements (data/paper2/paper2_claims_original_text.csv, :func:`sensitivity_rows`, :func:`run_sensitivity`,
:func:`sensitivity_directions`) and the Sobol indices of the five parameters from a polynomial-chaos surrogate
(:func:`sobol_samples`, :func:`sobol_evaluate`, :func:`sobol_indices`, :func:`sobol_study`). The parameters are set
by :func:`lumbar.muscles.muscle_model.apply_parameter`."""
from __future__ import annotations

import logging
from math import comb

import numpy as np
import pandas as pd

from . import pce
from .muscle_model import (
    PARAMETERS,
    POSTURES,
    apply_parameter,
    certificate,
    idp_parts,
    solve_with_progress,
)
from .muscle_set import ABDOMINALS, EXTENSORS

log = logging.getLogger(__name__)

def sensitivity_directions(df: pd.DataFrame, baseline: pd.DataFrame, claims: pd.DataFrame | None = None) -> pd.DataFrame:
    """Paper 2's sensitivity statements (the sensitivity, reachability and direction claims of
    ``data/paper2/paper2_claims_original_text.csv``, :mod:`lumbar.muscles.reproduction`) read against this sweep
    (``df``, the sensitivity table with ``change_pct``, ``reached``, ``certified``) and the baseline postures'
    validation table ``baseline``: one row per claim with the paper's value, ours, the verdict and the reason. The
    headline changes, the effects the paper calls small or negligible and the reachability statements are told apart
    by ``claim_class``, so that negligible effects cannot carry the count."""
    from . import reproduction as rp  # noqa: PLC0415 (reproduction reads this module's tables)

    claims = rp.read_claims() if claims is None else claims
    keep = claims[claims["claim_class"].isin(["sensitivity_headline", "sensitivity_bound", "sensitivity_direction",
                                              "reachability"])]
    empty = pd.DataFrame(columns=["activity"])
    res = rp.results_from_frames(baseline, {}, pd.DataFrame(columns=["level", "activity"]), empty, df)
    t = rp.claims_table(keep, {"reproduction": res})
    return t.drop(columns=["variant"])


def sensitivity_rows(parameter, ssl_um, values, scopes, postures) -> pd.DataFrame:
    """The scenarios of one sensitivity chunk (one Paramspace row: parameter and fixed SSL or none)."""
    if parameter not in PARAMETERS:
        raise ValueError(f"unknown muscle parameter {parameter!r}; expected one of {PARAMETERS}")
    rows = [{"parameter": parameter, "value": float(v), "ssl_um": ssl_um, "group_scope": sc, "posture": p}
            for v in values for sc in scopes for p in postures]
    return pd.DataFrame(rows)


def run_sensitivity(model, solver, rows: pd.DataFrame, baseline: dict, area_m2=18e-4, batch_size=None,
                    label="sensitivity") -> pd.DataFrame:
    """Solve every row (batches of ``batch_size``, progress logged), warm-started from the baseline solution
    of its posture."""
    props, start, names = [], [], []
    for _, r in rows.iterrows():
        ssl = None if pd.isna(r["ssl_um"]) else float(r["ssl_um"])
        props.append(apply_parameter(model.props, model.ms, r["parameter"], r["value"], r["group_scope"], ssl))
        names.append(POSTURES[r["posture"]])
        start.append(baseline[r["posture"]])
    sols = solve_with_progress(model, solver, names, props, start, batch_size, label)
    out = rows.copy()
    seg = [model.segment_loads(s.x[None], s.R[None]).query("level == 'L4-L5'").iloc[0] for s in sols]
    tot, fp, mp = idp_parts([s["compressive_n"] for s in seg], [s["moment_nm"] for s in seg], area_m2)
    out["idp_mpa"], out["idp_force_mpa"], out["idp_moment_mpa"] = tot, fp, mp
    out["converged"] = [s.converged for s in sols]
    out["reached"] = [s.reached for s in sols]
    out["certified"] = [s.certified for s in sols]
    out["kkt_residual"] = [s.kkt_residual for s in sols]
    out["ipopt_status"] = [s.ipopt_status for s in sols]      # why a reached posture is not certified
    out["tracking_error_deg"] = [s.tracking_error_deg for s in sols]
    ext, abd = np.isin(model.ms.groups, EXTENSORS), np.isin(model.ms.groups, ABDOMINALS)
    forces = [model.muscle_forces(s.x[None], s.R[None], s.a, pr)[2:4] for s, pr in zip(sols, props)]
    out["extensor_active_n"] = [float(a[0, ext].sum()) for a, _ in forces]
    out["extensor_passive_n"] = [float(q[0, ext].sum()) for _, q in forces]
    out["abdominal_active_n"] = [float(a[0, abd].sum()) for a, _ in forces]
    from . import reproduction as rp  # noqa: PLC0415
    claims = rp.read_claims()             # read once: the table's checks cost more than a row's lookup
    out["paper_claims"] = [";".join(paper_claim_ids(r["parameter"], float(r["value"]),
                                                     None if pd.isna(r["ssl_um"]) else float(r["ssl_um"]),
                                                     r["group_scope"], r["posture"], claims)) for _, r in out.iterrows()]
    return out


def paper_claim_ids(parameter, value, ssl_um, scope, posture, claims: pd.DataFrame | None = None) -> list:
    """The ids of paper 2's claims about one one-at-a-time scenario (data/paper2/paper2_claims_original_text.csv)."""
    from . import reproduction as rp  # noqa: PLC0415

    c = rp.read_claims() if claims is None else claims
    out = []
    for _, r in c[(c["parameter"] == parameter) & (c["scope"] == scope) & (c["posture"] == posture)].iterrows():
        vals = [float(v) for v in str(r["value"]).split("->")] if r["value"] != "" else []
        ssl = None if r["ssl_um"] == "" else float(r["ssl_um"])
        if ssl == ssl_um and any(np.isclose(v, value) for v in vals):
            out.append(r["claim_id"])
    return out


SOBOL_BOUNDS = {"ssl_um": (2.0, 3.6), "k_n_per_cm2": (10.0, 1000.0), "in_situ_sl_um": (2.0, 3.6),
                "spt_n_per_cm2": (5.0, 150.0), "pennation_deg": (0.0, 30.0)}
SOBOL_Q2_MIN = 0.9          # a PCE whose leave-one-out Q2 is below this is flagged (fit_ok False)
SOBOL_STABLE_WIDTH = 0.1    # stable: the top parameter's bootstrap 95 % S1 interval is narrower than this
# Sobol indices from a polynomial chaos surrogate (Sudret 2008; lumbar.muscles.pce), not from Saltelli sampling: SALib's
# Saltelli estimator with N = 16 (112 solves per posture) gave S1 up to 3.1 and 95 % half-widths 0.4-0.5 at
# N = 64; stable S1 would need N ~ 4096 (28 672 solves per posture).
# Default n_train 256, degree 3 (config/config.yaml), measured on 2026-11-23 with the config's model and solver
# (SQP certifier), seed 20261123, 500 bootstrap resamples; n_train 64/128 = the first points of the same design:
#   standing: 241 of 256 reached. degree 3: Q2_loo 0.952, top S1 (SSL) 0.340, interval width 0.040; degree 4:
#             Q2 0.978, width 0.050; degree 2: Q2 0.796. n_train 128, degree 3: Q2 0.933, width 0.099.
#   flexion:  193 of 256 reached. degree 3: Q2 0.960, top S1 (SSL) 0.376, width 0.067; degree 4 (126 terms on
#             193 points): Q2 0.960, width 0.284; degree 2: Q2 0.900. n_train 128, degree 3: Q2 0.957 but width
#             0.304 (98 reached points for 56 terms); n_train 64: width 0.18-0.22 in both postures.
# So degree 3 on 256 points is the smallest design stable in both postures (Q2 > 0.95). Tried and not better at
# n_train 128: hyperbolic (q = 0.75) or two-way-interaction truncation (Q2 0.70-0.93, widths 0.13-0.21: the
# SSL x in-situ SL interaction carries 28 % (standing) / 16 % (flexion) of the variance and needs its cubic
# terms, the SSL x K x in-situ SL term another 3 %) and sparse least squares (orthogonal matching pursuit with
# LOO selection; flexion width 0.17). Inputs stay uniform on the paper's ranges (a log-K input would change the
# question: indices for a log-uniform K). Cost: 2 x 256 solves; measured 1.9 s (standing) and 4.6 s (flexion)
# per solve with the SQP + IPOPT certifier on 2026-11-23; 0.38 s and 1.03 s on 2026-11-24 after the
# speed work (batches of 64, full step first, IPOPT polish from the primal point; benchmarks/bench_muscle_model.py,
# which estimates the whole default study at 282 s on 2 cores, target 300 s). The indices were measured with
#   python -c "import pandas as pd; from lumbar.muscles import muscle_model as mm, muscle_sensitivity as ms; \
#   m = mm.LumbarMuscleModel(); s = mm.make_solver(m, {'certifier': 'sqp'}); b = dict(zip(mm.POSTURES, \
#   mm.solve_postures(m, s, list(mm.POSTURES.values())))); X = ms.sobol_samples(256, 20261123); \
#   d = pd.concat([ms.sobol_evaluate(m, s, b, X, range(256), p) for p in b]); [print(n, g, \
#   ms.sobol_indices(d[d['sample'] < n], n, g, 20261123)) for n in (64, 128, 256) for g in (2, 3, 4)]"


def sobol_bounds() -> np.ndarray:
    """(lower, upper) of the five parameters (rows in ``PARAMETERS`` order, each in the units of its name)."""
    return np.array([SOBOL_BOUNDS[p] for p in PARAMETERS], float)


def sobol_samples(n_train: int, seed: int) -> np.ndarray:
    """Training design of the Sobol study: ``n_train`` scrambled Sobol QMC points (scipy.stats.qmc.Sobol,
    seeded; ``n_train`` a power of two) uniform on ``SOBOL_BOUNDS``; columns ``PARAMETERS`` in their units."""
    b = sobol_bounds()
    return b[:, 0] + pce.qmc_points(n_train, len(PARAMETERS), seed) * (b[:, 1] - b[:, 0])


def sobol_chunk_rows(n_samples: int, n_chunks: int, chunk: int) -> np.ndarray:
    """Row indices of Sobol sample chunk ``chunk`` (0-based) of ``n_chunks`` (contiguous, sizes within one)."""
    if not (0 <= chunk < n_chunks):
        raise ValueError(f"sobol chunk must be in [0, {n_chunks}), got {chunk}")
    return np.array_split(np.arange(n_samples), n_chunks)[chunk]


def sobol_evaluate(model, solver, baseline: dict, X: np.ndarray, rows, posture: str, scope="ALL", area_m2=18e-4,
                   batch_size=None, label="sobol") -> pd.DataFrame:
    """Solve the Sobol samples ``X[rows]`` in ``posture`` (parameters applied to ``scope``, warm-started from
    the baseline), one table row per sample: L4-L5 IDP, reached, certified, KKT residual."""
    if posture not in POSTURES:
        raise ValueError(f"unknown posture {posture!r}; expected one of {sorted(POSTURES)}")
    rows = np.asarray(rows, int)
    props = []
    for x in X[rows]:
        pr = model.props
        for name, v in zip(PARAMETERS, x):
            pr = apply_parameter(pr, model.ms, name, float(v), scope)
        props.append(pr)
    sols = solve_with_progress(model, solver, [POSTURES[posture]] * len(rows), props,
                               [baseline[posture]] * len(rows), batch_size, label)
    seg = [model.segment_loads(s.x[None], s.R[None]).query("level == 'L4-L5'").iloc[0] for s in sols]
    y = idp_parts([s["compressive_n"] for s in seg], [s["moment_nm"] for s in seg], area_m2)[0]
    out = pd.DataFrame({"posture": posture, "sample": rows, "scope": scope})
    for k, name in enumerate(PARAMETERS):
        out[name] = X[rows, k]
    out["idp_mpa"] = np.asarray(y, float)
    out["converged"] = [s.converged for s in sols]
    for key in ("reached", "certified", "kkt_residual"):
        out[key] = [certificate(s)[key] for s in sols]
    out["ipopt_status"] = [s.ipopt_status for s in sols]      # why a reached sample is not certified
    return out


def sobol_indices(samples: pd.DataFrame, n_train: int, degree: int, seed: int, n_bootstrap: int = 500) -> pd.DataFrame:
    """First-order (S1) and total (ST) Sobol indices of L4-L5 IDP per posture from a Legendre polynomial chaos
    expansion of total degree ``degree`` fitted by least squares on the certified samples (of the ``n_train`` rows of
    each posture, :func:`sobol_evaluate`: reached, and IPOPT certified the optimum); indices analytic from the
    coefficients (:mod:`lumbar.muscles.pce`).

    Columns: ``S1``, ``ST`` (point estimates from the fit to all reached samples); ``S1_lo``/``S1_hi``,
    ``ST_lo``/``ST_hi`` (bootstrap 95 % percentile interval, ``n_bootstrap`` resamples of the reached samples,
    each refitted); ``q2_loo`` (leave-one-out Q2 of the PCE, hat matrix) and ``fit_ok`` (Q2 >= ``SOBOL_Q2_MIN``);
    ``top_parameter`` (largest S1), ``top_s1_width`` (its S1_hi - S1_lo) and ``stable`` (that width <
    ``SOBOL_STABLE_WIDTH``); ``degree`` (the one fitted: lowered if the reached samples do not exceed the
    number of terms), ``n_terms``, ``n_train``, ``n_fit`` (certified samples), ``n_failed`` (samples whose posture
    is not reached: left out, so the indices are those of the reached part of the parameter box),
    ``n_uncertified`` (reached, optimum not certified: left out too, counted), ``kkt_residual_max`` (of the fit),
    ``idp_mean_mpa`` and ``idp_sd_mpa`` (mean and standard deviation of the PCE)."""

    n = int(n_train)
    rows = []
    order = [q for q in POSTURES if q in set(samples["posture"])]       # standing before flexion
    order += [q for q in dict.fromkeys(samples["posture"]) if q not in order]
    for posture in order:
        d = samples[samples["posture"] == posture].sort_values("sample")
        if list(d["sample"]) != list(range(n)):
            raise ValueError(f"Sobol samples of {posture}: expected rows 0..{n - 1} (n_train {n}), got {len(d)} rows")
        reached = d["reached"].to_numpy(bool)
        ok = reached & d["certified"].to_numpy(bool)        # certified optima only
        U = pce.to_unit(d.loc[ok, list(PARAMETERS)].to_numpy(float), sobol_bounds())
        y = d.loc[ok, "idp_mpa"].to_numpy(float)
        deg = int(degree)
        while deg > 0 and comb(len(PARAMETERS) + deg, deg) >= len(y):
            deg -= 1
        if deg < int(degree):
            log.warning("Sobol %s: %d reached samples do not exceed the %d terms of degree %d: degree %d fitted",
                        posture, len(y), comb(len(PARAMETERS) + int(degree), int(degree)), int(degree), deg)
        nan = np.full(len(PARAMETERS), np.nan)
        if deg > 0:
            r = pce.sobol_analysis(U, y, deg, n_bootstrap, seed)
            f = r["fit"]
            q2, mean, sd = f.q2_loo, f.mean, np.sqrt(f.variance)
        else:
            r = {k: nan for k in ("S1", "S1_lo", "S1_hi", "ST", "ST_lo", "ST_hi")}
            q2, mean, sd = np.nan, float(np.mean(y)) if len(y) else np.nan, np.nan
        top = int(np.nanargmax(r["S1"])) if np.isfinite(r["S1"]).any() else None
        width = float(r["S1_hi"][top] - r["S1_lo"][top]) if top is not None else np.nan
        fit_ok = bool(np.isfinite(q2) and q2 >= SOBOL_Q2_MIN)
        if not fit_ok:
            log.warning("Sobol %s: PCE degree %d leave-one-out Q2 = %.3f < %.2f: the indices are not reliable",
                        posture, deg, q2, SOBOL_Q2_MIN)
        kkt = d.loc[ok, "kkt_residual"]
        for k, name in enumerate(PARAMETERS):
            rows.append({"posture": posture, "parameter": name, "S1": r["S1"][k], "S1_lo": r["S1_lo"][k],
                         "S1_hi": r["S1_hi"][k], "ST": r["ST"][k], "ST_lo": r["ST_lo"][k], "ST_hi": r["ST_hi"][k],
                         "q2_loo": q2, "fit_ok": fit_ok,
                         "top_parameter": PARAMETERS[top] if top is not None else "",
                         "top_s1_width": width, "stable": bool(np.isfinite(width) and width < SOBOL_STABLE_WIDTH),
                         "degree": deg, "n_terms": comb(len(PARAMETERS) + deg, deg), "n_train": n,
                         "n_fit": int(ok.sum()), "n_bootstrap": int(n_bootstrap), "n_failed": int((~reached).sum()),
                         "n_uncertified": int((reached & ~ok).sum()),
                         "kkt_residual_max": float(kkt.max()) if len(kkt) else np.nan,
                         "idp_mean_mpa": mean, "idp_sd_mpa": sd, "scope": d["scope"].iloc[0]})
    return pd.DataFrame(rows)


def sobol_study(model, solver, baseline: dict, n_train: int, seed: int, degree: int = 3, n_bootstrap: int = 500,
                scope="ALL", postures=("standing", "flexion"), area_m2=18e-4):
    """Variance-based (Sobol) indices of L4-L5 IDP to the five parameters (uniform on the paper's ranges,
    applied to ``scope``) from a polynomial chaos surrogate, per posture, in one process (the workflow runs the
    samples in chunks: :func:`sobol_samples`, :func:`sobol_evaluate`, :func:`sobol_indices`)."""
    X = sobol_samples(n_train, seed)
    samples = pd.concat([sobol_evaluate(model, solver, baseline, X, np.arange(len(X)), p, scope, area_m2)
                         for p in postures], ignore_index=True)
    return sobol_indices(samples, n_train, degree, seed, n_bootstrap)
