"""Physics the solver must reproduce by hand: closed forms and invariants, not stored numbers.

* pure axial compression of a disc-only unit: k2 c^2 + k1 c = F (paper 1, Sect. 2.2.2, the disc's axial
  law with Table 1's k2, k1), no rotation, and the IDP through the solver equal to 1.68 F / CSA by hand;
* the paper-2 IDP moment term's sign end to end: a flexion moment on L2 loads the L4-L5 disc in flexion
  and adds 0.036 MPa per N*m, an extension moment adds 0.018 MPa per N*m (never subtracts);
* delta IDP = 1.68 delta F / CSA between two solved load cases.

All on the mirror-symmetric synthetic geometry (exact, independent of the default mesh) and the real
``calibrated`` characteristic set (paper 1, Tables 1-3).
"""
import math

import numpy as np
import pytest

from lumbar.experiments import l2s1

from lumbar.mechanics import so3
from lumbar.experiments.fsu import build_fsu
from lumbar.geometry.synthetic import symmetric_fsu
from lumbar.mechanics.idp import idp_from_disc
from lumbar.mechanics.solve import solve

from conftest import make_charset, synthetic_l2s1_chain


def _axial_loads(fsu, forces_n):
    """Loads (B, nb, 6) on the upper vertebra: a compressive force F along the disc normal *through the disc
    centre*, expressed at the body reference point (force plus the moment of its offset)."""
    m, lev = fsu.model, fsu.level
    n = np.asarray(lev.disc_normal, float) / np.linalg.norm(lev.disc_normal)
    r = np.asarray(lev.disc_centre, float) - np.asarray(m.centroids[0], float)
    L = np.zeros((len(forces_n), m.nb, 6))
    for i, F in enumerate(forces_n):
        f = -F * n
        L[i, 0, :3] = f
        L[i, 0, 3:] = np.cross(r, f)
    return L


def _closed_form_compression(F, k2, k1):
    """Positive root c [m] of k2 c^2 + k1 c = F."""
    return (-k1 + math.sqrt(k1 * k1 + 4.0 * k2 * F)) / (2.0 * k2)


@pytest.fixture(scope="module")
def disc_only():
    cs = make_charset(ligaments=False)
    return build_fsu(symmetric_fsu(), cs), cs


FORCES_N = (100.0, 300.0, 500.0, 1000.0)


def test_pure_axial_compression_of_disc_only_unit_matches_closed_form(disc_only):
    """Axial law k2 c^2 + k1 c = F (k2 = 6.90e8 N/m^2, k1 = 6.60e5 N/m): e.g. F = 500 N gives
    c = (-k1 + sqrt(k1^2 + 4 k2 F)) / (2 k2) = (-6.597e5 + 1.3475e6) / 1.3805e9 = 0.498 mm; the unit moves straight down by c, without
    rotation or shear, and the disc carries exactly F."""
    fsu, cs = disc_only
    m = fsu.model
    k2, k1 = cs.disc.k_axial_quadratic, cs.disc.k_axial_linear
    res = solve(m, _axial_loads(fsu, FORCES_N), cmask=0.0)      # facets removed: disc only
    assert res.converged.all()
    dl = m.disc_loads(res.x, res.R)
    for i, F in enumerate(FORCES_N):
        c = _closed_form_compression(F, k2, k1)
        assert -dl["r"][i, 0, 2] == pytest.approx(c, rel=1e-9, abs=1e-12), F          # compression [m]
        assert dl["force"][i, 0, 2] == pytest.approx(F, rel=1e-9), F                  # axial disc force [N]
        assert np.abs(dl["force"][i, 0, :2]).max() < 1e-6                              # no shear
        assert np.abs(so3.log(res.R[i, 0])).max() < 1e-9                               # no rotation
        assert k2 * c**2 + k1 * c == pytest.approx(F, rel=1e-12)
    assert _closed_form_compression(500.0, k2, k1) == pytest.approx(0.498e-3, abs=0.001e-3)


def test_idp_through_the_solver_equals_hand_computation(disc_only):
    """Paper 1 IDP = 1.68 F / CSA (Brinckmann and Grootenboer 1991) with the synthetic disc's 1600 mm^2:
    500 N -> 1.68 * 500 / 1.6e-3 = 0.525 MPa; and delta IDP = 1.68 delta F / CSA between load cases."""
    fsu, _ = disc_only
    m, csa = fsu.model, fsu.level.disc_csa
    assert csa == pytest.approx(1.6e-3)
    res = solve(m, _axial_loads(fsu, FORCES_N), cmask=0.0)      # facets removed: disc only
    assert res.converged.all()
    F_solved = m.disc_loads(res.x, res.R)["force"][:, 0, 2]
    idp = idp_from_disc(F_solved, formula="paper1", csa_m2=csa)
    assert idp[FORCES_N.index(500.0)] == pytest.approx(0.525e6, rel=1e-9)
    np.testing.assert_allclose(idp, 1.68 * np.array(FORCES_N) / 1.6e-3, rtol=1e-9)
    np.testing.assert_allclose(np.diff(idp), 1.68 * np.diff(FORCES_N) / csa, rtol=1e-9)


@pytest.fixture(scope="module")
def l2s1_paper2():
    geo = synthetic_l2s1_chain()
    cables = l2s1.mirror_cables(l2s1.derive_cables())
    # rupp2015: the same passive elements at every level; the calibrated set solves ~8x slower on this chain
    df, sol = l2s1.run_set(geo, make_charset("rupp2015"), cables, idp_formula="paper2")
    return df


def test_paper2_idp_is_the_hand_formula_of_the_reported_loads(l2s1_paper2):
    """Every row of the L2-S1 table (synthetic chain, rupp2015 set, idp_formula paper2): the reported IDP is
    0.85 F / (18 cm^2 * 0.66) + 0.036 MPa/(N*m) M (M >= 0) or + 0.018 MPa/(N*m) |M| (M < 0) of the reported
    disc axial force and FSU sagittal moment, so the moment term never lowers the IDP."""
    df = l2s1_paper2
    assert df["converged"].all()
    M = df["fsu_moment_sagittal_nm"].to_numpy()
    axial = 0.85 * df["disc_axial_force_n"].to_numpy() / (18e-4 * 0.66)
    hand = axial + np.where(M >= 0, 0.036e6 * M, -0.018e6 * M)
    np.testing.assert_allclose(df["idp_mpa"].to_numpy() * 1e6, hand, rtol=1e-9)
    assert (df["idp_mpa"].to_numpy() * 1e6 >= axial - 1e-6).all()


def test_paper2_moment_term_sign_end_to_end(l2s1_paper2):
    """Paper-2 IDP end to end, L2-S1 without cables: a pure +3.75 N*m flexion moment on L2 is transmitted
    unchanged through every level (statics of a pure moment), so the L4-L5 FSU bears M_flexion = 3.75 N*m
    (lumbar.experiments.l2s1.fsu_sagittal_moment: the whole unit, not the disc's own torque, which the prestressed
    ligaments leave at -0.88 N*m in this case) and
    the moment term is + 0.036 MPa/(N*m) * 3.75 = +0.135 MPa; extension: + 0.018 * 3.75 = +0.0675 MPa. The
    unit flexes in flexion and extends in extension (relative to its neutral, prestressed posture)."""
    df = l2s1_paper2
    assert df["converged"].all()
    d = df[df["muscle_setup"] == "none"].set_index("load_case")
    flex = d["disc_flexion_deg"] - d.loc["neutral", "disc_flexion_deg"]          # relative to the neutral case
    assert flex["flexion"] > 0.1 and flex["extension"] < -0.1
    axial = 0.85 * d["disc_axial_force_n"] / (18e-4 * 0.66)                      # Pa
    M = l2s1.MOMENT_NM
    assert d.loc["flexion", "idp_mpa"] * 1e6 - axial["flexion"] == pytest.approx(0.036e6 * M, rel=1e-6)
    assert d.loc["extension", "idp_mpa"] * 1e6 - axial["extension"] == pytest.approx(0.018e6 * M, rel=1e-6)
