"""Readings of the transfer of the calibrated characteristics to other levels (lumbar.experiments.level_transfer):
identity at the calibrated level, factors from the geometry, a rigid turn that changes nothing but the frame."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from lumbar.experiments import level_transfer as LT
from lumbar.experiments.calibration import elongation_prior
from lumbar.experiments.fsu import build_fsu, range_of_motion
from lumbar.geometry import load_geometry
from lumbar.inputs import resources
from lumbar.mechanics.elements.facet import fit_surface

GEOMETRY_DIR = resources.data_dir() / "geometry" / "visible_human_lss"


@pytest.fixture(scope="module")
def geometry():
    return load_geometry("visible_human", path=GEOMETRY_DIR, levels=["L4-L5", "L5-S1"])


@pytest.fixture(scope="module")
def prior():
    p = elongation_prior()[0]
    return dataclasses.replace(p, disc=dataclasses.replace(p.disc, k_shear=1.0e5))


def test_every_reading_is_the_identity_at_the_calibrated_level(geometry, prior):
    ref = geometry.levels["L4-L5"]
    f = LT.size_scale_factors(ref, ref)
    assert f == pytest.approx({"disc_axial": 1.0, "disc_torque": 1.0, "facet": 1.0})
    assert LT.size_scaled_set(prior, ref, ref) == prior
    assert LT.strain_transfer_set(prior, ref, ref) == prior


def test_size_factors_follow_the_section_laws():
    """A level with twice the disc cross-section at the same height: axial x2, bending x4 (I ~ A^2); a facet face
    twice as large: facet stiffness x2. Built so that an A/h torque scaling or a point-count facet scaling fails."""
    rng = np.random.default_rng(3)
    face = np.column_stack([rng.uniform(0, 0.01, 20), rng.uniform(0, 0.008, 20), rng.normal(0, 1e-5, 20)])
    inner = rng.dirichlet(np.ones(20), 30) @ face                     # 30 points inside the face's hull

    class Fac:
        def __init__(self, s, extra):
            self.contact_set = np.vstack([face, inner[:extra]]) * np.sqrt(s)

    def level(csa, s, extra):
        return type("L", (), {"disc_csa": csa, "disc_height": 0.01, "facets": {"left": Fac(s, extra),
                                                                              "right": Fac(s, extra)},
                              "ligaments": []})()

    area = LT.face_area(face)
    assert area == pytest.approx(LT.face_area(face + [0.1, -0.2, 0.3]))          # translation-free
    # more points on the larger face (a finer mesh must not matter: the area does)
    f = LT.size_scale_factors(level(2e-3, 2.0, 30), level(1e-3, 1.0, 0))
    assert f["disc_axial"] == pytest.approx(2.0)
    assert f["disc_torque"] == pytest.approx(4.0)
    assert f["facet"] == pytest.approx(2.0, rel=1e-3)


def test_strain_reading_scales_each_law_length_with_the_level_fibres(geometry, prior):
    lv, ref = geometry.levels["L5-S1"], geometry.levels["L4-L5"]
    s, r = LT.level_sizes(lv)["fibre_length"], LT.level_sizes(ref)["fibre_length"]
    cs = LT.strain_transfer_set(prior, lv, ref)
    for kind, law in prior.ligaments.items():
        assert cs.ligaments[kind].law_length_m == pytest.approx(law.law_length_m * s[kind] / r[kind])
        # the same pre-strain, so the pre-elongation follows the law length
        assert cs.ligaments[kind].prestrain_pct == law.prestrain_pct


def test_disc_frame_turn_is_rigid_and_aligns_the_disc_normal(geometry):
    lv = geometry.levels["L5-S1"]
    assert abs(LT.sagittal_tilt_deg(lv)) > 20          # the lumbosacral disc is tilted: the turn is not trivial
    g = LT.disc_frame_geometry(geometry, "L5-S1")
    new = g.levels["L5-S1"]
    assert abs(LT.sagittal_tilt_deg(new)) < 1e-9
    for a, b in zip(lv.ligaments, new.ligaments):
        np.testing.assert_allclose(a.lengths, b.lengths, rtol=0, atol=1e-12)
    d0 = np.linalg.norm(geometry.vertebrae["L5"].centroid - geometry.vertebrae["S1"].centroid)
    assert np.linalg.norm(g.vertebrae["L5"].centroid - g.vertebrae["S1"].centroid) == pytest.approx(d0, abs=1e-12)
    for side in lv.facets:        # the facet gaps at rest are the same: the contact surface turns with its points
        f0, f1 = lv.facets[side], new.facets[side]
        s0 = fit_surface(f0.superior, f0.inferior, contact=f0.contact, contact_points=f0.contact_points)
        s1 = fit_surface(f1.superior, f1.inferior, contact=f1.contact, contact_points=f1.contact_points)
        np.testing.assert_allclose(s0.gap(f0.contact_set)[0], s1.gap(f1.contact_set)[0], atol=1e-9)
    assert geometry.levels["L5-S1"] is lv and np.isclose(LT.sagittal_tilt_deg(lv), LT.sagittal_tilt_deg(
        geometry.levels["L5-S1"]))                      # the input geometry is left as it was


def test_disc_frame_changes_axial_rotation_not_flexion(geometry, prior):
    """A turn about the lateral axis leaves a moment about that axis where it was: flexion-extension is the same
    in both frames (up to the small coupled rotations, which meet the disc's lateral-bending and axial laws in
    other proportions once turned); the axial moment about the vertical, which loads the tilted disc partly in
    lateral bending, is not. A reading that turned the loads but not the unit (or the reverse) fails the first assertion."""
    kw = dict(directions=("flexion", "extension", "axial_rotation"), moments_nm=(5.0, 10.0))
    ref = geometry.levels["L4-L5"]
    a = range_of_motion(LT.reading_unit("as_calibrated", geometry, prior, "L5-S1", ref, build_fsu), **kw)
    b = range_of_motion(LT.reading_unit("disc_frame_loading", geometry, prior, "L5-S1", ref, build_fsu), **kw)
    assert a["converged"].all() and b["converged"].all()
    key = ["direction", "moment_nm"]
    m = a.merge(b, on=key, suffixes=("_p", "_d"))
    fe = m[m["direction"].isin(["flexion", "extension"])]
    np.testing.assert_allclose(fe["rom_deg_p"], fe["rom_deg_d"], atol=1e-3)
    ar = m[m["direction"] == "axial_rotation"]
    assert (np.abs(ar["rom_deg_p"] - ar["rom_deg_d"]) > 0.05).all()


def test_readings_summary_counts_other_levels_only():
    rom = pd.DataFrame({"level": ["L4-L5", "L3-L4", "L3-L4"], "direction": ["flexion", "flexion", "extension"],
                        "moment_nm": 10.0, "sim_deg": [7.0, 7.0, 4.8], "measured_deg": [8.9, 7.5, 3.7],
                        "ratio": [0.79, 0.93, 1.3], "within": [True, True, False], "converged": True,
                        "largest_jump_deg": [0.3, 0.6, 0.2]})
    t = LT.readings_table({"as_calibrated": rom, "size_scaled": rom}, "L4-L5")
    s = LT.readings_summary(t)
    assert list(s["reading"]) == ["as_calibrated", "size_scaled"]
    r = s.iloc[0]
    assert (r.other_within, r.other_n, r.calibrated_within, r.calibrated_n) == (1, 2, 1, 1)
    assert r.snap_or_not_converged == 1 and r.misses == "L3-L4 extension 1.30"
    # a curve on a 0.5 N*m grid: its 0.6 deg step is 0.3 deg per 0.25 N*m, no snap
    coarse = LT.readings_summary(LT.readings_table({"as_calibrated": rom}, "L4-L5", moment_step_nm=0.5))
    assert coarse["snap_or_not_converged"].iloc[0] == 0
    with pytest.raises(ValueError, match="unknown transfer reading"):
        LT.reading_unit("by_eye", None, None, "L4-L5", None, build_fsu)
