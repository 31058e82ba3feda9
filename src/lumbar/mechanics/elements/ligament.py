"""Ligament force laws (paper 1, Eq. 7 and Appendix 1).

Softplus law (Eq. 7, Brown et al. 1996): ``F(eps) = a * ln(exp((eps + b) / d) + 1) + c`` with
strain ``eps`` in percent of the slack length and F in N (the paper's units; the only
non-SI quantities in the library, kept because the published parameters are defined so).

Tension-only rule (project decision, documented in docs/design.md):
  * a slack fibre (eps <= 0) carries no force;
  * the law is never allowed to push: F = max(F_law, 0);
  * a C1 ramp over ``0 < eps < slack_width_pct`` joins the slack region to the law, so the
    force is continuous even for the published flaval-ligament fit (d < 0), whose force
    *falls* with stretch and is 79.5 N at 0 % strain. With the paper's 10 % FL prestrain
    the ramp is only reached when the FL shortens by more than 9 %.

Rupp et al. (2015) piecewise law, per strand: 0 below the slack length l0; a power law
``K_nl * dl**nu`` up to dl = l_A; linear ``dF0 + K_l * (dl - l_A)`` beyond; C1 at l_A.
"""
from __future__ import annotations

import numpy as np

#: fibre law codes of the model's arrays (``SpineModel.f_law``) and of the compiled core
LAW_SOFTPLUS, LAW_RUPP, LAW_CABLE = 0, 1, 2


def slack_length(reference_length, prestrain):
    """Slack length [m] of a fibre prestrained by ``prestrain`` (a strain, fraction: 0.1 = 10 %) at its
    ``reference_length`` [m]: ``l0 = l_ref / (1 + prestrain)``. The one place of this formula: the model's
    fibres, the Rupp shape parameters and the prestrain effect all use it; the characteristic tables give
    prestrains in percent, converted once by the laws' ``prestrain`` property (``lumbar.inputs.characteristics``)."""
    return reference_length / (1.0 + prestrain)


def softplus_law(eps_pct, a, b, c, d):
    """Raw Eq. 7 (no tension-only rule): returns (F [N], dF/deps [N per %])."""
    eps_pct = np.asarray(eps_pct, dtype=float)
    z = (eps_pct + b) / d
    F = a * np.logaddexp(0.0, z) + c
    sig = 0.5 * (1.0 + np.tanh(0.5 * z))  # logistic(z), overflow-free
    return F, a / d * sig


def slack_ramp(eps_pct, width_pct):
    """C1 smoothstep from 0 (eps <= 0) to 1 (eps >= width); returns (s, ds/deps)."""
    eps_pct = np.asarray(eps_pct, dtype=float)
    if width_pct <= 0:
        s = (eps_pct > 0).astype(float)
        return s, np.zeros_like(eps_pct)
    t = np.clip(eps_pct / width_pct, 0.0, 1.0)
    s = t * t * (3.0 - 2.0 * t)
    ds = np.where((eps_pct > 0) & (eps_pct < width_pct), 6.0 * t * (1.0 - t) / width_pct, 0.0)
    return s, ds


def softplus_force(eps_pct, a, b, c, d, slack_width_pct=0.5):
    """Eq. 7 with the tension-only rule: returns (F >= 0 [N], dF/deps [N per %])."""
    F, dF = softplus_law(eps_pct, a, b, c, d)
    pos = F > 0.0
    F = np.where(pos, F, 0.0)
    dF = np.where(pos, dF, 0.0)
    s, ds = slack_ramp(eps_pct, slack_width_pct)
    return s * F, ds * F + s * dF


def rupp_shape(l_a, l_b, f_a, f_b, n_strands):
    """Shape parameters of the Rupp law that do not depend on the strand's slack length.

    Lengths in m, forces in N. Returns (l_a, dF0, nu, K_nl, K_l): dF0 = F_A/n,
    K_l = (F_B - F_A)/n / (l_B - l_A), nu = l_A * K_l / dF0 (C1 at l_A), K_nl = dF0 / l_A**nu.
    """
    dF0 = f_a / n_strands
    K_l = (f_b - f_a) / n_strands / (l_b - l_a)
    nu = l_a * K_l / dF0
    K_nl = dF0 / l_a**nu
    return l_a, dF0, nu, K_nl, K_l


def rupp_force(dl, l_a, dF0, nu, K_nl, K_l):
    """Rupp strand force [N] and dF/d(dl) [N/m] at elongation ``dl = l - l0`` [m]."""
    dl = np.asarray(dl, dtype=float)
    toe = (dl > 0) & (dl < l_a)
    lin = dl >= l_a
    dlp = np.where(toe, dl, 1.0)
    F = np.where(toe, K_nl * dlp**nu, 0.0) + np.where(lin, dF0 + K_l * (dl - l_a), 0.0)
    dF = np.where(toe, nu * K_nl * dlp ** (nu - 1.0), 0.0) + np.where(lin, K_l, 0.0)
    return F, dF
