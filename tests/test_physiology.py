"""Physiology of the default L4-L5 unit (issue: real-world validity).

Fixture: the default geometry (embedded Visible Human L4-L5) with the calibration's prior (the Remus et al. 2021
laws of the same fibres on elongation with their sourced spreads, ``lumbar.experiments.calibration.calibration_prior``)
fitted on the real intact ROM of Yamamoto et al. 1989, the derived disc-only rows and the physical-admissibility
criteria (``fit_admissible``, the MAP fit that ends the workflow's calibration). Every threshold below is a
physiological statement with its source; a failing one is an xfail with the measured numbers, never a skip.
The intact ROM at 10 N*m against Yamamoto et al. is the fit's target, not a physiological finding: it is checked
where the fit's targets are (tests/test_calibration.py, test_admissible_fit_reaches_its_yamamoto_targets).
"""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments.calibration import FACET_STIFFNESS_RANGE, calibration_prior, elongation_prior, fit_admissible
from lumbar.inputs import resources
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


DISC_ONLY = ROOT / "data" / "experiments" / "heuer2007_disc_only_derived_from_published_fit.csv"


@pytest.fixture(scope="module")
def fitted(geo):
    path = resources.data_dir() / "geometry" / "visible_human_lss"
    paper = load_characteristic_set("calibrated")
    prior, _, spreads = calibration_prior(paper, geo, "L4-L5", path, "remus2021")
    return fit_admissible(geo, prior, pd.read_csv(YAMAMOTO), published=paper, geometry_path=path,
                          prior_spread=spreads, disc_rows=pd.read_csv(DISC_ONLY))


@pytest.fixture(scope="module")
def rom(geo, fitted):
    fsu = build_fsu(geo, fitted.charset)
    return range_of_motion(fsu, [10.0], DIRS, STAGES, tol=1e-7).set_index(["stage", "direction"])["rom_deg"]


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


def test_removing_ssl_raises_flexion(rom):
    """The SSL is in tension at 10 N*m flexion (an admissibility criterion): removing it must raise the flexion."""
    assert rom[("wo_ssl", "flexion")] - rom[("intact", "flexion")] >= 0.01


@pytest.mark.xfail(strict=True, reason=(
    "measured on this fixture (the admissible fit, 2026-11-25): flexion w/o ISL 7.42 -> w/o FL 7.24 deg. The "
    "flavum is pre-tensioned at rest (its fitted pre-elongation); removing it lets the unit settle in flexion at "
    "0 N*m, the neutral position from which the stage's ROM is measured, so the ROM from there is smaller although "
    "the unit is more flexed at 10 N*m. Heuer et al. measured ROM from each stage's own neutral too; whether their "
    "flavum was pre-tensioned enough to show this is not known here"))
def test_rom_does_not_fall_along_the_reduction(rom):
    """Heuer et al. 2007 (title): ROM increases with the stepwise reduction. Tolerance 0.05 deg."""
    bad = []
    for d in DIRS:
        seq = [rom[(s, d)] for s in STAGES]
        for a, b, s in zip(seq, seq[1:], STAGES[1:]):
            if b < a - 0.05:
                bad.append(f"{d} {s}: {a:.2f} -> {b:.2f}")
    assert not bad, "; ".join(bad)


@pytest.mark.xfail(strict=True, reason=(
    "measured (2026-11-26): the flexion row of the disc law (paper 1 Table 1, kept by the calibration) has p3 = "
    "-1.685 N*m/rad < 0, so the disc's torque pushes further into flexion from 0 to 1.75 deg and its stiffness is "
    "negative below about 1 deg: the disc-only unit's 0 N*m state at zero rotation is an equilibrium with one "
    "unstable direction (largest eigenvalue of the symmetric stiffness +1.68 N*m/rad), the first flexion step of the "
    "disc-only stage includes the snap onto the stable branch, and where only a weak ALL is left (Shirazi-Adl 1986 "
    "set, stage w/o PLL) the reference is a saddle the solver leaves only by cutting the PLL gradually "
    "(continue_rest_states; docs/validity.md, Known departures)"))
def test_disc_alone_is_stable_at_its_neutral_position(geo, fitted):
    """A disc without ligaments and facets is stable about its neutral position: every in-vitro moment-rotation curve
    is most compliant near neutral and stiffens with load, none has a negative stiffness (Yamamoto et al. 1989). The
    symmetric part of the disc-only unit's tangent stiffness at its 0 N*m equilibrium is positive definite (the
    residual's Jacobian negative definite)."""
    fsu = build_fsu(geo, fitted.charset)
    m = fsu.model
    fm, cm = fsu.masks(["wo_all"])
    r0 = solve(m, np.zeros((1, m.nb, 6)), fmask=fm, cmask=cm, tol_force=1e-9, tol_moment=1e-9)
    assert r0.converged.all()
    J = m.evaluate(r0.x, r0.R, fmask=fm, cmask=cm)[1][0].reshape(6 * m.nb, 6 * m.nb)
    # the whole 6x6 block: the unstable mode is a rotation about the disc centre, i.e. rotation and translation of
    # the vertebra's reference point together (definiteness does not depend on the mixed units, N/m and N*m/rad)
    assert np.linalg.eigvalsh(0.5 * (J + J.T)).max() < 0.0


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


def test_fit_flags_bounds_with_their_reasons(geo, fitted):
    p = fitted.parameters
    assert {"at_bound", "bound_reason"} <= set(p.columns)
    assert (p.loc[p["at_bound"], "bound_reason"].str.len() > 20).all()      # a bound is a finding, with its reason
    assert (p.loc[~p["at_bound"], "bound_reason"] == "").all()
    # a case with a bound whatever the fixture's fit does: the fit started with the facet stiffness on the upper end
    # of its range and stopped after one evaluation (the ROM does not move the facet stiffness off it)
    start = dict(zip(p["parameter"], p["fit_value"]))
    start["facet_stiffness"] = np.log10(FACET_STIFFNESS_RANGE[1])
    q = fit_admissible(geo, elongation_prior(load_characteristic_set("calibrated"))[0], pd.read_csv(YAMAMOTO),
                       geometry_path=resources.data_dir() / "geometry" / "visible_human_lss", start=start,
                       max_nfev=1).parameters.set_index("parameter")
    assert q.loc["facet_stiffness", "at_bound"], q.loc["facet_stiffness"]
    assert len(q.loc["facet_stiffness", "bound_reason"]) > 20, q.loc["facet_stiffness"]
    assert (q.loc[~q["at_bound"], "bound_reason"] == "").all()
