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


def idp_paper1(f_axial_n, csa_m2, factor=1.68):
    """IDP [Pa] = factor * F_axial / CSA."""
    if not np.isfinite(csa_m2) or csa_m2 <= 0:
        raise ValueError(f"disc CSA must be a finite area > 0 m^2, got {csa_m2}")
    return factor * np.asarray(f_axial_n, float) / csa_m2


def idp_paper2(f_axial_n, m_sagittal_nm, area_m2=18e-4, disc_share=0.85, nucleus_factor=0.66,
               k_flexion_pa_per_nm=0.036 * MPA, k_extension_pa_per_nm=0.018 * MPA):
    """IDP [Pa] = disc_share * F / (A * nucleus_factor) + k_flex * M_flexion (or k_ext * M_extension)."""
    if not np.isfinite(area_m2) or area_m2 <= 0:
        raise ValueError(f"disc area must be a finite area > 0 m^2, got {area_m2}")
    M = np.asarray(m_sagittal_nm, float)
    return (disc_share * np.asarray(f_axial_n, float) / (area_m2 * nucleus_factor)
            + np.where(M >= 0, k_flexion_pa_per_nm * M, -k_extension_pa_per_nm * M))


def idp_from_disc(f_axial_n, m_sagittal_nm=0.0, formula="paper1", csa_m2=None, area_m2=18e-4, factor=1.68):
    """IDP [Pa] by ``formula`` (``paper1`` | ``paper2``; config key ``l2s1.idp_formula``)."""
    if formula == "paper1":
        if csa_m2 is None:
            raise ValueError("formula 'paper1' needs the disc CSA (csa_m2)")
        return idp_paper1(f_axial_n, csa_m2, factor)
    if formula == "paper2":
        return idp_paper2(f_axial_n, m_sagittal_nm, area_m2)
    raise ValueError(f"unknown IDP formula {formula!r} (config key l2s1.idp_formula); expected one of {FORMULAS}")
