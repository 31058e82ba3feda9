"""Physiology of the default L4-L5 unit (issue: real-world validity).

Fixture: the default geometry (embedded Visible Human L4-L5) with the paper's published characteristic set
fitted on the real intact ROM of Yamamoto et al. 1989 (``lumbar.experiments.calibration.fit_real_targets``, the same
step that anchors the surrogate generator and ends the workflow's calibration). Every threshold below is a
physiological statement with its source; a failing one is an xfail with the measured numbers, never a skip.
"""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments.calibration import fit_real_targets
from lumbar.inputs.characteristics import load_characteristic_set
from lumbar.experiments.fsu import STAGES, build_fsu, range_of_motion
from lumbar.geometry import load_geometry
from lumbar.mechanics.solve import solve
from lumbar.experiments.fsu import moment_loads

ROOT = Path(__file__).resolve().parents[1]
YAMAMOTO = ROOT / "data" / "experiments" / "yamamoto1989_intact_rom_original_text.csv"
ANATOMY = ROOT / "data" / "anatomy" / "l4l5_magnitudes_original_text.csv"
DIRS = ("flexion", "extension", "lateral_bending", "axial_rotation")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def geo():
    return load_geometry("visible_human", levels=["L4-L5"])


@pytest.fixture(scope="module")
def fitted(geo):
    return fit_real_targets(geo, load_characteristic_set("calibrated"), pd.read_csv(YAMAMOTO))


@pytest.fixture(scope="module")
def rom(geo, fitted):
    fsu = build_fsu(geo, fitted.charset)
    return range_of_motion(fsu, [10.0], DIRS, STAGES, tol=1e-7).set_index(["stage", "direction"])["rom_deg"]


def test_intact_rom_within_25_percent_of_yamamoto(rom):
    ref = pd.read_csv(YAMAMOTO).set_index("direction")["rom_mean_deg"]
    for d in DIRS:
        assert abs(rom[("intact", d)] - ref[d]) <= 0.25 * ref[d], (d, rom[("intact", d)], ref[d])


def test_intact_flexion_exceeds_extension(rom):
    # Yamamoto et al. 1989: L4-L5 flexion 8.9 deg > extension 5.8 deg at 10 N*m
    assert rom[("intact", "flexion")] > rom[("intact", "extension")]


@pytest.mark.parametrize("direction", ["extension", "axial_rotation"])
def test_facets_carry_load_at_10_nm(geo, fitted, direction):
    fsu = build_fsu(geo, fitted.charset)
    m = fsu.model
    r = solve(m, moment_loads([direction], [10.0], m.nb), tol_force=1e-7, tol_moment=1e-7)
    assert r.converged.all()
    total = m.contact_forces(r.x, r.R).sum()
    assert total > 10.0, f"facet contact force at 10 N*m {direction}: {total:.2f} N"


def test_removing_vertebral_arch_raises_axial_rotation_by_1deg(rom):
    assert rom[("wo_va", "axial_rotation")] - rom[("wo_cl", "axial_rotation")] >= 1.0


@pytest.mark.xfail(strict=True, reason=(
    "measured: the SSL of the Visible Human L4-L5 (one 20.1 mm fibre, prestrain -6 %, Table 3 knee at 23 % "
    "strain) stays slack up to 10 N*m flexion: w/o SSL = intact; the real-target fit cannot identify it "
    "(ROM sensitivity < 1e-4 deg per decade) and keeps the published law"))
def test_removing_ssl_raises_flexion(rom):
    assert rom[("wo_ssl", "flexion")] - rom[("intact", "flexion")] >= 0.1


@pytest.mark.xfail(strict=True, reason=(
    "measured on this fixture (published Table 3 laws, force-scaled): flexion w/o FL 7.79 -> 7.56 deg (the "
    "paper's FL law is concave, d < 0: its tension falls as it stretches, a negative stiffness the paper "
    "attributes to the vertebral-arch artefact, Sect. 4.2); flexion w/o PLL 12.16 -> 11.52 and extension "
    "w/o ALL 14.25 -> 12.82 deg (the prestrained ALL/PLL, 8-10 %, carry tension at rest; removing it moves "
    "the stage's neutral position, from which ROM is measured). The workflow's own calibration fits monotone "
    "laws with F(0) = 0 instead (lumbar.experiments.calibration)"))
def test_rom_does_not_fall_along_the_reduction(rom):
    """Heuer et al. 2007 (title): ROM increases with the stepwise reduction. Tolerance 0.05 deg."""
    bad = []
    for d in DIRS:
        seq = [rom[(s, d)] for s in STAGES]
        for a, b, s in zip(seq, seq[1:], STAGES[1:]):
            if b < a - 0.05:
                bad.append(f"{d} {s}: {a:.2f} -> {b:.2f}")
    assert not bad, "; ".join(bad)


def test_disc_cross_section_within_sourced_range(geo):
    a = pd.read_csv(ANATOMY).set_index("quantity")
    ref = float(a.loc["disc_cross_section", "value"])      # mm^2, Wilke et al. 1999 (third party)
    csa = geo.levels["L4-L5"].disc_csa * 1e6
    assert abs(csa - ref) <= 0.25 * ref, csa


def test_facet_joint_space_within_sourced_range(geo):
    a = pd.read_csv(ANATOMY).set_index("quantity")
    lo, hi = float(a.loc["facet_joint_space_width", "low"]), float(a.loc["facet_joint_space_width", "high"])
    for side, f in geo.levels["L4-L5"].facets.items():
        width = float(np.mean(np.linalg.norm(f.inferior - f.superior, axis=1))) * 1e3
        assert lo <= width <= hi, (side, width)


def test_fit_flags_bounds_and_identifiability(fitted):
    p = fitted.parameters.set_index("parameter")
    assert {"at_bound", "identifiable"} <= set(p.columns)
    assert not p.loc["SSL", "identifiable"]      # slack (see the xfail above): kept, not fitted to a bound
    assert p.loc["SSL", "value"] == 1.0
