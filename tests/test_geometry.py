"""Tests of lumbar.geometry: frame, disc measures, ligaments, facets, input validation."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh
from scipy.spatial import cKDTree

from lumbar.geometry import GeometryError, LEVEL_NAMES, load_geometry
from lumbar.geometry.landmarks import COLUMNS, default_csv_path, propose_landmarks
from lumbar.geometry.meshio import read_mesh

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared"
VH = SHARED / "geometry" / "visible_human_lss"
LUMBAR = ("L1", "L2", "L3", "L4", "L5")


def _vh_path():
    if not VH.is_dir():
        pytest.skip(f"shared Visible Human geometry not found at {VH}")
    return VH


@pytest.fixture(scope="module")
def myo():
    return load_geometry("default")


@pytest.fixture(scope="module")
def vh():
    return load_geometry("visible_human", path=_vh_path())


@pytest.fixture(params=["myo", "vh"])
def geo(request):
    return request.getfixturevalue(request.param)


def _dist_to_mesh(mesh, pts):
    _, d, _ = trimesh.proximity.closest_point(mesh, np.atleast_2d(pts))
    return d


# ---------------------------------------------------------------- frame
def test_all_levels_present(geo):
    assert list(geo.levels) == list(LEVEL_NAMES)
    assert set(geo.vertebrae) == {"L1", "L2", "L3", "L4", "L5", "S1"}


def test_frame_spinous_process_posterior_and_vertical_order(geo):
    zs = []
    for v in LUMBAR:
        vert = geo.vertebrae[v]
        pts = vert.mesh.vertices
        tip = pts[np.argmin(pts[:, 0])]                 # most posterior point
        assert abs(tip[1] - vert.centroid[1]) < 0.006, f"{v}: most posterior point not midline (spinous tip)"
        assert tip[0] < vert.centroid[0] - 0.03, f"{v}: spinous process not at -x"
        assert pts[:, 0].max() - vert.centroid[0] < 0.03   # body anterior, within ~3 cm of its centroid
        zs.append(vert.centroid[2])
    assert np.all(np.diff(zs) < -0.02), "L1..L5 must descend in z (L4 above L5)"
    assert geo.vertebrae["L4"].centroid[2] > geo.vertebrae["L5"].centroid[2] > geo.vertebrae["S1"].centroid[2]


def test_frame_left_right_facets(geo):
    for name, lev in geo.levels.items():
        for surf in ("superior", "inferior"):
            left = getattr(lev.facets["left"], surf)
            right = getattr(lev.facets["right"], surf)
            assert left.shape == (9, 3) and right.shape == (9, 3)
            assert np.all(left[:, 1] > 0.004), f"{name} left {surf} facet not at +y"
            assert np.all(right[:, 1] < -0.004), f"{name} right {surf} facet not at -y"
            # mirror symmetry in y (both sources are near-symmetric)
            assert abs(left[:, 1].mean() + right[:, 1].mean()) < 0.004
            assert abs(left[:, 2].mean() - right[:, 2].mean()) < 0.004
            assert len(np.unique(np.round(left, 6), axis=0)) == 9
        # facets posterior to the disc, superior surface on the lower vertebra, inferior on the upper
        f = lev.facets["left"]
        assert f.superior[:, 0].mean() < lev.disc_centre[0] - 0.015
        du = _dist_to_mesh(geo.vertebrae[lev.upper].mesh, f.inferior)
        dl = _dist_to_mesh(geo.vertebrae[lev.lower].mesh, f.superior)
        # VH cartilage node sheets sit up to ~3 mm inside the shrink-wrapped vertebra meshes (3.04 mm at L3-L4)
        assert du.max() < 0.0035 and dl.max() < 0.0035, name
        # lumbar anatomy: the upper vertebra's inferior articular face lies medial to the lower one's superior face
        for side in ("left", "right"):
            fs = lev.facets[side]
            if geo.name == "visible_human":     # (the myo-sim landmarks are hand-placed point sets)
                assert np.abs(fs.inferior[:, 1]).mean() < np.abs(fs.superior[:, 1]).mean(), (name, side)


def test_myo_frame_matches_mujoco_compile(myo):
    mujoco = pytest.importorskip("mujoco")
    import xml.etree.ElementTree as ET
    from lumbar.geometry import myo_sim as ms
    root = ms.package_root() / "models"
    a = ET.parse(root / "torso/assets/myotorso_assets.xml").getroot()
    defaults = "".join(ET.tostring(e, encoding="unicode") for e in a if e.tag == "default")
    defaults = defaults.replace('material="mat_myotorso"', "").replace('material="MatSkin_myotorso"', "")
    assets = "<asset>" + "".join(ET.tostring(e, encoding="unicode") for e in a.find("asset")
                                 if e.tag == "mesh" and ("lumbar" in e.get("name") or "sacrum" in e.get("name"))) + "</asset>"
    c = ET.parse(root / "torso/assets/myotorso_chain.xml").getroot()
    sac = next(b for b in c.iter("body") if b.get("name") == "sacrum")

    def strip(b):
        for ch in list(b):
            if ch.tag == "body":
                strip(ch)
            elif not (ch.tag == "inertial" or (ch.tag == "geom" and ch.get("type") == "mesh"
                                                and ("lumbar" in ch.get("mesh") or "sacrum" in ch.get("mesh")))):
                b.remove(ch)
    strip(sac)
    xml = (f'<mujoco><compiler angle="radian" meshdir="{root}"/>{defaults}{assets}<worldbody>'
           f'{ET.tostring(sac, encoding="unicode")}</worldbody></mujoco>')
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for v, body in ms.BODY_OF.items():
        gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, body + "_geom_1")
        mid = m.geom_dataid[gid]
        verts = m.mesh_vert[m.mesh_vertadr[mid]:m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
        world = verts @ d.geom_xmat[gid].reshape(3, 3).T + d.geom_xpos[gid]
        proj = world @ ms.R_PROJECT_FROM_WORLD.T
        ours = myo.vertebrae[v].mesh.vertices
        assert np.abs(np.sort(proj, axis=0) - np.sort(ours, axis=0)).max() < 1e-6, v


# ---------------------------------------------------------------- disc
def test_disc_measures_plausible(geo):
    for name, lev in geo.levels.items():
        assert np.isclose(np.linalg.norm(lev.disc_normal), 1.0)
        assert lev.disc_normal[2] > 0.8, f"{name} disc normal must point superior"
        assert 0.005 <= lev.disc_height <= 0.015, f"{name} disc height {lev.disc_height}"
        assert 8e-4 <= lev.disc_csa <= 2.5e-3, f"{name} disc CSA {lev.disc_csa}"
        up, lo = geo.vertebrae[lev.upper].centroid, geo.vertebrae[lev.lower].centroid
        assert lo[2] < lev.disc_centre[2] < up[2]
    l45 = geo.levels["L4-L5"]
    assert 1.0e-3 <= l45.disc_csa <= 2.0e-3   # 10-20 cm^2 adult L4-L5


def test_myo_landmark_csv_is_reproducible():
    from lumbar.geometry import myo_sim
    committed = pd.read_csv(default_csv_path())
    fresh = propose_landmarks(myo_sim.load_raw_meshes())
    assert list(committed.columns) == COLUMNS
    assert len(committed) == len(fresh)
    assert np.allclose(committed[["x_m", "y_m", "z_m"]].to_numpy(), fresh[["x_m", "y_m", "z_m"]].to_numpy(), atol=2e-6)
    assert (committed["kind"] == "derived_from_geometry").all()


# ---------------------------------------------------------------- ligaments
EXPECTED = {"ALL", "PLL", "FL", "CL_L", "CL_R", "ISL", "SSL", "ITL_L", "ITL_R"}


def test_ligament_ends_on_their_vertebrae_and_lengths(geo):
    def dist(v, pts):
        mesh = geo.vertebrae[v].mesh
        if len(mesh.vertices) > 5000:     # dense (VH): vertex distance is accurate and fast
            return cKDTree(mesh.vertices).query(pts)[0]
        return _dist_to_mesh(mesh, pts)

    for name, lev in geo.levels.items():
        assert {g.name for g in lev.ligaments} == EXPECTED
        for lig in lev.ligaments:
            assert lig.kind in {"ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL"}
            assert lig.upper.shape == lig.lower.shape == (lig.n_fibres, 3)
            du, dul = dist(lev.upper, lig.upper), dist(lev.lower, lig.upper)
            dl, dlu = dist(lev.lower, lig.lower), dist(lev.upper, lig.lower)
            # via-point fibres (ALL/PLL of VH) keep the disc-crossing segment, whose ends sit at the disc
            # surface, i.e. up to about half a disc height from the bone
            tol = 0.004 + (0.6 * lev.disc_height if lig.extra_length.any() else 0.0)
            assert du.max() < tol, f"{name} {lig.name}: upper end {du.max() * 1e3:.1f} mm from {lev.upper}"
            assert dl.max() < tol, f"{name} {lig.name}: lower end {dl.max() * 1e3:.1f} mm from {lev.lower}"
            if not lig.extra_length.any():    # via-point ends near the disc are checked by the mid-disc test
                # the (upper, lower) assignment fits better than the swapped one, fibre by fibre
                assert np.all(du + dl <= dul + dlu + 1e-9), f"{name} {lig.name} ends swapped"
            L = lig.lengths
            assert np.all(L > 0) and np.all(lig.extra_length >= 0)
            if lig.kind in ("ALL", "PLL"):
                assert np.all((L > 0.005) & (L < 0.04)), f"{name} {lig.name} lengths {L}"
                # the anterior ligament is anterior of the disc centre, the posterior one posterior
                sgn = 1 if lig.kind == "ALL" else -1
                assert np.all(sgn * (lig.upper[:, 0] - lev.disc_centre[0]) > 0.005)
            if lig.kind in ("ISL", "SSL"):
                assert np.all((L > 0.005) & (L < 0.06)), f"{name} {lig.name} lengths {L}"
            if lig.kind == "CL":
                assert lig.n_fibres >= 4
                sgn = 1 if lig.name == "CL_L" else -1
                assert np.all(sgn * lig.upper[:, 1] > 0)
        assert lev.ligament("ALL").n_fibres >= 3 and lev.ligament("SSL").n_fibres >= 1


def test_vh_via_point_ligaments_have_extra_length(vh):
    for lev in vh.levels.values():
        for nm in ("ALL", "PLL"):
            lig = lev.ligament(nm)
            assert np.all(lig.extra_length > 0.002)
            # upper end above, lower end below the mid-disc plane
            assert np.all((lig.upper - lev.disc_centre) @ lev.disc_normal > 0)
            assert np.all((lig.lower - lev.disc_centre) @ lev.disc_normal < 0)


def test_centroid_is_vertebral_body(geo):
    for v in LUMBAR:
        vert = geo.vertebrae[v]
        whole = vert.mesh.vertices.mean(axis=0)
        assert vert.centroid[0] > whole[0] + 0.005, f"{v}: centroid not anterior (body) part"


def test_levels_subset_and_cache_fast():
    import time
    t = time.perf_counter()
    g = load_geometry("myo_sim", levels=["L4-L5"])
    assert list(g.levels) == ["L4-L5"] and set(g.vertebrae) == {"L4", "L5"}
    assert time.perf_counter() - t < 5


# ---------------------------------------------------------------- bad input
def _copy_vh_l45(tmp_path):
    src = _vh_path()
    dst = tmp_path / "vh"
    for sub in ("meshes", "ligaments", "disc_fe", "facet_fe"):
        (dst / sub).mkdir(parents=True)
    for f in ("L4_vertebra.obj", "L4_body.obj", "L5_vertebra.obj", "L5_body.obj"):
        shutil.copy(src / "meshes" / f, dst / "meshes" / f)
    for sub, pat in (("ligaments", "L45_Ligs_*.lig"), ("disc_fe", "L45_*.node"), ("facet_fe", "L45_FAC?_L4.node")):
        for f in (src / sub).glob(pat):
            shutil.copy(f, dst / sub / f.name)
    return dst


def test_copied_vh_level_loads(tmp_path):
    g = load_geometry("visible_human", path=_copy_vh_l45(tmp_path), levels=["L4-L5"])
    assert g.levels["L4-L5"].ligament("FL").n_fibres == 11


def test_reject_missing_directory(tmp_path):
    with pytest.raises(GeometryError, match="directory missing"):
        load_geometry("visible_human", path=tmp_path / "nope")


def test_reject_missing_mesh(tmp_path):
    d = _copy_vh_l45(tmp_path)
    (d / "meshes" / "L5_vertebra.obj").unlink()
    with pytest.raises(GeometryError, match="L5_vertebra.obj"):
        load_geometry("visible_human", path=d, levels=["L4-L5"])


def test_reject_mesh_in_millimetres(tmp_path):
    d = _copy_vh_l45(tmp_path)
    m = trimesh.load(d / "meshes" / "L4_vertebra.obj", force="mesh")
    m.apply_scale(1000.0)
    m.export(d / "meshes" / "L4_vertebra.obj")
    with pytest.raises(GeometryError, match="looks like millimetres, expected metres") as e:
        load_geometry("visible_human", path=d, levels=["L4-L5"])
    assert "L4_vertebra.obj" in str(e.value)


def test_reject_mesh_in_millimetres_standalone(tmp_path):
    p = tmp_path / "box.stl"
    trimesh.creation.box(extents=[40.0, 50.0, 30.0]).export(p)
    with pytest.raises(GeometryError, match="millimetres"):
        read_mesh(p)


def test_reject_unreadable_mesh(tmp_path):
    p = tmp_path / "bad.stl"
    p.write_text("this is not a mesh\n")
    with pytest.raises(GeometryError, match="bad.stl"):
        read_mesh(p)


def test_malformed_lig_line(tmp_path):
    d = _copy_vh_l45(tmp_path)
    f = d / "ligaments" / "L45_Ligs_AS.lig"
    lines = f.read_text().splitlines()
    lines[4] = "-0.011602, -0.016498, 0.051319, -0.010820, -0.018837"   # 5 numbers instead of 6
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(GeometryError, match=r"L45_Ligs_AS\.lig: line 5 .*expected 6 numbers"):
        load_geometry("visible_human", path=d, levels=["L4-L5"])


def test_bad_lig_header(tmp_path):
    d = _copy_vh_l45(tmp_path)
    f = d / "ligaments" / "L45_Ligs_MP.lig"
    lines = f.read_text().splitlines()
    lines[1] = "L45_ALL; 9; 7"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(GeometryError, match=r"L45_Ligs_MP\.lig: line 2: expected header 'NAME, n_fibres, n_points'"):
        load_geometry("visible_human", path=d, levels=["L4-L5"])


def test_reject_landmark_off_surface(tmp_path):
    df = pd.read_csv(default_csv_path())
    i = int(np.flatnonzero((df["level"] == "L4-L5") & (df["structure"] == "ALL"))[0])
    df.loc[i, "x_m"] += 0.005                    # 5 mm anterior, off the bone
    p = tmp_path / "lm.csv"
    df.to_csv(p, index=False)
    with pytest.raises(GeometryError, match=rf"lm\.csv: row {i + 1} .*x_m,y_m,z_m.*mm from the L4 mesh"):
        load_geometry("default", path=p)


def test_bad_landmark_csv_missing_column(tmp_path):
    df = pd.read_csv(default_csv_path()).drop(columns=["z_m"])
    p = tmp_path / "lm.csv"
    df.to_csv(p, index=False)
    with pytest.raises(GeometryError, match=r"lm\.csv: missing column\(s\) \['z_m'\]"):
        load_geometry("default", path=p)


def test_reject_unknown_kind_and_level():
    with pytest.raises(GeometryError, match="unknown geometry kind"):
        load_geometry("nope")
    with pytest.raises(GeometryError, match="unknown level"):
        load_geometry("default", levels=["L4-L6"])


@pytest.mark.parametrize("angle", [0.0, 30.0, 60.0, 90.0])
def test_facet_sagittal_angle_of_a_known_plane(angle):
    """Landmarks on a plane whose normal lies in the transverse plane at ``angle`` from the lateral axis: a joint
    plane ``angle`` from the sagittal plane (0 = sagittal facets, 90 = coronal), whatever the sign of the normal."""
    from types import SimpleNamespace

    from lumbar.geometry.analysis import facet_sagittal_angle_deg
    a = np.radians(angle)
    n = np.array([np.sin(a), np.cos(a), 0.0])                       # joint normal
    e1 = np.array([0.0, 0.0, 1.0])                                   # superior, in the plane
    e2 = np.cross(n, e1)
    rng = np.random.default_rng(1)
    uv = rng.uniform(-0.01, 0.01, (18, 2))
    P = np.array([0.03, 0.02, 0.05]) + uv[:, :1] * e1 + uv[:, 1:] * e2 + rng.normal(0, 1e-5, (18, 1)) * n
    facet = SimpleNamespace(superior=P[:9], inferior=P[9:])
    assert facet_sagittal_angle_deg(facet) == pytest.approx(angle, abs=0.2)
    flipped = SimpleNamespace(superior=-P[:9], inferior=-P[9:])       # mirrored: the same orientation
    assert facet_sagittal_angle_deg(flipped) == pytest.approx(angle, abs=0.2)
