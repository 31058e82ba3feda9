"""Shared fixtures: a hand-built characteristic set (paper 1 Tables 1 and 3) and paths."""
from pathlib import Path
from types import SimpleNamespace as NS

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
VISIBLE_HUMAN = SHARED / "geometry" / "visible_human_lss"

TABLE1 = {"flexion": (10.67, 0.005913, -1.685), "extension": (5.196, 0.008417, 24.50),
          "lateral_bending": (6.929, 0.001482, 19.76), "axial_rotation": (4.399, 0.001141, 42.38)}


def make_charset(torque=None, ligaments=True, facet_stiffness=12000.0, k_shear=9.65e4):
    disc = NS(k_axial_quadratic=690234060.0, k_axial_linear=659748.0, k_shear=k_shear, k_tension=0.0,
              torque=torque or TABLE1)
    L = lambda a, b, c, d, p: NS(a=a, b=b, c=c, d=d, prestrain_pct=p)  # noqa: E731
    ligs = {"ALL": L(173.5, -10.06, -26.82, 5.625, 8), "PLL": L(48.12, -43.97, -2.5, 15, 10),
            "FL": L(47.11, 4.21, 54.85, -11.25, 10), "CL": L(98.94, 18.97, -82.2, 73.33, 10),
            "ISL": L(0.4517, -3.502, 0, 0.02414, 4), "SSL": L(1.218, -22.97, 0, 1.369, -6)}
    return NS(name="test", disc=disc, facet=NS(stiffness=facet_stiffness), ligaments=ligs if ligaments else {})


@pytest.fixture
def charset():
    return make_charset()


@pytest.fixture
def shared_geometry_dir():
    if not VISIBLE_HUMAN.is_dir():
        pytest.skip("../shared/geometry/visible_human_lss not present")
    return VISIBLE_HUMAN
