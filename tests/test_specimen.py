"""A user's specimen (lumbar.geometry.specimen*, lumbar.plots.specimen): the project frame from the anatomy, the
landmarks, the tables and their read-back, the command, and the accuracy on the Visible Human set (leave one out).

Every claim has a control that fails: landmarks compared without the alignment differ by centimetres; a correct
declaration passes where a wrong one raises; the atlas without registration misses the accuracy thresholds.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from lumbar.geometry import GeometryError, load_geometry
from lumbar.geometry.specimen import align_to_project, check_winding, declared_matrix
from lumbar.geometry.specimen_accuracy import LPS_FROM_PROJECT, ct_pose, visible_human_accuracy, write_posed_meshes
from lumbar.geometry.specimen_build import build_specimen, facet_space_range_m
from lumbar.geometry.specimen_tables import geometry_from_table, read_landmark_table, write_tables

RAS_FROM_PROJECT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
PAIR = ("L4", "L5")
TOL_M = 1e-4          # 0.1 mm
#: the snap to the surface (closest point) is discontinuous at concave creases and across a joint gap: a carried
#: point that moves by 1 um (the registration's round-off under a rigid motion) may land on the other side of a
#: crease, up to 0.25 mm away (measured: CL, a facet and an ISL point of L4-L5). Every other landmark agrees to
#: ~1 um; the test asserts 0.1 mm for 95 % of the landmarks and 0.3 mm for all
SNAP_JUMP_M = 3e-4


def _agree(a, b):
    d = np.linalg.norm(a - b, axis=1)
    return np.quantile(d, 0.95) < TOL_M and d.max() < SNAP_JUMP_M


def _pose(R, t=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _rot(axis, deg):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(deg)
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


@pytest.fixture(scope="module")
def vh():
    return load_geometry("visible_human")


@pytest.fixture(scope="module")
def project_meshes(vh):
    return {v: vh.vertebrae[v].mesh for v in PAIR}


def _moved(meshes, T):
    return {v: m.copy().apply_transform(T) for v, m in meshes.items()}


def _points(sp):
    """Every landmark of the specimen (project frame), in a fixed order."""
    out = []
    for lv in sorted(sp.landmarks):
        lm = sp.landmarks[lv]
        for name in sorted(lm["ligaments"]):
            out += [lm["ligaments"][name][0], lm["ligaments"][name][1]]
        for side in sorted(lm["facets"]):
            out += list(lm["facets"][side])
    return np.vstack(out)


@pytest.fixture(scope="module")
def reference_specimen(project_meshes):
    return build_specimen(project_meshes, axes="project")


def test_declared_axes_codes():
    assert np.allclose(declared_matrix("LPS"), LPS_FROM_PROJECT.T)
    assert np.allclose(declared_matrix("RAS"), RAS_FROM_PROJECT.T)
    assert np.allclose(declared_matrix("project"), np.eye(3))
    assert declared_matrix("any") is None
    with pytest.raises(GeometryError, match="left-handed"):
        declared_matrix("LPI")                       # control: a mirrored code
    with pytest.raises(GeometryError, match="three-letter code"):
        declared_matrix("LPX")


@pytest.mark.parametrize("seed", [1, 2])
def test_landmarks_invariant_under_rigid_motion(project_meshes, reference_specimen, seed):
    """Any rotation and shift of the input ("any": the anatomy alone) gives the same project-frame landmarks."""
    rng = np.random.default_rng(seed)
    T = _pose(_rot(rng.normal(size=3), rng.uniform(20, 170)), rng.normal(size=3) * 0.3)
    sp = build_specimen(_moved(project_meshes, T), axes="any")
    ref = _points(reference_specimen)
    assert _agree(_points(sp), ref)
    # control: the same landmarks carried back without the alignment differ by centimetres
    raw = _points(sp) @ np.linalg.inv(sp.alignment.transform)[:3, :3].T
    assert not _agree(raw, ref) and np.abs(raw - ref).max() > 0.01


def _renumbered(mesh, seed):
    """The same surface with its vertices in another order (faces re-indexed): what another file format gives."""
    import trimesh
    perm = np.random.default_rng(seed).permutation(len(mesh.vertices))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    return trimesh.Trimesh(np.asarray(mesh.vertices)[perm], inv[np.asarray(mesh.faces)], process=False)


def _file_order_stride(mesh, n):
    """The first version's sample: every k-th vertex in the file's order."""
    v = np.asarray(mesh.vertices, float)
    idx = np.arange(0, len(v), max(1, int(np.ceil(len(v) / n))))
    return v[idx], idx


def test_surface_sample_ignores_vertex_order_and_pose_and_is_even_over_the_area(vh):
    import trimesh

    from lumbar.geometry.register import mesh_sample, surface_sample, welded
    m = welded(vh.vertebrae["L4"].mesh)
    v = np.asarray(m.vertices)
    perm = np.random.default_rng(0).permutation(len(v))
    a = surface_sample(v, 1500)
    assert 1000 < len(a) <= 1500
    assert np.array_equal(surface_sample(v[perm], 1500), a)
    T = _pose(_rot([0.2, -1.0, 0.4], 70.0), (0.3, -0.1, 0.9))
    assert np.allclose(surface_sample(v @ T[:3, :3].T + T[:3, 3], 1500), a @ T[:3, :3].T + T[:3, 3], atol=1e-12)
    b, _ = mesh_sample(m, 1500)
    assert np.array_equal(mesh_sample(_renumbered(m, 1), 1500)[0], b)
    # control: every k-th vertex in file order is another sample of the same surface
    assert not np.array_equal(np.sort(_file_order_stride(_renumbered(m, 1), 1500)[0], 0),
                              np.sort(_file_order_stride(m, 1500)[0], 0))
    # even over the area: one half of the surface subdivided (4x its vertices there) keeps its share of an area-even
    # sample (its share of the area), while a stride over the vertices follows the vertex count
    half = m.triangles_center[:, 0] > np.median(m.triangles_center[:, 0])
    vv, ff = trimesh.remesh.subdivide(m.vertices, m.faces, face_index=np.flatnonzero(half))
    dense = trimesh.Trimesh(vv, ff)
    cut = np.median(m.triangles_center[:, 0])
    share_area = m.area_faces[half].sum() / m.area
    assert abs(np.mean(mesh_sample(dense, 1500)[0][:, 0] > cut) - share_area) < 0.05
    assert np.mean(surface_sample(dense.vertices, 1500)[:, 0] > cut) - share_area > 0.15


def test_landmarks_independent_of_the_vertex_order(monkeypatch, project_meshes, reference_specimen):
    """The same surfaces with their vertices renumbered (as STL, OBJ, PLY and VTK readers number them differently)
    give the same landmarks; control: sampling every k-th vertex in file order moves them (a median 0.1-0.3 mm here;
    before the registration followed the surface, over 1 mm)."""
    import lumbar.geometry.specimen as spm
    import lumbar.geometry.specimen_landmarks as sl
    sl.default_atlas()          # built (and cached for the session) with the package's own sample first
    shuffled = {v: _renumbered(m, i) for i, (v, m) in enumerate(project_meshes.items())}
    assert np.abs(_points(build_specimen(shuffled, axes="project")) - _points(reference_specimen)).max() < 1e-6
    monkeypatch.setattr(spm, "mesh_sample", _file_order_stride)
    monkeypatch.setattr(sl, "mesh_sample", _file_order_stride)
    d = np.linalg.norm(_points(build_specimen(shuffled, axes="project"))
                       - _points(build_specimen(project_meshes, axes="project")), axis=1)
    assert np.median(d) > 5e-5 and d.max() > 3e-4


def test_registration_follows_the_surface_not_its_sample(monkeypatch, project_meshes):
    """Two equally valid samples of the same target surface (the other half of its vertices) give nearly the same
    landmarks when the pairs pull along the surface normal onto the whole surface (register.TANGENTIAL = 0, the
    target's vertices as ``dense``); control: point-to-point pairs on the sample (the earlier registration) move them
    several times as far."""
    import lumbar.geometry.register as rg
    import lumbar.geometry.specimen_landmarks as sl

    def spread():
        pts = []
        for offset in (0, 1):
            def sample(mesh, n, offset=offset):
                _, idx = rg.mesh_sample(mesh, 2 * n)      # two disjoint halves of an area-even sample of 2n vertices
                idx = idx[offset::2]
                return np.asarray(mesh.vertices)[idx], idx
            monkeypatch.setattr(sl, "mesh_sample", sample)
            pts.append(_points(build_specimen(project_meshes, axes="project")))
        return float(np.median(np.linalg.norm(pts[0] - pts[1], axis=1)))

    sl.default_atlas()          # built (and cached for the session) with the package's own sample first
    near = spread()
    register = sl.register
    monkeypatch.setattr(rg, "TANGENTIAL", 1.0)
    monkeypatch.setattr(sl, "register", lambda X, Y, method="full", normals=None, dense=None:
                        register(X, Y, method=method, normals=normals))
    far = spread()
    print(f"median landmark distance between two samples: {1e3 * near:.2f} mm, point to point {1e3 * far:.2f} mm")
    assert near < 0.5e-3 and far > 2.0 * near


def test_lps_and_ras_inputs_agree(project_meshes, reference_specimen):
    tilt = _rot([1.0, 0.3, 0.0], 25.0)
    lps = build_specimen(_moved(project_meshes, _pose(LPS_FROM_PROJECT @ tilt, (0.01, 0.2, -0.9))), axes="LPS")
    ras = build_specimen(_moved(project_meshes, _pose(RAS_FROM_PROJECT @ tilt, (-0.05, 0.1, 0.3))), axes="RAS")
    assert _agree(_points(lps), _points(ras))
    assert _agree(_points(lps), _points(reference_specimen))
    assert lps.alignment.detected["angle_to_declared_deg"] == pytest.approx(25.0, abs=8.0)


def test_anterior_posterior_swapped_raises(project_meshes):
    ras_data = _moved(project_meshes, _pose(RAS_FROM_PROJECT))
    align_to_project(ras_data, axes="RAS")         # control: the right declaration passes
    with pytest.raises(GeometryError, match="anterior/posterior swapped"):
        align_to_project(ras_data, axes="LPS")


def test_declared_axes_contradicting_the_column_raise(project_meshes):
    # turned upside down about the antero-posterior axis: anterior still agrees, superior does not
    flipped = _moved(project_meshes, _pose(LPS_FROM_PROJECT @ _rot([1.0, 0, 0], 180.0)))
    with pytest.raises(GeometryError, match="contradict the anatomy"):
        align_to_project(flipped, axes="LPS")
    align_to_project(flipped, axes="any")          # control: without a declaration the anatomy decides


def test_mirrored_mesh_raises(project_meshes):
    mirrored = {v: m.copy() for v, m in project_meshes.items()}
    mirrored["L4"].vertices[:, 1] *= -1.0          # one axis flipped, faces not re-ordered
    with pytest.raises(GeometryError, match="L4 mesh.*wind inwards"):
        align_to_project(mirrored, axes="project")
    assert check_winding(project_meshes["L4"], "L4") > 0    # control: the original passes


def test_specimen_builds_a_unit_that_solves(reference_specimen):
    from lumbar.experiments.fsu import build_fsu, range_of_motion
    from lumbar.inputs.characteristics import resolve_characteristic_set
    geo = reference_specimen.geometry
    fsu = build_fsu(geo, resolve_characteristic_set("calibrated"), "L4-L5")
    df = range_of_motion(fsu, (10.0,))
    assert df["converged"].all() and df["valid"].all()
    assert (df["rom_deg"] > 0.5).all() and (df["rom_deg"] < 20).all()
    f = geo.levels["L4-L5"].facets["left"]
    assert f.contact == "touching" and len(f.contact_points) >= 9


def test_facet_space_range_is_the_sourced_one():
    mean, low, high = facet_space_range_m()
    assert mean == pytest.approx(1.93e-3) and low == pytest.approx(0.91e-3) and high == pytest.approx(2.95e-3)


def test_tables_round_trip_and_edits(reference_specimen, tmp_path):
    sp = reference_specimen                      # built from meshes in metres: input units "m"
    paths = write_tables(sp, tmp_path)
    df = pd.read_csv(paths["landmarks"])
    assert {"x_input", "y_input", "z_input", "extra_length_m", "rule", "source", "kind"} <= set(df.columns)
    back = read_landmark_table(paths["landmarks"], sp.meshes, sp.alignment, units="m")
    geo = geometry_from_table(back, sp)
    a, b = geo.levels["L4-L5"], sp.geometry.levels["L4-L5"]
    for la, lb in zip(a.ligaments, b.ligaments):
        assert np.abs(la.upper - lb.upper).max() < 1e-6 and np.abs(la.lower - lb.lower).max() < 1e-6
    # an edited copy: a point moved 5 mm off the bone is refused with its row and columns
    bad = df.copy()
    row = int(np.flatnonzero(bad["structure"] == "FL")[0])
    bad.loc[row, "x_m"] += 0.005
    bad[["x_input", "y_input", "z_input"]] = np.nan        # the input columns emptied: computed from x_m..
    bad.to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(GeometryError, match=f"data row {row + 1} column x_m,y_m,z_m: FL point"):
        read_landmark_table(tmp_path / "bad.csv", sp.meshes, sp.alignment, units="m")
    # project and input columns that disagree are refused; emptying one set is accepted
    bad = df.copy()
    bad.loc[row, "x_input"] += 0.003
    bad.to_csv(tmp_path / "bad2.csv", index=False)
    with pytest.raises(GeometryError, match="x_input,y_input,z_input: describes a point 3.00 mm"):
        read_landmark_table(tmp_path / "bad2.csv", sp.meshes, sp.alignment, units="m")
    # a point moved along the bone, edited in input coordinates only, is accepted and carried to the project frame
    moved = np.asarray(sp.meshes[df.loc[row, "body"]].vertices)[int(df.loc[row, "vertex_index"]) + 7]
    bad.loc[row, ["x_input", "y_input", "z_input"]] = sp.alignment.inverse(moved)[0]
    bad.loc[row, ["x_m", "y_m", "z_m"]] = np.nan
    bad.to_csv(tmp_path / "ok.csv", index=False)
    ok = read_landmark_table(tmp_path / "ok.csv", sp.meshes, sp.alignment, units="m")
    assert np.allclose(ok.loc[row, ["x_m", "y_m", "z_m"]].to_numpy(float), moved, atol=1e-9)
    bad = df.copy()
    bad.loc[row, "body"] = "L3"
    bad.to_csv(tmp_path / "bad3.csv", index=False)
    with pytest.raises(GeometryError, match="column body: 'L3'; expected L4 or L5"):
        read_landmark_table(tmp_path / "bad3.csv", sp.meshes, sp.alignment, units="m")
    levels = pd.read_csv(paths["levels"])
    assert {"disc_height_mm", "disc_csa_mm2", "facet_left_mean_p30", "facet_left_bone_gap_mm"} <= set(levels.columns)


def test_cli_writes_tables_and_figures(vh, tmp_path):
    from lumbar.cli import main
    write_posed_meshes(vh, ct_pose(3), tmp_path / "in", PAIR)
    assert main(["landmarks", str(tmp_path / "in"), "--units", "mm", "--axes", "LPS", "--out",
                 str(tmp_path / "out"), "--backend", "matplotlib"]) == 0
    for f in ("landmarks.csv", "levels.csv", "transform.json", "qa_L4-L5.png"):
        assert (tmp_path / "out" / f).stat().st_size > 0
    # control: the same files declared RAS are refused, naming the files
    assert main(["landmarks", str(tmp_path / "in"), "--units", "mm", "--axes", "RAS", "--out",
                 str(tmp_path / "out2"), "--backend", "none"]) == 2


def test_atlas_facet_grids_in_one_order(vh):
    """Every atlas level's 3x3 facet grid has its rows running superior and its columns anterior (in the face's
    plane), so the median over templates combines the same points; control: the loader's own grids do not."""
    from lumbar.geometry.specimen_landmarks import canonical_grid

    def directions(G):
        H = G.reshape(3, 3, 3)
        return (H[2] - H[0]).sum(0), (H[:, 2] - H[:, 0]).sum(0)

    raw_ok = []
    for lev in vh.levels.values():
        for f in lev.facets.values():
            for G in (f.superior, f.inferior):
                sup, ant = directions(canonical_grid(G))
                assert sup[2] > 0 and ant[0] > 0
                assert np.allclose(np.sort(canonical_grid(G), axis=0), np.sort(G, axis=0))   # the same points
                s0, a0 = directions(G)
                raw_ok.append(s0[2] > 0 and a0[0] > 0)
    assert not all(raw_ok)


def test_all_path_follows_the_targets_disc_height(vh):
    """The ALL's fibre length (segment + via-point path) scales with the target's own disc height: the lower vertebra
    moved 2 mm down lengthens it by the atlas's length/height ratio times the measured height change; control: the
    PLL (not scaled) keeps its length."""
    from lumbar.geometry.specimen_landmarks import SPANS, _fibre_rule, default_atlas, disc_height
    atlas = default_atlas()
    lev = vh.levels["L4-L5"]
    meshes = {v: vh.vertebrae[v].mesh for v in PAIR}
    taller = {"L4": meshes["L4"], "L5": meshes["L5"].copy().apply_translation([0.0, 0.0, -0.002])}
    h0, h1 = disc_height("L4-L5", meshes), disc_height("L4-L5", taller)
    assert h1 - h0 == pytest.approx(0.002, abs=3e-4)

    def total(name, m):
        lig = lev.ligament(name)
        u, lo, e = _fibre_rule(name, lig.upper, lig.lower, lig.extra_length, "L4-L5", m, atlas, exclude=PAIR)
        return float(np.mean(np.linalg.norm(u - lo, axis=1) + e))

    ratio = np.median([a / b for lv, (a, b) in atlas[SPANS]["ALL"].items() if not set(lv.split("-")) & set(PAIR)])
    assert total("ALL", meshes) == pytest.approx(ratio * h0, rel=1e-9)
    assert total("ALL", taller) - total("ALL", meshes) == pytest.approx(ratio * (h1 - h0), rel=1e-6)
    assert total("PLL", taller) == pytest.approx(total("PLL", meshes), rel=1e-12)


def test_process_fit_places_a_facet_face_moved_along_its_plane(vh):
    """The rigid fit of the articular process (lumbar.geometry.specimen_landmarks._process_fit) carries a facet grid
    onto a target vertebra that is the template moved by 1.5 mm (mostly along the face) with an identity warp: the
    grid lands where the move puts it (within 0.1 mm); control: with the fit off (radius 0) it stays 1.6 mm away."""
    from scipy.spatial import cKDTree

    from lumbar.geometry.specimen_landmarks import _process_fit
    mesh = vh.vertebrae["L5"].mesh
    grid = np.asarray(vh.levels["L4-L5"].facets["left"].superior)
    d = np.array([0.0005, 0.0014, 0.0003])
    target = np.asarray(mesh.vertices) + d
    tree = cKDTree(target)
    fitted = _process_fit(mesh, grid, lambda P: np.asarray(P, float), target, tree)
    assert np.linalg.norm(fitted - (grid + d), axis=1).max() < 1e-4
    unfitted = _process_fit(mesh, grid, lambda P: np.asarray(P, float), target, tree, radius=0.0)
    assert np.linalg.norm(unfitted.mean(0) - (grid + d).mean(0)) > 1.4e-3


@pytest.mark.parametrize("gap_mm, touching", [(1.5, False), (-0.5, True)])
def test_inferior_face_lies_on_the_joint_side_of_the_superior_face(gap_mm, touching):
    """Two blocks facing each other across z = 0 (lower block's top face: the superior face, outward normal +z): with
    a joint space the inferior face is the upper block's face across it (gap_mm above); with the blocks
    interpenetrating (upper block reaching 0.5 mm below the superior face) the closest upper-bone points lie behind the
    superior face and the faces touch: the inferior face is the superior one. Control: the parametrisation's other
    case gives the other answer."""
    import trimesh

    from lumbar.geometry.specimen_landmarks import _facing_face
    lower = trimesh.creation.box(extents=[0.02, 0.02, 0.01]).apply_translation([0, 0, -0.005])
    upper = trimesh.creation.box(extents=[0.03, 0.03, 0.01]).apply_translation([0, 0, 0.005 + 1e-3 * gap_mm])
    g = np.linspace(-0.003, 0.003, 3)
    sup = np.array([[x, y, 0.0] for x in g for y in g])
    inf = _facing_face(upper, lower, sup)
    if touching:
        assert np.array_equal(inf, sup)
    else:
        assert np.allclose(inf, sup + [0.0, 0.0, 1e-3 * gap_mm], atol=1e-9)


@pytest.fixture(scope="module")
def vh_accuracy():
    """The Visible Human meshes as a user gives them through the whole path, leave one out, scored at every level
    (seed 0), shared by the tests that read it (each ~8 s)."""
    return visible_human_accuracy(seed=0, length_level="all")


@pytest.mark.slow
def test_automatic_facet_contact_surfaces_face_the_joint(monkeypatch, vh, vh_accuracy):
    """Every facet contact surface of the automatic landmarks (Visible Human meshes as a user gives them, leave one
    out; lumbar.experiments.fsu.facet_surfaces) has its normal towards the joint's medial side (from the superior to
    the inferior process), as the reference's do; control: with the upper bone's closest points as the inferior face
    also where they lie behind the superior face (the meshes interpenetrate at the Visible Human facet joints) the
    surfaces are turned around (the facet then resists the wrong motions: no facet force in axial rotation)."""
    import lumbar.geometry.specimen_landmarks as sl
    from lumbar.experiments.fsu import facet_surfaces

    def medial_components(geo):
        return [float(surf.axes[2] @ [0.0, -1.0 if side == "left" else 1.0, 0.0])
                for lev in geo.levels.values() for side, _, surf in facet_surfaces(lev)]

    assert min(medial_components(vh)) > 0.5
    assert min(medial_components(vh_accuracy["specimen"].geometry)) > 0.5
    monkeypatch.setattr(sl, "_facing_face", lambda upper, lower, sup: sl._closest(upper, sup))
    assert min(medial_components(visible_human_accuracy(seed=0)["specimen"].geometry)) < 0


#: what the leave-one-out measurement reaches (docs/specimen.md, "Accuracy"), with a small margin
ACCURACY = dict(overall_median_mm=1.8, structure_median_mm=3.2, facet_bone_median_mm=0.9, facet_cartilage_median_mm=1.4,
                length_rel=0.15, every_level_length_rel=0.3, contact_normal_deg=30.0,
                anchored_median_mm={"ITL": 0.95, "SSL": 2.2, "ISL lower": 3.5})


@pytest.mark.slow
def test_accuracy_on_the_visible_human_set_leave_one_out(monkeypatch, vh_accuracy):
    r = vh_accuracy
    s = r["summary"].set_index("structure")
    assert s.loc["all ligament groups", "median_mm"] <= ACCURACY["overall_median_mm"]
    kinds = ["ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL"]
    assert (s.loc[kinds, "median_mm"] <= ACCURACY["structure_median_mm"]).all()
    assert s.loc["facet faces vs their bone points", "median_mm"] <= ACCURACY["facet_bone_median_mm"]
    assert s.loc["facet faces vs cartilage nodes", "median_mm"] <= ACCURACY["facet_cartilage_median_mm"]
    every = r["lengths"]
    assert set(every["level"]) == {"L1-L2", "L2-L3", "L3-L4", "L4-L5", "L5-S1"}
    # the via-point fibres at every level: the ALL's path follows each level's own disc height
    via = every[every["structure"].isin(["ALL", "PLL"])]
    assert len(via) == 10 and (via["relative_error"].abs() <= ACCURACY["length_rel"]).all()
    # every ligament's fibre length: within 15 % as the median over the five levels, within 30 % at every level
    # (known misses, docs/specimen.md: the capsule fibres have the other levels' length, -26 % at L4-L5; the ISL at
    # L4-L5 -22 % with its lower ends on the bone-feature anchor, at L3-L4 +32 % without)
    rel = every.pivot_table(index="structure", columns="level", values="relative_error").abs()
    assert (rel.median(axis=1) <= ACCURACY["length_rel"]).all(), rel.round(2)
    assert (rel <= ACCURACY["every_level_length_rel"]).all().all(), rel.round(2)
    # the bone-feature anchors (intertransverse, supraspinous, interspinous lower ends): medians between the anchored
    # (measured 0.81, 1.59 and 2.71 mm, seed 0) and the plain transfer's (1.03, 2.57 and 4.94 mm)
    g = r["groups"]
    for key, limit in ACCURACY["anchored_median_mm"].items():
        kind, _, end = key.partition(" ")
        sel = g[(g["kind"] == kind) & ((g["end"] == end) if end else True)]
        assert sel["centroid_error_mm"].median() <= limit, key
    # control: the atlas without the registration step (templates only moved onto the target's centroid)
    c = visible_human_accuracy(seed=0, method="translation")["summary"].set_index("structure")
    assert c.loc["all ligament groups", "median_mm"] > ACCURACY["overall_median_mm"]
    # control of the facet faces: without touching faces (the inferior face on the upper bone's closest points) they
    # miss the cartilage threshold (measured 1.64-1.66 mm, seeds 0-3; the rigid fit of the articular process moves
    # the faces by about 0.1 mm, docs/specimen.md, and has its own test:
    # test_process_fit_places_a_facet_face_moved_along_its_plane)
    # the orientation of the joints' Eq. 4 contact surfaces, which the centroid distances do not score: within
    # ACCURACY["contact_normal_deg"] of the reference's (measured 5.5-14.6 deg at L1-L5, 22-24 deg at L5-S1)
    assert (r["facets"]["contact_normal_angle_deg"] <= ACCURACY["contact_normal_deg"]).all()
    import lumbar.geometry.specimen_landmarks as sl
    monkeypatch.setattr(sl, "_facing_face", lambda upper, lower, sup: sl._closest(upper, sup))
    control = visible_human_accuracy(seed=0)
    f = control["summary"].set_index("structure")
    assert f.loc["facet faces vs cartilage nodes", "median_mm"] > ACCURACY["facet_cartilage_median_mm"]
    # ... and their contact surfaces are turned around (165-177 deg from the reference's)
    assert (control["facets"]["contact_normal_angle_deg"] > 90.0).any()


def test_bone_feature_anchor_follows_the_targets_own_process():
    """A specimen whose transverse processes are 5 mm longer than the atlas vertebra's (the Visible Human L3 with its
    vertices lateral of 25 mm moved outwards, leave one out): the intertransverse ends anchored on the transverse
    tip move outwards with it on both sides (at least 4 of the 5 mm); control: the plain transfer (no anchors) is
    carried by the smooth warp of the whole vertebra and falls more than 1.5 mm short on one side (measured 2.7 of
    5 mm on the left)."""
    import lumbar.geometry.specimen_landmarks as sl
    from lumbar.geometry.bone_features import feature_point
    atlas = sl.default_atlas()
    base = atlas["L3"]["mesh"]
    longer = base.copy()
    V = np.asarray(longer.vertices).copy()
    far = np.abs(V[:, 1]) > 0.025
    V[far, 1] += np.sign(V[far, 1]) * 0.005
    longer.vertices = V
    for s, sign in (("ITL_L", 1.0), ("ITL_R", -1.0)):   # the feature itself: the lateral end, 5 mm further out
        assert sign * (feature_point(longer, s, "upper") - feature_point(base, s, "upper"))[1] == pytest.approx(
            5e-3, abs=1e-4)
    moved = {}
    for anchored in ((), None):
        w0, w1 = {}, {}
        a = sl.transfer("L3", base, "upper", atlas, exclude=("L3",), warps=w0, anchored=anchored)
        b = sl.transfer("L3", longer, "upper", atlas, exclude=("L3",), warps=w1, anchored=anchored)
        moved[anchored] = {s: sign * (b[s]["points"] - a[s]["points"]).mean(0)[1]
                           for s, sign in (("ITL_L", 1.0), ("ITL_R", -1.0))}
        assert all((b[s]["anchor"] == "transverse_tip") == (anchored is None) for s in ("ITL_L", "ITL_R"))
    assert min(moved[None].values()) >= 4e-3, moved
    assert min(moved[()].values()) < 3.5e-3, moved


def test_fibre_lengths_follow_the_specimen_size(monkeypatch):
    """A specimen 20 % larger than the atlas (the Visible Human L4-L5 scaled, the truth with it): every L4-L5 fibre
    length keeps its relative error (measured, also at 0.8: within 0.5 percentage points for the fibres that keep the
    atlas's own vector, CL, ALL, PLL; ISL 4 points at 0.8), and the insertion-group distances scale with the size.
    Control: the atlas's fibre vectors at the atlas's size (no size ratio) make the capsule fibres of the larger
    specimen 12 points shorter, the error of a real specimen of another size than the Visible Human male's."""
    import lumbar.geometry.specimen_landmarks as sl

    def lengths(scale):
        r = visible_human_accuracy(seed=0, vertebrae=("L4", "L5"), scale=scale)
        return (r["lengths"].set_index("structure")["relative_error"],
                r["summary"].set_index("structure").loc["all ligament groups", "median_mm"])
    (base, d1), (big, d12) = lengths(1.0), lengths(1.2)
    kept = ["CL_L", "CL_R", "ALL", "PLL"]
    assert (big[kept] - base[kept]).abs().max() < 0.01
    assert (big - base).abs().max() < 0.03
    assert d12 == pytest.approx(1.2 * d1, rel=0.1)
    fixed = sl._fibre_rule
    monkeypatch.setattr(sl, "_fibre_rule", lambda *a, size=1.0, **k: fixed(*a, **k))
    control, _ = lengths(1.2)
    assert (control[["CL_L", "CL_R"]] - base[["CL_L", "CL_R"]]).min() < -0.1


def test_voxelise_keeps_the_volume_and_splits_an_overlap_by_depth():
    """The CT-like label map of closed surfaces: a voxel is a bone's when its centre is inside it, so the labelled
    volume is the surface's (a sphere, within 2 %; control: trimesh's voxelisation with its surface voxels filled
    grows it by half a voxel, > 10 %); a voxel inside two surfaces goes to the one it lies deeper in, so two boxes
    that overlap by 2 mm meet at the overlap's middle plane (a first- or last-wins rule puts the seam at one face of
    the overlap, 1 mm away); the affine maps a voxel index to its centre in world millimetres."""
    import trimesh

    from lumbar.geometry.specimen_accuracy import voxelise
    h = 0.5
    ball = trimesh.creation.icosphere(subdivisions=5, radius=6.0).apply_translation([30.0, -12.0, 400.0])
    labels, aff, values, contested = voxelise({"L4": ball}, h)
    assert contested == 0 and values == {"L4": 20}
    assert (labels == 20).sum() * h ** 3 == pytest.approx(ball.volume, rel=0.02)
    grown = ball.voxelized(pitch=h).fill()
    assert grown.matrix.sum() * h ** 3 > 1.1 * ball.volume                     # control: half a voxel all round
    ijk = np.round(np.linalg.solve(aff, np.r_[ball.centroid, 1.0])[:3]).astype(int)
    assert labels[tuple(ijk)] == 20
    q = h / 2 + 0.01                  # no voxel centre on a face: x 0.26..10.26 and 8.26..18.26
    a = trimesh.creation.box(extents=[10.0, 8.0, 8.0]).apply_translation([5.0 + q, q, q])
    b = trimesh.creation.box(extents=[10.0, 8.0, 8.0]).apply_translation([13.0 + q, q, q])
    labels, aff, values, contested = voxelise({"L4": a, "L5": b}, h)
    assert contested == 4 * 16 * 16                        # the overlap, 2 x 8 x 8 mm, in voxels of 0.5 mm
    ii = np.arange(labels.shape[0])
    x = aff[0, 0] * ii + aff[0, 3]
    mid = labels[:, labels.shape[1] // 2, labels.shape[2] // 2]
    assert x[mid == values["L4"]].max() < 9.0 + q < x[mid == values["L5"]].min()
    assert (mid == values["L4"]).sum() == (mid == values["L5"]).sum() == 18


@pytest.mark.slow
def test_landmarks_on_a_ct_label_map_of_the_visible_human_set():
    """The same bones as a CT segmentation gives them (posed in the scanner, voxelised at 1 mm in its axes, one
    multi-label NIfTI file, meshed by the label-volume path, leave one out): the landmarks keep the surface meshes'
    accuracy (measured, seeds 0-3: groups 1.43-1.51 mm, facet faces vs bone points 0.63-0.98 mm, vs cartilage nodes
    1.57-1.72 mm; docs/specimen.md); the facet faces within the issue's 2 mm of the cartilage nodes (median)."""
    from lumbar.geometry.specimen_accuracy import voxelised_accuracy, voxelised_tables
    r = voxelised_accuracy(1.0, seed=0)
    s = r["summary"].set_index("structure")
    assert s.loc["all ligament groups", "median_mm"] <= ACCURACY["overall_median_mm"]
    assert (s.loc[["ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL"], "median_mm"] <= ACCURACY["structure_median_mm"]).all()
    assert s.loc["facet faces vs their bone points", "median_mm"] <= 1.2
    assert s.loc["facet faces vs cartilage nodes", "median_mm"] <= 2.0
    assert r["contested_voxels"] > 0                       # the Visible Human bones interpenetrate at the facets
    assert list(r["meshing"]["level"]) == ["L1", "L2", "L3", "L4", "L5", "S1"]
    table, faces = voxelised_tables(s.reset_index(), {1.0: r})
    assert list(table["input"].unique()) == ["surface meshes", "label volume"] and len(faces) == 18
    # 1 mm voxels do not resolve the facet joint space (half of its sourced lower bound): said, not hidden
    assert not table.loc[table["input"] == "label volume", "facet_surfaces_supported"].iloc[0]


def test_rbf_kernel_fast_form_equals_the_direct_distances():
    """The registration's Gaussian kernel by one matrix product agrees with the direct (n, k, 3) form, at the project
    frame's offsets (coordinates 0.1-0.2 m from the origin, where |p|^2 + |c|^2 - 2 p.c would cancel badly without
    the centring); a width change shows (the control)."""
    from lumbar.geometry.register import _kernel
    rng = np.random.default_rng(5)
    P = rng.normal(size=(400, 3)) * 0.02 + [0.05, -0.01, 0.18]
    C = rng.normal(size=(60, 3)) * 0.02 + [0.05, -0.01, 0.18]
    for s in (0.006, 0.010, 0.016):
        direct = np.exp(-0.5 * ((P[:, None, :] - C[None, :, :]) ** 2).sum(-1) / s**2)
        np.testing.assert_allclose(_kernel(P, C, s), direct, rtol=0, atol=1e-13)
    assert np.abs(_kernel(P, C, 0.010) - _kernel(P, C, 0.011)).max() > 1e-3
