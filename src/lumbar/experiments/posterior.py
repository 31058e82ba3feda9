"""The calibration's posterior: a Laplace approximation at the MAP estimate, and prediction bands by linearisation.

The admissible fit (:func:`lumbar.experiments.calibration.fit_admissible`) minimises one stacked residual vector r(q)
over the fit parameters q (fit units: log10 force scales, pre-elongation changes in mm, log10 stiffnesses):

    r = [ (ROM_sim - ROM_measured) / data spread,          the data
          steep one-sided terms beyond the acceptance band,  constraints (soft)
          admissibility penalties (one-sided, soft),          constraints (soft)
          (q - prior centre) / prior spread ]                 the prior

Its minimum is a MAP estimate under a Gaussian likelihood and prior, with the constraints as soft penalties.
The Laplace approximation takes the Gauss-Newton Hessian of the same objective at the optimum, H = J^T J, and the
posterior covariance C = H^-1 (fit units): the posterior the fit actually uses, penalties included. A prediction
y(q) (a rotation, a facet force, an IDP) with gradient g = dy/dq has the linearised spread sqrt(g^T C g) and the 90 %
band y +- 1.645 sqrt(g^T C g) (:meth:`Posterior.band`): one extra Jacobian per prediction set, not hundreds of
forward runs. Where the linearisation is in doubt, :meth:`Posterior.draws` gives parameter samples to run forward.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

#: two-sided 90 % interval of a normal distribution: +- Z90 standard deviations
Z90 = 1.6448536269514722
#: a parameter whose MAP lies within this many prior spreads of its prior centre, and whose posterior spread is at
#: least this fraction of its prior spread, is "at its prior": the data did not move it
STAYED_SHIFT_SD = 0.25
STAYED_SPREAD_RATIO = 0.9
#: a parameter within this fraction of its bound range from a bound is flagged at_bound
AT_BOUND_FRACTION = 0.01


@dataclass
class Posterior:
    """Laplace posterior of a MAP fit in fit units (see the module docstring)."""

    names: list
    map_q: np.ndarray
    prior_centre: np.ndarray
    prior_sd: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    cov: np.ndarray
    jacobian: np.ndarray
    residual: np.ndarray
    residual_names: list
    n_data: int

    @property
    def sd(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    @property
    def at_bound(self) -> np.ndarray:
        w = self.upper - self.lower
        return (self.map_q - self.lower <= AT_BOUND_FRACTION * w) | (self.upper - self.map_q <= AT_BOUND_FRACTION * w)

    def band(self, gradient) -> np.ndarray:
        """Linearised standard deviation of predictions with ``gradient`` (m, p) = dy/dq in fit units."""
        G = np.atleast_2d(np.asarray(gradient, float))
        return np.sqrt(np.clip(np.einsum("ij,jk,ik->i", G, self.cov, G), 0.0, None))

    def draws(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` parameter vectors (n, p) from the Laplace posterior, clipped to the bounds (seeded)."""
        rng = np.random.default_rng(seed)
        L = np.linalg.cholesky(self.cov + 1e-15 * np.eye(len(self.map_q)))
        q = self.map_q + rng.standard_normal((n, len(self.map_q))) @ L.T
        return np.clip(q, self.lower, self.upper)

    def moved_by(self, j: int, top: int = 2) -> list[str]:
        """The residual rows (data or constraints, never the prior) that pull parameter ``j`` away from its prior
        centre at the optimum, strongest first: the rows whose descent direction -J_ij r_i points the way the
        parameter moved. At an interior optimum their pulls add up to the prior's restoring pull."""
        shift = self.map_q[j] - self.prior_centre[j]
        if abs(shift) < 1e-12:
            return []
        pull = -self.jacobian[:, j] * self.residual * np.sign(shift)
        rows = [(p, nm) for p, nm in zip(pull, self.residual_names) if not nm.startswith("prior ") and p > 0]
        rows.sort(key=lambda t: -t[0])
        total = sum(p for p, _ in rows)
        return [f"{nm} ({p / total:.0%})" for p, nm in rows[:top]] if total > 0 else []

    def stayed_at_prior(self) -> np.ndarray:
        shift = np.abs(self.map_q - self.prior_centre) / self.prior_sd
        return (shift < STAYED_SHIFT_SD) & (self.sd / self.prior_sd >= STAYED_SPREAD_RATIO)


def laplace_posterior(names, q, prior_centre, prior_sd, lower, upper, jacobian, residual, residual_names,
                      n_data: int) -> Posterior:
    """:class:`Posterior` from the stacked residual vector of a MAP fit and its Jacobian at the optimum (fit units).
    The Gauss-Newton Hessian J^T J includes the prior rows, so it is positive definite; a pseudo-inverse guards
    against round-off."""
    J = np.asarray(jacobian, float)
    r = np.asarray(residual, float)
    if J.shape != (len(r), len(names)):
        raise ValueError(f"laplace_posterior: Jacobian shape {J.shape}, expected ({len(r)}, {len(names)})")
    if len(residual_names) != len(r):
        raise ValueError(f"laplace_posterior: {len(residual_names)} residual names for {len(r)} residuals")
    H = J.T @ J
    cov = np.linalg.pinv(H, hermitian=True)
    return Posterior(list(names), np.asarray(q, float), np.asarray(prior_centre, float), np.asarray(prior_sd, float),
                     np.asarray(lower, float), np.asarray(upper, float), cov, J, r, list(residual_names), int(n_data))


def natural_units(name, v):
    """Fit units -> natural units and unit of a parameter."""
    v = np.asarray(v, float)
    if name.endswith(":pre_elongation"):
        return v, "mm (change)"
    if name.endswith(":scale") or name.startswith("disc_torque:"):
        return 10.0 ** v, "scale (-)"
    return 10.0 ** v, "N/m"


def posterior_table(post: Posterior, sources=None, bound_reasons=None) -> pd.DataFrame:
    """One row per parameter: prior centre and spread (fit units) with its 90 % interval in natural units, the MAP,
    the posterior 90 % interval, posterior/prior spread ratio, shift in prior spreads, which rows moved it, whether
    the data moved it at all, the at-bound flag and its reason."""
    sd = post.sd
    rows = []
    stayed = post.stayed_at_prior()
    atb = post.at_bound
    for j, n in enumerate(post.names):
        c, s, m = post.prior_centre[j], post.prior_sd[j], post.map_q[j]
        lo_p, hi_p = max(c - Z90 * s, post.lower[j]), min(c + Z90 * s, post.upper[j])
        lo_q, hi_q = max(m - Z90 * sd[j], post.lower[j]), min(m + Z90 * sd[j], post.upper[j])
        val, unit = natural_units(n, [c, lo_p, hi_p, m, lo_q, hi_q])
        rows.append({
            "parameter": n, "unit": unit, "fit_unit": "mm" if n.endswith(":pre_elongation") else "log10",
            "prior_centre": val[0], "prior_90_low": val[1], "prior_90_high": val[2],
            "prior_centre_fit": c, "prior_spread_fit": s,
            "map": val[3], "posterior_90_low": val[4], "posterior_90_high": val[5],
            "map_fit": m, "posterior_spread_fit": sd[j],
            "spread_ratio": sd[j] / s, "shift_prior_sd": (m - c) / s,
            "moved_by": "; ".join(post.moved_by(j)) if not stayed[j] else "",
            "data_moved_it": not bool(stayed[j]),
            "at_bound": bool(atb[j]),
            "bound_reason": (bound_reasons or {}).get(n, "") if atb[j] else "",
            "prior_source": (sources or {}).get(n, ""),
        })
    return pd.DataFrame(rows)


def covariance_table(post: Posterior) -> pd.DataFrame:
    """The posterior covariance in fit units as a long table (parameter_i, parameter_j, covariance)."""
    p = len(post.names)
    return pd.DataFrame([{"parameter_i": post.names[i], "parameter_j": post.names[j], "covariance": post.cov[i, j]}
                         for i in range(p) for j in range(p)])


def read_covariance(table: pd.DataFrame) -> tuple[list, np.ndarray]:
    """(names, covariance (p, p)) from :func:`covariance_table`'s table."""
    names = list(dict.fromkeys(table["parameter_i"]))
    idx = {n: i for i, n in enumerate(names)}
    C = np.zeros((len(names), len(names)))
    for a, b, v in zip(table["parameter_i"], table["parameter_j"], table["covariance"]):
        C[idx[a], idx[b]] = float(v)
    return names, C


#: finite-difference step of a prediction's gradient (fit units: a decade of scale, a mm of pre-elongation)
BAND_STEP = 0.01


def read_posterior(posterior_csv, covariance_csv) -> tuple[list, np.ndarray] | None:
    """(parameter names, covariance (p, p), fit units) of a calibration's posterior files; None when the calibration
    has no posterior (empty tables, e.g. a strain-transfer calibration)."""
    post, cov = pd.read_csv(posterior_csv), pd.read_csv(covariance_csv)
    if post.empty or cov.empty:
        return None
    names, C = read_covariance(cov)
    if list(post["parameter"]) != names:
        raise ValueError(f"{posterior_csv} and {covariance_csv} name different parameters")
    return names, C


def linearised_band(predict, charset, names, cov, shift, step: float = BAND_STEP):
    """(y (m,), standard deviation (m,), gradient (m, p)) of the predictions ``predict(charset) -> (m,)`` under the
    posterior covariance ``cov`` of the fit parameters ``names``: forward differences of one step per parameter
    (``shift(charset, name, delta)`` moves one parameter in fit units), var = g C g^T. A prediction that is not
    finite at the MAP or at a step keeps a NaN spread."""
    y0 = np.asarray(predict(charset), float)
    G = np.empty((len(y0), len(names)))
    for j, n in enumerate(names):
        G[:, j] = (np.asarray(predict(shift(charset, n, step)), float) - y0) / step
    sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", G, cov, G), 0.0, None))
    return y0, np.where(np.isfinite(sd), sd, np.nan), G


#: where draws run forward, a linearised band whose ends lie further than this fraction of its width from the draws'
#: 5th and 95th percentiles fails the comparison and takes the draws' band
BAND_AGREEMENT = 0.25
#: a row takes the draws' band only if at least this fraction of the draws gave it a (converged) value
BAND_MIN_VALID = 0.5
#: band_method values: how a row's 90 % band was made
METHOD_LINEAR = "linearised"
METHOD_BOUND = "draws: linear band crosses the physical bound"
METHOD_NONLINEAR = "draws: linear band off the draws' band"
METHOD_CLIPPED = "linearised, clipped at the physical bound (no usable draws)"


@dataclass
class Band:
    """Checked 90 % bands of m predictions (:func:`checked_band`)."""

    y: np.ndarray           # (m,) prediction at the MAP
    sd: np.ndarray          # (m,) linearised standard deviation
    low90: np.ndarray       # (m,) lower end of the 90 % band used
    high90: np.ndarray      # (m,) upper end
    method: np.ndarray      # (m,) how the band was made (METHOD_*)
    n_draws: int            # posterior draws run forward (0: the linearisation passed its check everywhere)
    n_draws_failed: int     # draws whose forward run raised (their rows count as not converged)
    draw_values: np.ndarray | None = None   # (n_draws, m) the draws' predictions (NaN: not converged), if run

    def summary(self) -> str:
        """One log line: rows per method and the draws run."""
        vals, counts = np.unique(self.method.astype(str), return_counts=True)
        rows = "; ".join(f"{c} {v}" for v, c in zip(vals, counts))
        draws = (f"{self.n_draws} posterior draws run forward ({self.n_draws_failed} failed)" if self.n_draws
                 else "no draws run")
        return f"{rows}; {draws}"


def checked_band(predict, charset, names, cov, shift, lower=None, predict_draw=None, offsets=None) -> Band:
    """90 % bands of the predictions ``predict(charset) -> (m,)`` by linearisation (:func:`linearised_band`),
    checked, and from posterior draws where the check shows that the linearisation fails.

    The check: a prediction with a physical lower bound (``lower`` (m,) or scalar, NaN for none: a tension, a
    contact force, a range of motion) whose linear band reaches below it is not a linear function of the parameters
    there. If any row fails, the posterior draws ``offsets`` (n, p: draw minus MAP in fit units, the calibration's
    MCMC sample, :func:`sample_posterior`) are run forward (``predict_draw``, default ``predict``: NaN for a row
    whose equilibrium did not converge), and
    - the rows that failed take the draws' 5th-95th percentile band;
    - every other row is compared with the draws too: if an end of its linear band lies more than
      :data:`BAND_AGREEMENT` of the band's width from the draws', it takes the draws' band as well.
    A failing row without draws, or with fewer than :data:`BAND_MIN_VALID` valid ones, keeps its linear band clipped
    at the bound and says so. Without a failing row no draw is run."""
    y, sd, _ = linearised_band(predict, charset, names, cov, shift)
    low, high = y - Z90 * sd, y + Z90 * sd
    m = len(y)
    lo_b = np.broadcast_to(np.asarray(np.nan if lower is None else lower, float), (m,))
    tol = 1e-9 * (1.0 + np.abs(y))
    below = np.isfinite(lo_b) & np.isfinite(low) & (low < lo_b - tol)
    method = np.full(m, METHOD_LINEAR, dtype=object)
    low, high = low.copy(), high.copy()
    D = np.empty((0, len(names))) if offsets is None else np.atleast_2d(np.asarray(offsets, float))
    if not below.any() or not len(D):
        low[below] = lo_b[below]
        method[below] = METHOD_CLIPPED
        return Band(y, sd, low, high, method, 0, 0)
    if D.shape[1] != len(names):
        raise ValueError(f"checked_band: draws of {D.shape[1]} parameters for {len(names)} names")
    run = predict_draw or predict
    Y = np.full((len(D), m), np.nan)
    failed = 0
    for i, d in enumerate(D):
        cs = charset
        for n, dj in zip(names, d):
            cs = shift(cs, n, float(dj))
        try:
            Y[i] = np.asarray(run(cs), float)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            failed += 1
    valid = np.isfinite(Y).sum(axis=0) >= BAND_MIN_VALID * len(D)
    q05 = np.full(m, np.nan)
    q95 = np.full(m, np.nan)
    if valid.any():
        q05[valid], q95[valid] = np.nanpercentile(Y[:, valid], [5.0, 95.0], axis=0)
    off = np.maximum(np.abs(q05 - low), np.abs(q95 - high))
    nonlinear = valid & ~below & np.isfinite(off) & (off > BAND_AGREEMENT * (high - low) + tol)
    take = valid & (below | nonlinear)
    low[take], high[take] = q05[take], q95[take]
    method[below & valid] = METHOD_BOUND
    method[nonlinear] = METHOD_NONLINEAR
    clip = below & ~valid
    low[clip] = lo_b[clip]
    method[clip] = METHOD_CLIPPED
    return Band(y, sd, low, high, method, len(D), failed, Y)


# ------------------------------------------------------------------ posterior draws: a short MCMC on the objective
#: the sampler's defaults (config stepwise_reduction.posterior_draws): walkers, steps, burn-in steps, draws kept, seed,
#: and the start: walkers drawn from the Laplace posterior shrunk by this factor about the MAP (the Laplace spread
#: ignores the one-sided constraints inactive at the MAP and is several times too wide in some directions)
DRAW_DEFAULTS = {"walkers": 40, "steps": 250, "burn_in": 100, "keep": 64, "seed": 0, "start_scale": 0.4}
#: columns of the sampling table (role calibration.sampling)
SAMPLING_COLUMNS = ("parameter", "map_fit", "laplace_sd_fit", "sampled_sd_fit", "sd_ratio_sampled_over_laplace",
                    "sampled_5_fit", "sampled_95_fit", "walkers", "steps", "burn_in", "kept", "acceptance",
                    "autocorrelation_steps", "independent_samples")


@dataclass
class PosteriorSample:
    """Draws from the calibration's posterior (:func:`sample_posterior`), fit units."""

    names: list
    map_q: np.ndarray
    draws: np.ndarray           # (keep, p) parameter vectors
    chain_sd: np.ndarray        # (p,) spread of the whole chain after burn-in
    chain_q05: np.ndarray
    chain_q95: np.ndarray
    walkers: int
    steps: int
    burn_in: int
    acceptance: float
    autocorrelation_steps: float   # mean integrated autocorrelation time of the chain [steps]

    @property
    def independent_samples(self) -> float:
        return self.walkers * (self.steps - self.burn_in) / max(self.autocorrelation_steps, 1.0)

    @property
    def offsets(self) -> np.ndarray:
        return self.draws - self.map_q


def check_draw_settings(settings: dict, n_parameters: int, where: str = "stepwise_reduction.posterior_draws") -> dict:
    """The sampler's settings (:data:`DRAW_DEFAULTS` completed by ``settings``), checked before any computation: a
    ValueError naming the config key and the expected form for a burn-in not below the steps, fewer walkers than
    twice the ``n_parameters`` (emcee's ensemble needs them), or no draw kept."""
    unknown = sorted(set(settings) - set(DRAW_DEFAULTS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; expected some of {sorted(DRAW_DEFAULTS)}")
    s = {**DRAW_DEFAULTS, **settings}
    if not 0 <= int(s["burn_in"]) < int(s["steps"]):
        raise ValueError(f"{where}.burn_in: {s['burn_in']} with steps {s['steps']}; expected 0 <= burn_in < steps")
    if int(s["walkers"]) < 2 * n_parameters:
        raise ValueError(f"{where}.walkers: {s['walkers']}; expected at least twice the {n_parameters} calibrated "
                         f"parameters ({2 * n_parameters})")
    if int(s["keep"]) < 1:
        raise ValueError(f"{where}.keep: {s['keep']}; expected at least 1 draw (50 or more for a 90 % band)")
    return s


def sample_posterior(residual, post: Posterior, walkers: int = 40, steps: int = 250, burn_in: int = 100,
                     keep: int = 64, seed: int = 0, start_scale: float = 0.4) -> PosteriorSample:
    """Draws from the posterior the MAP fit uses, log p(q) = -r(q).r(q)/2 inside the fit's bounds (``residual``: q ->
    the stacked residuals, :attr:`lumbar.experiments.calibration.AdmissibleFit.objective`), by emcee's affine-invariant
    ensemble sampler (Foreman-Mackey et al. 2013): ``walkers`` started about the MAP (Laplace draws shrunk by
    ``start_scale``, inside the bounds), ``steps`` steps, the first ``burn_in`` discarded; ``keep`` draws taken evenly
    from the rest. Seeded. A residual that raises (a law outside its validity) or is not finite counts as outside the
    posterior."""
    import emcee  # noqa: PLC0415 - only this function needs it

    if not (0 <= burn_in < steps) or keep < 1 or walkers < 2 * len(post.names):
        raise ValueError(f"sample_posterior: need 0 <= burn_in ({burn_in}) < steps ({steps}), keep >= 1 ({keep}) and "
                         f"walkers >= 2 x parameters ({walkers} for {len(post.names)})")

    def log_prob(q):
        if np.any(q < post.lower) or np.any(q > post.upper):
            return -np.inf
        try:
            r = np.asarray(residual(q), float)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            return -np.inf
        return -0.5 * float(r @ r) if np.all(np.isfinite(r)) else -np.inf

    rng = np.random.default_rng(seed)
    w, V = np.linalg.eigh(0.5 * (post.cov + post.cov.T))
    root = V * np.sqrt(np.clip(w, 0.0, None))
    start = []
    for _ in range(200 * walkers):
        q = post.map_q + start_scale * (rng.standard_normal(len(w)) @ root.T)
        if np.isfinite(log_prob(q)):
            start.append(q)
            if len(start) == walkers:
                break
    if len(start) < walkers:
        raise RuntimeError(f"sample_posterior: only {len(start)} of {walkers} start points inside the posterior's "
                           f"support after {200 * walkers} tries (start_scale {start_scale})")
    sampler = emcee.EnsembleSampler(walkers, len(w), log_prob)
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(np.array(start), steps, progress=False)
    chain = sampler.get_chain(discard=burn_in)            # (steps - burn_in, walkers, p)
    flat = chain.reshape(-1, len(w))
    # tol=0: the length check of emcee is replaced by the independent-sample count this stage reports
    tau = float(np.mean(emcee.autocorr.integrated_time(chain, tol=0, quiet=True)))
    idx = np.linspace(0, len(flat) - 1, keep).round().astype(int)
    q05, q95 = np.percentile(flat, [5.0, 95.0], axis=0)
    return PosteriorSample(list(post.names), post.map_q.copy(), flat[idx], flat.std(axis=0), q05, q95, walkers, steps,
                           burn_in, float(np.mean(sampler.acceptance_fraction)), tau)


def sampling_table(post: Posterior, sample: PosteriorSample) -> pd.DataFrame:
    """Per parameter: the MAP, the Laplace and the sampled spread (fit units) and their ratio, the sampled 90 %
    interval, and the chain's settings and diagnostics (role calibration.sampling)."""
    return pd.DataFrame({
        "parameter": sample.names, "map_fit": sample.map_q, "laplace_sd_fit": post.sd, "sampled_sd_fit": sample.chain_sd,
        "sd_ratio_sampled_over_laplace": sample.chain_sd / np.where(post.sd > 0, post.sd, np.nan),
        "sampled_5_fit": sample.chain_q05, "sampled_95_fit": sample.chain_q95, "walkers": sample.walkers,
        "steps": sample.steps, "burn_in": sample.burn_in, "kept": len(sample.draws), "acceptance": sample.acceptance,
        "autocorrelation_steps": sample.autocorrelation_steps, "independent_samples": sample.independent_samples,
    })[list(SAMPLING_COLUMNS)]


def draws_table(sample: PosteriorSample) -> pd.DataFrame:
    """The kept draws (role calibration.draws): one row per draw, one column per parameter (fit units)."""
    t = pd.DataFrame(sample.draws, columns=sample.names)
    t.insert(0, "draw", np.arange(len(t)))
    return t


def read_draw_offsets(posterior_csv, draws_csv, names) -> np.ndarray | None:
    """Draws minus the MAP (n, p) in the order of ``names`` (fit units), from the calibration's posterior and draws
    tables; None when there are no draws (no posterior, or an empty table)."""
    post, d = pd.read_csv(posterior_csv), pd.read_csv(draws_csv)
    if post.empty or d.empty:
        return None
    missing = [n for n in names if n not in d.columns]
    if missing:
        raise ValueError(f"{draws_csv}: no column for the parameters {missing} of {posterior_csv}; rerun rule "
                         "calibration_draws")
    m = post.set_index("parameter")["map_fit"]
    return d[list(names)].to_numpy(float) - m.reindex(list(names)).to_numpy(float)


#: quantities of the intact moment-rotation curves that get a posterior band (columns of the curve tables; plus the
#: larger facet force and, for lateral bending and axial rotation, the mean of the two sides)
BAND_QUANTITIES = ("rotation_deg", "facet_left_contact_n", "facet_right_contact_n", "disc_axial_force_n",
                   "ALL_tension_n", "PLL_tension_n", "FL_tension_n", "CL_tension_n", "ISL_tension_n",
                   "SSL_tension_n", "ITL_tension_n", "facet_left_beyond_surface_n", "facet_right_beyond_surface_n")
BAND_COLUMNS = ("direction", "moment_nm", "quantity", "map", "sd", "low90", "high90", "converged", "band_method")
#: quantities that cannot be negative: the disc carries no traction, contact pushes, ligaments pull
NON_NEGATIVE_QUANTITIES = frozenset(q for q in BAND_QUANTITIES if q != "rotation_deg") | {"facet_max_contact_n"}
#: result-table values that cannot be negative: a range of motion in the direction of its moment, a pressure of a
#: disc without traction (:func:`table_bands`)
NON_NEGATIVE_TABLE_VALUES = frozenset({"rom_deg", "idp_mpa"})


def _curve_vector(curves: pd.DataFrame, directions, moments):
    """Prediction vector of :func:`curve_bands` from a curve table: one value per (direction, moment, quantity),
    derived quantities included (facet_max_contact_n; the two-side means lateral_bending / axial_rotation of the
    rotation)."""
    c = curves.set_index(["direction", "moment_nm"])
    out, keys, conv = [], [], []
    for d in directions:
        for M in moments:
            r = c.loc[(d, M)]
            for q in BAND_QUANTITIES:
                out.append(float(r[q]) if q in r.index else np.nan)
                keys.append((d, M, q))
                conv.append(bool(r["converged"]))
            out.append(max(float(r["facet_left_contact_n"]), float(r["facet_right_contact_n"])))
            keys.append((d, M, "facet_max_contact_n"))
            conv.append(bool(r["converged"]))
    for pair, (a, b) in (("lateral_bending", ("lateral_bending_right", "lateral_bending_left")),
                         ("axial_rotation", ("axial_rotation_left", "axial_rotation_right"))):
        if a in directions and b in directions:
            for M in moments:
                out.append(0.5 * (float(c.loc[(a, M)]["rotation_deg"]) + float(c.loc[(b, M)]["rotation_deg"])))
                keys.append((pair, M, "rotation_deg"))
                conv.append(bool(c.loc[(a, M)]["converged"]) and bool(c.loc[(b, M)]["converged"]))
    return np.array(out), keys, np.array(conv)


def curve_bands(build, charset, names, cov, shift, curves_of, directions, moments,
                offsets=None) -> tuple[pd.DataFrame, Band]:
    """90 % posterior bands of the intact moment-rotation curves and their internal loads: linearised, checked, and
    from posterior draws where the check fails (:func:`checked_band`; the forces of :data:`NON_NEGATIVE_QUANTITIES`
    cannot be negative).

    ``build(charset)`` -> unit; ``curves_of(unit)`` -> its intact curve table (``moment_rotation_curves``);
    ``shift(charset, name, delta)`` moves one fit parameter (:func:`lumbar.experiments.calibration.shift_parameter`);
    ``offsets``: the calibration's posterior draws minus its MAP (:func:`read_draw_offsets`).
    One table row per (direction, moment, quantity): the MAP value, the linearised standard deviation, the 90 %
    band (:data:`Z90`), whether the MAP step converged and how the band was made (``band_method``); and the
    :class:`Band` (its log line)."""
    keys, conv = [], []

    def predict(cs, draw=False):
        y, k, c = _curve_vector(curves_of(build(cs)), directions, moments)
        if not keys:
            keys.extend(k)
            conv.extend(c)
        return np.where(c, y, np.nan) if draw else y

    y0 = predict(charset)
    lower = np.array([0.0 if k[2] in NON_NEGATIVE_QUANTITIES else np.nan for k in keys])
    b = checked_band(lambda cs: y0 if cs is charset else predict(cs), charset, names, cov, shift, lower=lower,
                     predict_draw=lambda cs: predict(cs, draw=True), offsets=offsets)
    t = pd.DataFrame({"direction": [k[0] for k in keys], "moment_nm": [k[1] for k in keys],
                      "quantity": [k[2] for k in keys], "map": b.y, "sd": b.sd, "low90": b.low90,
                      "high90": b.high90, "converged": conv, "band_method": b.method})
    return t[list(BAND_COLUMNS)], b


#: columns of the draws' values of the band rows (role load_sharing.band_draws)
DRAW_VALUE_COLUMNS = ("direction", "moment_nm", "quantity", "draw", "value")
#: moments [N*m] whose draws' values are kept: the internal loads judged at 7.5 N*m, the ROM at 10 N*m
DRAW_VALUE_MOMENTS = (7.5, 10.0)


def curve_draws_table(bands: pd.DataFrame, band: Band, moments=DRAW_VALUE_MOMENTS) -> pd.DataFrame:
    """The posterior draws' values of the rows of a curve band table (:func:`curve_bands`) at ``moments``: one row
    per (direction, moment, quantity, draw); empty where no draw was run. A judged quantity's posterior probability
    of lying in its acceptance interval is read from these (:func:`lumbar.experiments.validation.scoreboard`)."""
    if band is None or band.draw_values is None:
        return pd.DataFrame(columns=list(DRAW_VALUE_COLUMNS))
    keep = np.flatnonzero(np.isin(np.round(bands["moment_nm"].to_numpy(float), 6), np.round(moments, 6)))
    n = band.draw_values.shape[0]
    sub = bands.iloc[keep]
    return pd.DataFrame({"direction": np.repeat(sub["direction"].to_numpy(), n),
                         "moment_nm": np.repeat(sub["moment_nm"].to_numpy(float), n),
                         "quantity": np.repeat(sub["quantity"].to_numpy(), n),
                         "draw": np.tile(np.arange(n), len(keep)),
                         "value": band.draw_values[:, keep].T.reshape(-1)})[list(DRAW_VALUE_COLUMNS)]


def table_bands(table_of, value_col: str, key_cols, charset, names, cov, shift,
                offsets=None) -> tuple[pd.DataFrame, Band]:
    """90 % posterior band of every row of a result table ``table_of(charset) -> DataFrame`` (its rows in the same
    order for every set; e.g. the 160 stepwise-reduction scenarios of Table 4 or the 49 IDP scenarios of Table 5):
    linearised, checked, from posterior draws where the check fails (:func:`checked_band`; the values of
    :data:`NON_NEGATIVE_TABLE_VALUES` cannot be negative; a draw's row whose ``converged`` column is false counts
    as missing; ``offsets`` as in :func:`curve_bands`). ``key_cols`` of the table, then map, sd, low90, high90 of
    ``value_col`` and band_method; and the :class:`Band`."""
    keys = []

    def predict(cs, draw=False):
        t = table_of(cs)
        if not keys:
            keys.append(t[list(key_cols)].reset_index(drop=True))
        v = t[value_col].to_numpy(float)
        if draw and "converged" in t.columns:
            v = np.where(t["converged"].to_numpy(bool), v, np.nan)
        return v

    lower = 0.0 if value_col in NON_NEGATIVE_TABLE_VALUES else None
    b = checked_band(predict, charset, names, cov, shift, lower=lower,
                     predict_draw=lambda cs: predict(cs, draw=True), offsets=offsets)
    out = keys[0].copy()
    out["map"], out["sd"], out["low90"], out["high90"], out["band_method"] = b.y, b.sd, b.low90, b.high90, b.method
    return out, b


def table_bands_from_files(posterior_csv, covariance_csv, draws_csv, table_of, value_col: str, key_cols, charset,
                           shift) -> tuple[pd.DataFrame, Band | None]:
    """:func:`table_bands` with the calibration's posterior and draws read from its files; an empty table with the
    columns (and no :class:`Band`) when the calibration has no posterior (no admissible fit)."""
    post = read_posterior(posterior_csv, covariance_csv)
    if post is None:
        return pd.DataFrame(columns=list(key_cols) + ["map", "sd", "low90", "high90", "band_method"]), None
    offsets = read_draw_offsets(posterior_csv, draws_csv, post[0])
    return table_bands(table_of, value_col, key_cols, charset, post[0], post[1], shift, offsets=offsets)
