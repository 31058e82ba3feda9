"""Intradiscal pressure (IDP) from the disc's internal loads.

Two formulas (SI inside: N, m^2, N*m -> Pa):

* ``paper1`` (paper 1, Sect. 2.2.2; Brinckmann and Grootenboer 1991): ``IDP = 1.68 * F_axial / CSA``,
  CSA = the endplate cross-sectional area from the mesh (``Level.disc_csa``).
* ``paper2`` (paper 2, Sect. 2.4): ``IDP = 0.85 * F_axial / (A * 0.66) + 0.036 MPa/(N*m) * M_flexion``
  or ``+ 0.018 MPa/(N*m) * M_extension``, with the disc area A = 18 cm^2 (Wilke et al. 2001) by default.

``F_axial`` is the axial disc force on the upper vertebra in the disc frame (compression positive, from
``SpineModel.disc_loads``); ``M_sagittal`` the sagittal moment the disc carries (+ flexion, - extension).
"""
from __future__ import annotations

import numpy as np

FORMULAS = ("paper1", "paper2")
MPA = 1e6
# the constants of the two formulas (this module owns them; other modules import them or idp_per_newton)
PAPER1_FACTOR = 1.68                        # paper 1: IDP = 1.68 F / CSA
DISC_AREA_M2 = 18e-4                        # paper 2: disc area A (Wilke et al. 2001) [m^2]
DISC_SHARE = 0.85                           # paper 2: share of the axial force on the disc
NUCLEUS_FACTOR = 0.66                       # paper 2: nucleus share of the disc area
K_FLEXION_PA_PER_NM = 0.036 * MPA           # paper 2: moment term in flexion [Pa/(N*m)]
K_EXTENSION_PA_PER_NM = 0.018 * MPA         # paper 2: moment term in extension [Pa/(N*m)]


def idp_paper1(f_axial_n, csa_m2, factor=PAPER1_FACTOR):
    """IDP [Pa] = factor * F_axial / CSA."""
    if not np.isfinite(csa_m2) or csa_m2 <= 0:
        raise ValueError(f"disc CSA must be a finite area > 0 m^2, got {csa_m2}")
    return factor * np.asarray(f_axial_n, float) / csa_m2


def idp_paper2(f_axial_n, m_sagittal_nm, area_m2=DISC_AREA_M2, disc_share=DISC_SHARE, nucleus_factor=NUCLEUS_FACTOR,
               k_flexion_pa_per_nm=K_FLEXION_PA_PER_NM, k_extension_pa_per_nm=K_EXTENSION_PA_PER_NM):
    """IDP [Pa] = disc_share * F / (A * nucleus_factor) + k_flex * M_flexion (or k_ext * M_extension)."""
    if not np.isfinite(area_m2) or area_m2 <= 0:
        raise ValueError(f"disc area must be a finite area > 0 m^2, got {area_m2}")
    M = np.asarray(m_sagittal_nm, float)
    return (disc_share * np.asarray(f_axial_n, float) / (area_m2 * nucleus_factor)
            + np.where(M >= 0, k_flexion_pa_per_nm * M, -k_extension_pa_per_nm * M))


def idp_per_newton(formula, csa_m2=None, area_m2=DISC_AREA_M2):
    """d IDP / d axial force [Pa/N] of ``formula`` (the force part: ``paper1`` 1.68 / CSA, ``paper2``
    0.85 / (A * 0.66)); used by the IDP effects (axial preload) and the discovery's IDP model."""
    if formula == "paper1":
        if csa_m2 is None:
            raise ValueError("formula 'paper1' needs the disc CSA (csa_m2)")
        return PAPER1_FACTOR / csa_m2
    if formula == "paper2":
        return DISC_SHARE / (area_m2 * NUCLEUS_FACTOR)
    raise ValueError(f"unknown IDP formula {formula!r} (config key l2s1.idp_formula); expected one of {FORMULAS}")


def idp_from_disc(f_axial_n, m_sagittal_nm=0.0, formula="paper1", csa_m2=None, area_m2=DISC_AREA_M2,
                  factor=PAPER1_FACTOR):
    """IDP [Pa] by ``formula`` (``paper1`` | ``paper2``; config key ``l2s1.idp_formula``)."""
    if formula == "paper1":
        if csa_m2 is None:
            raise ValueError("formula 'paper1' needs the disc CSA (csa_m2)")
        return idp_paper1(f_axial_n, csa_m2, factor)
    if formula == "paper2":
        return idp_paper2(f_axial_n, m_sagittal_nm, area_m2)
    raise ValueError(f"unknown IDP formula {formula!r} (config key l2s1.idp_formula); expected one of {FORMULAS}")
