"""lumbar.mechanics.idp: the two IDP formulas, analytically."""
import numpy as np
import pytest

from lumbar.mechanics.idp import FORMULAS, idp_from_disc, idp_paper1, idp_paper2


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


def test_formulas_listed():
    assert FORMULAS == ("paper1", "paper2")


def test_reject_unknown_idp_formula():
    with pytest.raises(ValueError, match="l2s1.idp_formula"):
        idp_from_disc(100.0, formula="paper3", csa_m2=1e-3)


def test_bad_csa_rejected():
    with pytest.raises(ValueError, match="CSA"):
        idp_paper1(100.0, 0.0)
    with pytest.raises(ValueError, match="needs the disc CSA"):
        idp_from_disc(100.0, formula="paper1")
