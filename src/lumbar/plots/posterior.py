"""Figure of the calibration's posterior (matplotlib object API, no pyplot, no backend switching): every fitted
parameter's prior and posterior 90 % interval on one axis, in units of its prior spread."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..inputs.io import save_figure_atomic, subplots

#: two-sided 90 % interval of a normal distribution: +- Z90 standard deviations (lumbar.experiments.posterior.Z90)
Z90 = 1.6448536269514722


def plot_prior_posterior(table: pd.DataFrame, path, sampling: pd.DataFrame | None = None) -> None:
    """One row per parameter of the calibration's posterior table (stage manifest role calibration.posterior): the
    prior's 90 % interval (grey, -1.645 to +1.645 prior spreads about its centre), the Laplace posterior's (blue bar,
    MAP dot) and, with ``sampling`` (role calibration.sampling), the posterior draws' 5-95 % interval (dark line),
    all in prior spreads from the prior centre, so that a shift and a narrowing read alike for every unit; a
    parameter at a bound is marked red."""
    t = table.reset_index(drop=True)
    n = len(t)
    fig, ax = subplots(1, 1, figsize=(8.0, 0.32 * n + 2.0))
    y = np.arange(n)[::-1]
    s = t["prior_spread_fit"].to_numpy(float)
    c = t["prior_centre_fit"].to_numpy(float)
    shift = (t["map_fit"].to_numpy(float) - c) / s
    log_unit = (t["fit_unit"] == "log10").to_numpy()

    def fit_units(col):                       # the table's intervals are in natural units, clipped to the bounds
        v = t[col].to_numpy(float)
        return (np.where(log_unit, np.log10(np.where(v > 0, v, np.nan)), v) - c) / s

    lo, hi = fit_units("posterior_90_low"), fit_units("posterior_90_high")
    plo, phi = fit_units("prior_90_low"), fit_units("prior_90_high")
    ax.barh(y, phi - plo, left=plo, height=0.7, color="0.85", label="prior, 90 % (within the bounds)")
    ax.barh(y, hi - lo, left=lo, height=0.38, color="C0", alpha=0.75, label="posterior, 90 % (Laplace, within the bounds)")
    if sampling is not None and not sampling.empty:
        sm = sampling.set_index("parameter").reindex(t["parameter"])
        slo = (sm["sampled_5_fit"].to_numpy(float) - c) / s
        shi = (sm["sampled_95_fit"].to_numpy(float) - c) / s
        ok = np.isfinite(slo) & np.isfinite(shi)
        ax.hlines(y[ok], slo[ok], shi[ok], color="k", lw=2.2, label="posterior draws (MCMC), 5-95 %")
    at_b = t["at_bound"].astype(bool).to_numpy()
    ax.plot(shift[~at_b], y[~at_b], "o", color="C0", ms=4, label="MAP")
    if at_b.any():
        ax.plot(shift[at_b], y[at_b], "s", color="C3", ms=5, label="MAP at a bound")
    ax.axvline(0.0, color="0.4", lw=0.8)
    ax.set_yticks(y)
    ax.set_yticklabels([p.replace("_", " ") for p in t["parameter"]], fontsize=8)
    ax.set_xlabel("(value - prior centre) / prior spread  [fit units: log10 scale, mm, log10 N/m]")
    ax.set_title("What the data told us: prior and posterior of every calibrated parameter", fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, frameon=False)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
