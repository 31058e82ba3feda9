"""lumbar.mechanics.idp: the two IDP formulas, analytically."""
import numpy as np
import pytest

from lumbar.mechanics.idp import FORMULAS, idp_from_disc, idp_paper1, idp_paper2, idp_per_newton


def test_paper1_is_1p68_force_over_csa():
    # 1000 N on 1500 mm^2 -> 1.68 * 1000 / 1.5e-3 Pa = 1.12 MPa
    assert idp_paper1(1000.0, 1.5e-3) == pytest.approx(1.12e6, rel=1e-12)
    np.testing.assert_allclose(idp_from_disc([0.0, 500.0], formula="paper1", csa_m2=1e-3), [0.0, 840e3])


def test_paper2_axial_part_and_moment_terms():
    f = 0.85 * 600.0 / (18e-4 * 0.66)                      # Pa, axial part for 600 N on 18 cm^2
    assert idp_paper2(600.0, 0.0) == pytest.approx(f, rel=1e-12)
    assert idp_paper2(600.0, 5.0) == pytest.approx(f + 0.036e6 * 5.0, rel=1e-12)      # flexion moment
    assert idp_paper2(600.0, -5.0) == pytest.approx(f + 0.018e6 * 5.0, rel=1e-12)     # extension moment
    assert idp_paper2(600.0, 0.0, area_m2=9e-4) == pytest.approx(2 * f, rel=1e-12)
    assert idp_from_disc(600.0, 5.0, formula="paper2") == pytest.approx(f + 0.18e6)


# the two papers' equations as printed, in their own units (N, mm^2, N*m -> MPa = N/mm^2), written out here apart
# from the module's constants: paper 1 Sect. 2.2.2, IDP ~ 1.68 F / CSA (Brinckmann and Grootenboer 1991); paper 2
# Sect. 2.4, IDP = F x 0.85 / (disc area x 0.66) + M_flexion x 0.036 MPa/(N*m) (0.018 MPa/(N*m) in extension)
PAPER_EQUATIONS_MPA = {
    "paper1": lambda f_n, m_nm, csa_mm2: 1.68 * f_n / csa_mm2,
    "paper2": lambda f_n, m_nm, csa_mm2: f_n * 0.85 / (1800.0 * 0.66) + (0.036 * m_nm if m_nm >= 0 else -0.018 * m_nm),
}


@pytest.mark.parametrize("f_n,m_nm,csa_mm2", [(0.0, 0.0, 1500.0), (1000.0, 0.0, 1500.0), (600.0, 5.0, 1800.0),
                                             (2500.0, -7.5, 1200.0)])
def test_every_listed_formula_is_its_papers_equation_in_pascal(f_n, m_nm, csa_mm2):
    """Every formula the configuration may name (l2s1.idp_formula) computes its paper's equation, in Pa from SI
    inputs (the paper's MPa from N and mm^2), and is linear in the axial force with the slope idp_per_newton: a
    formula without an equation, a dispatch to the other paper, or a unit slip (mm^2 for m^2) fails."""
    assert len(FORMULAS) >= 1
    for name in FORMULAS:
        assert name in PAPER_EQUATIONS_MPA, f"formula {name!r} has no paper equation here"
        got = idp_from_disc(f_n, m_nm, formula=name, csa_m2=csa_mm2 * 1e-6)
        assert got == pytest.approx(PAPER_EQUATIONS_MPA[name](f_n, m_nm, csa_mm2) * 1e6, rel=1e-12, abs=1e-6)
        twice = idp_from_disc(2 * f_n, m_nm, formula=name, csa_m2=csa_mm2 * 1e-6)
        assert twice - got == pytest.approx(f_n * idp_per_newton(name, csa_m2=csa_mm2 * 1e-6), rel=1e-12, abs=1e-6)


def test_reject_unknown_idp_formula():
    with pytest.raises(ValueError, match="l2s1.idp_formula"):
        idp_from_disc(100.0, formula="paper3", csa_m2=1e-3)


def test_bad_csa_rejected():
    with pytest.raises(ValueError, match="CSA"):
        idp_paper1(100.0, 0.0)
    with pytest.raises(ValueError, match="needs the disc CSA"):
        idp_from_disc(100.0, formula="paper1")
