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


def _natural(name, v):
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
        val, unit = _natural(n, [c, lo_p, hi_p, m, lo_q, hi_q])
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


#: quantities of the intact moment-rotation curves that get a posterior band (columns of the curve tables; plus the
#: larger facet force and, for lateral bending and axial rotation, the mean of the two sides)
BAND_QUANTITIES = ("rotation_deg", "facet_left_contact_n", "facet_right_contact_n", "disc_axial_force_n",
                   "ALL_tension_n", "PLL_tension_n", "FL_tension_n", "CL_tension_n", "ISL_tension_n",
                   "SSL_tension_n", "ITL_tension_n", "facet_left_beyond_surface_n", "facet_right_beyond_surface_n")
BAND_COLUMNS = ("direction", "moment_nm", "quantity", "map", "sd", "low90", "high90", "converged")


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


def curve_bands(build, charset, names, cov, shift, curves_of, directions, moments) -> pd.DataFrame:
    """90 % posterior bands of the intact moment-rotation curves and their internal loads, by linearisation.

    ``build(charset)`` -> unit; ``curves_of(unit)`` -> its intact curve table (``moment_rotation_curves``);
    ``shift(charset, name, delta)`` moves one fit parameter (:func:`lumbar.experiments.calibration.shift_parameter`).
    One table row per (direction, moment, quantity): the MAP value, the linearised standard deviation and the 90 %
    band (:data:`Z90`), and whether the MAP step converged."""
    keys, conv = [], []

    def predict(cs):
        y, k, c = _curve_vector(curves_of(build(cs)), directions, moments)
        if not keys:
            keys.extend(k)
            conv.extend(c)
        return y

    y, sd, _ = linearised_band(predict, charset, names, cov, shift)
    return pd.DataFrame({"direction": [k[0] for k in keys], "moment_nm": [k[1] for k in keys],
                         "quantity": [k[2] for k in keys], "map": y, "sd": sd, "low90": y - Z90 * sd,
                         "high90": y + Z90 * sd, "converged": conv})[list(BAND_COLUMNS)]


def table_bands(table_of, value_col: str, key_cols, charset, names, cov, shift) -> pd.DataFrame:
    """90 % posterior band of every row of a result table ``table_of(charset) -> DataFrame`` (its rows in the same
    order for every set; e.g. the 160 stepwise-reduction scenarios of Table 4 or the 49 IDP scenarios of Table 5),
    by linearisation: ``key_cols`` of the table, then map, sd, low90, high90 of ``value_col``."""
    keys = []

    def predict(cs):
        t = table_of(cs)
        if not keys:
            keys.append(t[list(key_cols)].reset_index(drop=True))
        return t[value_col].to_numpy(float)

    y, sd, _ = linearised_band(predict, charset, names, cov, shift)
    out = keys[0].copy()
    out["map"], out["sd"], out["low90"], out["high90"] = y, sd, y - Z90 * sd, y + Z90 * sd
    return out


def table_bands_from_files(posterior_csv, covariance_csv, table_of, value_col: str, key_cols, charset,
                           shift) -> pd.DataFrame:
    """:func:`table_bands` with the calibration's posterior read from its files; an empty table with the columns
    when the calibration has no posterior (no admissible fit)."""
    post = read_posterior(posterior_csv, covariance_csv)
    if post is None:
        return pd.DataFrame(columns=list(key_cols) + ["map", "sd", "low90", "high90"])
    return table_bands(table_of, value_col, key_cols, charset, post[0], post[1], shift)
