"""A user's specimen geometry (lumbar.geometry.specimen_io): a folder of vertebra surfaces or a CT label volume in,
validated meshes out; every kind of bad input a GeometryError naming the file (or level) before any long step."""
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lumbar.geometry import specimen_io as S
from lumbar.geometry.core import GeometryError

ROOT = Path(__file__).resolve().parents[1]
VH_MESHES = ROOT / "data" / "geometry" / "visible_human_lss" / "meshes"
TS_MASKS = ROOT / "tests" / "data" / "totalsegmentator_example"

# synthetic specimen: ellipsoids of a lumbar vertebral body's size (mm), centres 38 mm apart along +z (13 mm gaps)
SIZE_MM = np.array([40.0, 50.0, 25.0])
PITCH_MM = 38.0
LEVELS3 = ("L4", "L5", "S1")


def ellipsoid(z_mm=0.0, subdivisions=4):
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    m.apply_scale(SIZE_MM / 2)
    m.apply_translation([0.0, 0.0, z_mm])
    return m


def write_folder(folder: Path, levels=LEVELS3, name="spec_{level}.stl"):
    folder.mkdir(parents=True, exist_ok=True)
    for i, lv in enumerate(levels):
        ellipsoid(-PITCH_MM * i).export(folder / name.format(level=lv))
    return folder


# ------------------------------------------------------------------ file names and levels
def test_level_tokens():
    assert S.level_of("L4.stl") == ["L4"]
    assert S.level_of("vertebrae_L4.stl") == ["L4"]
    assert S.level_of("spec12_L4.ply") == ["L4"]
    assert S.level_of("sacrum.obj") == ["S1"]
    assert S.level_of("L4-L5_disc.stl") == ["L4", "L5"]
    # controls: a level inside a longer word or number is no token
    assert S.level_of("L45.stl") == [] and S.level_of("TL4.stl") == [] and S.level_of("pelvis.stl") == []


def test_find_level_files_reads_names_and_ignores_volumes(tmp_path):
    for n in ("L3.stl", "vertebrae_L4.obj", "spec12_L5.ply", "sacrum.stl", "vertebrae_L4.nii.gz", "notes.txt"):
        (tmp_path / n).write_bytes(b"x")
    got = S.find_level_files(tmp_path)
    assert {k: v.name for k, v in got.items()} == {"L3": "L3.stl", "L4": "vertebrae_L4.obj",
                                                    "L5": "spec12_L5.ply", "S1": "sacrum.stl"}


def test_several_surfaces_per_level_need_a_pattern(tmp_path):
    for n in ("L4_body.obj", "L4_vertebra.obj", "L5_body.obj", "L5_vertebra.obj"):
        (tmp_path / n).write_bytes(b"x")
    with pytest.raises(GeometryError, match=r"L4_body\.obj, L4_vertebra\.obj") as e:
        S.find_level_files(tmp_path)
    assert "pattern" in str(e.value)
    got = S.find_level_files(tmp_path, pattern="{level}_vertebra.obj")
    assert {k: v.name for k, v in got.items()} == {"L4": "L4_vertebra.obj", "L5": "L5_vertebra.obj"}
    with pytest.raises(GeometryError, match="several"):          # a pattern that still matches two files
        S.find_level_files(tmp_path, pattern="{level}_*.obj")
    with pytest.raises(GeometryError, match=r"\{level\}"):
        S.find_level_files(tmp_path, pattern="vertebra.obj")


def test_folder_of_volumes_points_to_the_mesher(tmp_path):
    (tmp_path / "vertebrae_L4.nii.gz").write_bytes(b"x")
    with pytest.raises(GeometryError, match="label_volume_to_meshes"):
        S.find_level_files(tmp_path)


# ------------------------------------------------------------------ reading: units, formats, axes
@pytest.mark.parametrize("units,factor", [("mm", 1.0), ("m", 1e-3)])
def test_units_round_trip(tmp_path, units, factor):
    folder = tmp_path / "spec"
    folder.mkdir()
    for i, lv in enumerate(LEVELS3):
        m = ellipsoid(-PITCH_MM * i)
        m.apply_scale(factor)                              # the file in the declared unit
        m.export(folder / f"{lv}.stl")
    got = S.read_specimen_meshes(folder, units=units, axes="RAS")
    assert list(got) == list(LEVELS3)
    ref = ellipsoid(0.0)
    for i, lv in enumerate(LEVELS3):
        # STL stores float32: equal to 1e-6
        np.testing.assert_allclose(got[lv].extents, ref.extents * 1e-3, rtol=1e-6)
        np.testing.assert_allclose(got[lv].center_mass, [0, 0, -PITCH_MM * i * 1e-3], atol=1e-8)
    other = "m" if units == "mm" else "mm"                 # control: the other unit is refused, naming the file
    with pytest.raises(GeometryError, match=rf"L4\.stl.*units={other!r}"):
        S.read_specimen(folder, units=other)


def test_formats_give_the_same_mesh(tmp_path):
    import pyvista

    ref = ellipsoid(0.0, subdivisions=3)
    vols = {}
    for ext in ("stl", "obj", "ply", "vtp", "vtk"):
        d = tmp_path / ext
        d.mkdir()
        if ext in ("vtp", "vtk"):
            faces = np.column_stack([np.full(len(ref.faces), 3), ref.faces]).ravel()
            pyvista.PolyData(np.asarray(ref.vertices), faces).save(d / f"L4.{ext}")
        else:
            ref.export(d / f"L4.{ext}")
        vols[ext] = S.read_specimen_meshes(d)["L4"].volume
    np.testing.assert_allclose(list(vols.values()), ref.volume * 1e-9, rtol=1e-6)


def test_units_and_axes_are_validated(tmp_path):
    write_folder(tmp_path)
    with pytest.raises(GeometryError, match="units 'cm'"):
        S.read_specimen(tmp_path, units="cm")
    with pytest.raises(GeometryError, match="axes 'XYZ'.*LPS.*RAS.*project"):
        S.read_specimen(tmp_path, axes="XYZ")
    for axes in S.AXES:                                    # control: the three named frames are accepted
        assert S.read_specimen(tmp_path, axes=axes).axes == axes


# ------------------------------------------------------------------ closed surfaces
def punch(mesh, n_faces):
    """The mesh without the n faces nearest its top (+z) point: a hole there."""
    top = mesh.vertices[np.argmax(mesh.vertices[:, 2])]
    order = np.argsort(np.linalg.norm(mesh.triangles_center - top, axis=1))
    keep = np.ones(len(mesh.faces), bool)
    keep[order[:n_faces]] = False
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)


def test_small_hole_filled_and_logged(tmp_path):
    write_folder(tmp_path)
    closed = S.read_specimen(tmp_path)
    assert closed.repairs == []                            # control: a closed folder needs no repair
    punch(ellipsoid(0.0), 6).export(tmp_path / "spec_L4.stl")
    r = S.read_specimen(tmp_path)
    assert [x.level for x in r.repairs] == ["L4"] and "filled 1 hole" in r.repairs[0].what
    assert r.meshes["L4"].is_watertight
    # the fan fill is nearly flat over a 6-triangle hole: volume within 0.1 % of the closed surface's
    np.testing.assert_allclose(r.meshes["L4"].volume, closed.meshes["L4"].volume, rtol=1e-3)


def test_large_hole_refused(tmp_path):
    write_folder(tmp_path)
    punch(ellipsoid(0.0), 400).export(tmp_path / "spec_L4.stl")
    with pytest.raises(GeometryError, match=r"spec_L4\.stl: L4 surface is not closed"):
        S.read_specimen(tmp_path)
    # control: the same hole passes when the fill limit admits it
    assert S.read_specimen(tmp_path, max_hole_m=1.0).repairs[0].level == "L4"


def test_orientation_and_repeated_faces_repaired_and_logged(tmp_path):
    write_folder(tmp_path)
    m = ellipsoid(0.0)
    faces = m.faces.copy()
    faces[:10] = faces[:10, ::-1]                           # ten triangles turned
    trimesh.Trimesh(m.vertices, faces, process=False).export(tmp_path / "spec_L4.stl")
    inv = ellipsoid(-PITCH_MM)
    inv.invert()                                            # the whole surface wound inwards
    inv.export(tmp_path / "spec_L5.stl")
    # declared axes: turned outwards, logged (the anatomy is checked against the axes when the frame is found)
    r = S.read_specimen(tmp_path)
    log = {lv: " | ".join(x.what for x in r.repairs if x.level == lv) for lv in LEVELS3}
    kinds = {lv: [x.kind for x in r.repairs if x.level == lv] for lv in LEVELS3}
    assert "orientation" in log["L4"] and "wound inwards" in log["L5"] and "declared axes LPS" in log["L5"]
    assert kinds["L5"] == ["inside_out"] and kinds["S1"] == [] and r.turned == ["L5"]
    for lv in ("L4", "L5"):
        assert r.meshes[lv].is_winding_consistent and r.meshes[lv].volume > 0
        np.testing.assert_allclose(r.meshes[lv].volume, m.volume * 1e-9, rtol=1e-6)
    # no declared axes: nothing can show a mirror, so refused unless the user states the coordinates are not mirrored
    with pytest.raises(GeometryError, match=r"spec_L5\.stl: L5 surface is inside-out.*axes are 'any'.*--turn-inside-out"):
        S.read_specimen(tmp_path, axes="any")
    r = S.read_specimen(tmp_path, axes="any", turn_inside_out=True)
    assert r.turned == ["L5"] and "turn_inside_out" in [x.what for x in r.repairs if x.level == "L5"][0]


def test_empty_and_unreadable_files(tmp_path):
    write_folder(tmp_path)
    (tmp_path / "spec_L5.stl").write_bytes(b"")
    with pytest.raises(GeometryError, match=r"spec_L5\.stl.*empty"):
        S.read_specimen(tmp_path)
    (tmp_path / "spec_L5.stl").write_text("solid x\nnot an stl\n")
    with pytest.raises(GeometryError, match=r"spec_L5\.stl"):
        S.read_specimen(tmp_path)


# ------------------------------------------------------------------ levels and neighbours
def test_missing_level_between_and_required(tmp_path):
    write_folder(tmp_path, ("L3", "L4", "L5"))
    (tmp_path / "spec_L4.stl").unlink()
    ellipsoid(-PITCH_MM).export(tmp_path / "spec_L4.stl")        # control first: L3, L4, L5 read
    assert S.read_specimen(tmp_path, require="L4-L5").levels == ["L3", "L4", "L5"]
    with pytest.raises(GeometryError, match="S1 required but missing"):
        S.read_specimen(tmp_path, require=["L5-S1"])
    (tmp_path / "spec_L4.stl").unlink()
    with pytest.raises(GeometryError, match="L4 missing between L3 and L5"):
        S.read_specimen(tmp_path)


@pytest.mark.parametrize("shift_mm,what", [((100.0, 0, 0), "apart"), ((0, 0, -0.6 * PITCH_MM), "overlap"),
                                          ((0, 0, -2 * PITCH_MM - 3), "apart|overlap|not above")])
def test_neighbour_checks(tmp_path, shift_mm, what):
    write_folder(tmp_path)
    assert S.read_specimen(tmp_path).levels == list(LEVELS3)       # control: the unshifted folder passes
    ellipsoid(0.0).apply_translation(shift_mm).export(tmp_path / "spec_L4.stl")
    with pytest.raises(GeometryError, match=what) as e:
        S.read_specimen(tmp_path)
    assert "spec_L4.stl" in str(e.value)


def test_stacked_upside_down_refused(tmp_path):
    write_folder(tmp_path, ("S1", "L5", "L4"))                     # S1 on top: +z not superior
    with pytest.raises(GeometryError, match="not above.*axes 'any'"):
        S.read_specimen(tmp_path)
    # a specimen at any angle in the scanner, declared as such: read (the anatomy orients it, specimen.py);
    # the other checks stay: a vertebra moved 100 mm away is still refused
    assert S.read_specimen(tmp_path, axes="any").levels == list(LEVELS3)
    ellipsoid(-PITCH_MM - 100.0).export(tmp_path / "spec_L5.stl")
    with pytest.raises(GeometryError, match="apart"):
        S.read_specimen(tmp_path, axes="any")


def test_visible_human_meshes_read_with_pattern():
    with pytest.raises(GeometryError, match="L4_body.obj, L4_vertebra.obj"):
        S.find_level_files(VH_MESHES)
    r = S.read_specimen(VH_MESHES, units="m", axes="project", pattern="{level}_vertebra.obj")
    assert r.levels == ["L1", "L2", "L3", "L4", "L5", "S1"] and r.repairs == []
    # control: the same files declared in millimetres are 1000 times too small
    with pytest.raises(GeometryError, match=r"L1_vertebra\.obj.*units='m'"):
        S.read_specimen(VH_MESHES, units="mm", pattern="{level}_vertebra.obj")


# ------------------------------------------------------------------ what the levels allow
def test_skipped_stages():
    assert S.skipped_stages(["L1", "L2", "L3", "L4", "L5", "S1"]) == []
    no_s1 = dict(S.skipped_stages(["L1", "L2", "L3", "L4", "L5"]))
    assert set(no_s1) == {"l2s1", "muscle_model", "load_sharing.other_levels L5-S1"}
    assert "no sacrum" in no_s1["l2s1"] and "L2-S1" in no_s1["l2s1"]
    no_l45 = dict(S.skipped_stages(["L1", "L2", "L3"]))
    assert {"fsu", "stepwise_reduction", "calibration"} <= set(no_l45)
    assert "fsu.level" in no_l45["calibration"] and "L1-L2" in no_l45["calibration"]
    assert dict(S.skipped_stages(["L1", "L2", "L3"], calibrated_level="L2-L3")).keys().isdisjoint({"fsu"})
    assert S.buildable_units(["L4", "L5", "S1"]) == ["L4-L5", "L5-S1"]


# ------------------------------------------------------------------ label volumes
@pytest.fixture(scope="module")
def ts_meshes(tmp_path_factory):
    out = tmp_path_factory.mktemp("ts_meshes")
    return out, S.label_volume_to_meshes(TS_MASKS, out)


def test_label_masks_meshed_in_world_coordinates(ts_meshes):
    import nibabel

    out, written = ts_meshes
    assert {k: v.name for k, v in written.items()} == {"L4": "L4.stl", "L5": "L5.stl", "S1": "S1.stl"}
    r = S.read_specimen(out, units="mm", axes="RAS")
    assert r.levels == ["L4", "L5", "S1"] and r.repairs == []
    for lv, f in (("L4", "vertebrae_L4.nii.gz"), ("L5", "vertebrae_L5.nii.gz"), ("S1", "sacrum.nii.gz")):
        img = nibabel.load(TS_MASKS / f)
        mask = np.asarray(img.dataobj) > 0.5
        ijk = np.argwhere(mask)
        voxel_ml = abs(np.linalg.det(img.affine[:3, :3])) * 1e-9
        # marching cubes at level 0.5 plus volume-keeping smoothing: the surface encloses about the voxel volume
        # (within 15 %: the surface cuts the corners of the staircase), centred on the voxels' centroid (within a
        # voxel); both in the header's world frame, metres
        np.testing.assert_allclose(r.meshes[lv].volume, mask.sum() * voxel_ml, rtol=0.15)
        centre_mm = img.affine[:3, :3] @ ijk.mean(axis=0) + img.affine[:3, 3]
        assert np.linalg.norm(r.meshes[lv].center_mass - centre_mm * 1e-3) < 3e-3


def test_label_mesh_follows_the_affine(tmp_path):
    import nibabel

    img = nibabel.load(TS_MASKS / "vertebrae_L4.nii.gz")
    aff = img.affine.copy()
    aff[:3, 3] += [10.0, -20.0, 30.0]                       # the same voxels 10, -20, 30 mm away
    d = tmp_path / "moved"
    d.mkdir()
    nibabel.save(nibabel.Nifti1Image(np.asarray(img.dataobj), aff), d / "vertebrae_L4.nii.gz")
    shutil.copy(TS_MASKS / "vertebrae_L4.nii.gz", tmp_path / "vertebrae_L4.nii.gz")
    a = S.read_specimen_meshes(S.label_volume_to_meshes(tmp_path, tmp_path / "a")["L4"].parent)["L4"]
    b = S.read_specimen_meshes(S.label_volume_to_meshes(d, tmp_path / "b")["L4"].parent)["L4"]
    np.testing.assert_allclose(b.center_mass - a.center_mass, [0.010, -0.020, 0.030], atol=1e-9)


def test_multilabel_volume_with_table(tmp_path, ts_meshes):
    import nibabel

    _, written = ts_meshes
    ref = nibabel.load(TS_MASKS / "vertebrae_L4.nii.gz")
    lab = np.zeros(ref.shape, np.int16)
    for v, f in ((31, "vertebrae_L4.nii.gz"), (32, "vertebrae_L5.nii.gz"), (92, "sacrum.nii.gz")):
        lab[np.asarray(nibabel.load(TS_MASKS / f).dataobj) > 0.5] = v
    vol = tmp_path / "labels.nii.gz"
    nibabel.save(nibabel.Nifti1Image(lab, ref.affine), vol)
    table = tmp_path / "labels.csv"
    table.write_text("label,value\nvertebrae_L4,31\nL5,32\nsacrum,92\n")
    got = S.label_volume_to_meshes(vol, tmp_path / "out", label_table=table)
    for lv in ("L4", "L5", "S1"):                          # the same meshes as from the per-structure masks
        a, b = trimesh.load(got[lv]), trimesh.load(written[lv])
        np.testing.assert_allclose(a.volume, b.volume, rtol=1e-9)
    with pytest.raises(GeometryError, match="label_table"):
        S.label_volume_to_meshes(vol, tmp_path / "x")
    table.write_text("label,value\nL4,31\nL5,33\n")         # a value the volume does not hold
    with pytest.raises(GeometryError, match=r"labels\.nii\.gz: no voxel has the value 33 of L5"):
        S.label_volume_to_meshes(vol, tmp_path / "x", label_table=table)
    table.write_text("label,value\nL4,31\nvertebrae_L4,32\n")
    with pytest.raises(GeometryError, match=r"labels\.csv: rows 1 and 2 both name L4"):
        S.label_volume_to_meshes(vol, tmp_path / "x", label_table=table)


def test_empty_mask_and_no_masks(tmp_path):
    import nibabel

    ref = nibabel.load(TS_MASKS / "vertebrae_L4.nii.gz")
    nibabel.save(nibabel.Nifti1Image(np.zeros(ref.shape, np.uint8), ref.affine), tmp_path / "vertebrae_L3.nii.gz")
    with pytest.raises(GeometryError, match=r"vertebrae_L3\.nii\.gz: the L3 mask is empty"):
        S.label_volume_to_meshes(tmp_path, tmp_path / "out")
    assert not (tmp_path / "out").exists()                 # refused before anything is written
    (tmp_path / "none").mkdir()
    with pytest.raises(GeometryError, match="no vertebra masks"):
        S.label_volume_to_meshes(tmp_path / "none", tmp_path / "out")


def test_two_sacrum_masks_need_a_pattern(tmp_path):
    # TotalSegmentator 2 writes sacrum.nii.gz beside vertebrae_S1.nii.gz: both name S1
    shutil.copy(TS_MASKS / "vertebrae_L5.nii.gz", tmp_path / "vertebrae_L5.nii.gz")
    shutil.copy(TS_MASKS / "sacrum.nii.gz", tmp_path / "sacrum.nii.gz")
    shutil.copy(TS_MASKS / "sacrum.nii.gz", tmp_path / "vertebrae_S1.nii.gz")
    with pytest.raises(GeometryError, match=r"S1: sacrum\.nii\.gz, vertebrae_S1\.nii\.gz.*pattern"):
        S.label_volume_to_meshes(tmp_path, tmp_path / "out")
    got = S.label_volume_to_meshes(tmp_path, tmp_path / "out", pattern="vertebrae_{level}.nii.gz")
    assert set(got) == {"L5", "S1"}


def test_mislabelled_mask_refused_before_writing(tmp_path):
    for f in ("vertebrae_L4.nii.gz", "vertebrae_L5.nii.gz"):
        shutil.copy(TS_MASKS / f, tmp_path / f)
    assert set(S.label_volume_to_meshes(tmp_path, tmp_path / "ok", require="L4-L5")) == {"L4", "L5"}   # control
    with pytest.raises(GeometryError, match="S1 required but missing"):
        S.label_volume_to_meshes(tmp_path, tmp_path / "x", require="L5-S1")
    shutil.copy(TS_MASKS / "vertebrae_L4.nii.gz", tmp_path / "vertebrae_L5.nii.gz")   # L4's voxels named L5
    with pytest.raises(GeometryError, match=r"vertebrae_L5\.nii\.gz.*overlap"):
        S.label_volume_to_meshes(tmp_path, tmp_path / "bad")
    assert not (tmp_path / "bad").exists()


def test_nifti_unit_in_header_followed(tmp_path):
    import nibabel

    img = nibabel.load(TS_MASKS / "vertebrae_L4.nii.gz")
    aff = img.affine.copy()
    aff[:3, :] /= 1000.0                                    # the same grid in metres, the header saying so
    m = nibabel.Nifti1Image(np.asarray(img.dataobj), aff)
    m.header.set_xyzt_units(xyz="meter")
    d = tmp_path / "metres"
    d.mkdir()
    nibabel.save(m, d / "vertebrae_L4.nii.gz")
    shutil.copy(TS_MASKS / "vertebrae_L4.nii.gz", tmp_path / "vertebrae_L4.nii.gz")
    a = S.read_specimen_meshes(S.label_volume_to_meshes(tmp_path, tmp_path / "a")["L4"].parent)["L4"]
    b = S.read_specimen_meshes(S.label_volume_to_meshes(d, tmp_path / "b")["L4"].parent)["L4"]
    np.testing.assert_allclose(b.volume, a.volume, rtol=1e-6)
    m.header.set_xyzt_units(xyz="mm")                       # control: the same numbers declared in mm are refused
    nibabel.save(m, d / "vertebrae_L4.nii.gz")
    with pytest.raises(GeometryError, match=r"vertebrae_L4\.nii\.gz.*units='m'"):
        S.label_volume_to_meshes(d, tmp_path / "c")


def test_decimation_keeps_a_closed_surface(tmp_path, ts_meshes):
    import pandas as pd

    shutil.copy(TS_MASKS / "vertebrae_L4.nii.gz", tmp_path / "vertebrae_L4.nii.gz")
    full = trimesh.load(ts_meshes[1]["L4"])
    got = trimesh.load(S.label_volume_to_meshes(tmp_path, tmp_path / "out", max_faces=3000)["L4"])
    assert len(got.faces) <= 3000 < len(full.faces) and got.is_watertight
    np.testing.assert_allclose(got.volume, full.volume, rtol=0.01)
    # a target so low that quadric decimation opens this 3 mm surface: the closed mesh is kept, and the report says so
    kept = trimesh.load(S.label_volume_to_meshes(tmp_path, tmp_path / "low", max_faces=1500)["L4"])
    assert len(kept.faces) == len(full.faces) and kept.is_watertight
    assert pd.read_csv(tmp_path / "low" / "meshing_report.csv").decimation[0].startswith("skipped")


def test_resolution_limits_name_the_facets(ts_meshes):
    out, _ = ts_meshes
    import pandas as pd

    rows = pd.read_csv(out / "resolution_limits.csv")
    facet = rows[rows.feature.str.startswith("facet")].iloc[0]
    assert not facet.supported and "3 mm" in facet.reason and "Simon et al. 2012" in facet.reason
    # control: a sub-millimetre scan resolves the joint space (half its sourced low end, 0.71 mm)
    assert S.resolution_limits([0.5, 0.5, 0.6])[0]["supported"]
    assert not S.resolution_limits([0.5, 0.5, 0.8])[0]["supported"]


# ------------------------------------------------------------------ property test: corruptions
OPS = st.one_of(
    st.tuples(st.just("delete"), st.sampled_from(LEVELS3)),
    st.tuples(st.just("duplicate"), st.sampled_from(LEVELS3)),
    st.tuples(st.just("truncate"), st.sampled_from(LEVELS3)),
    st.tuples(st.just("empty"), st.sampled_from(LEVELS3)),
    st.tuples(st.just("small_hole"), st.sampled_from(LEVELS3)),
    st.tuples(st.just("large_hole"), st.sampled_from(LEVELS3)),
    st.tuples(st.just("scale"), st.sampled_from(LEVELS3), st.sampled_from([1000.0, 0.001])),
    st.tuples(st.just("translate"), st.sampled_from(LEVELS3),
              st.sampled_from([(100, 0, 0), (-100, 0, 0), (0, 100, 0), (0, -100, 0), (0, 0, 100), (0, 0, -100)])),
    st.tuples(st.just("overlap"), st.sampled_from(LEVELS3[:2])),
    st.tuples(st.just("copy_onto_below"), st.sampled_from(LEVELS3[:2])),    # a vertebra saved under two names
)


def corrupt(folder: Path, op) -> None:
    kind, lv = op[0], op[1]
    f = folder / f"spec_{lv}.stl"
    if not f.exists():
        return
    if kind == "delete":
        f.unlink()
    elif kind == "duplicate":
        shutil.copy(f, folder / f"copy_{lv}.stl")
    elif kind == "copy_onto_below":
        shutil.copy(f, folder / f"spec_{LEVELS3[LEVELS3.index(lv) + 1]}.stl")
    elif kind == "truncate":
        f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    elif kind == "empty":
        f.write_bytes(b"")
    else:
        try:
            m = trimesh.load(f, force="mesh")
        except Exception:  # noqa: BLE001 - a file an earlier op broke stays as it is
            return
        if len(m.faces) == 0:
            return
        if kind == "small_hole":
            m = punch(m, 4)
        elif kind == "large_hole":
            m = punch(m, 400)
        elif kind == "scale":
            m.apply_scale(op[2])
        elif kind == "translate":
            m.apply_translation(op[2])
        elif kind == "overlap":                            # onto the vertebra below
            m.apply_translation([0, 0, -0.6 * PITCH_MM])
        m.export(f)


def expected_state(ops) -> dict:
    """file name -> state after ``ops`` (the model of :func:`corrupt`): level, scale (about the origin), centre
    (mm), broken (emptied, truncated, a large hole), holed (small holes)."""
    files = {f"spec_{lv}.stl": {"level": lv, "scale": 1.0, "centre": np.array([0.0, 0.0, -PITCH_MM * i]),
                                "broken": False, "holed": False} for i, lv in enumerate(LEVELS3)}
    for op in ops:
        kind, lv = op[0], op[1]
        name = f"spec_{lv}.stl"
        if name not in files:
            continue
        f = files[name]
        if kind == "delete":
            del files[name]
        elif kind == "duplicate":
            files[f"copy_{lv}.stl"] = dict(f)
        elif kind == "copy_onto_below":
            below = LEVELS3[LEVELS3.index(lv) + 1]
            files[f"spec_{below}.stl"] = dict(f, level=below)
        elif kind in ("truncate", "empty", "large_hole"):
            f["broken"] = True
        elif f["broken"] and kind != "small_hole":
            continue                                        # corrupt() leaves an unreadable file as it is
        elif kind == "scale":
            f["scale"] *= op[2]
            f["centre"] = f["centre"] * op[2]
        elif kind == "translate":
            f["centre"] = f["centre"] + op[2]
        elif kind == "overlap":
            f["centre"] = f["centre"] + [0, 0, -0.6 * PITCH_MM]
        elif kind == "small_hole":
            f["holed"] = True
    for f in files.values():
        f["broken"] = f["broken"] or not np.isclose(f["scale"], 1.0)
    return files


def must_fail(files) -> bool:
    """Whether a folder in this state must be refused: a level twice, a broken file, a level missing between two
    present ones, or two neighbours (centre offset o) clearly wrong for any specimen: the upper not above
    (o_z <= 0), surely more than MAX_NEIGHBOUR_GAP_M apart (the gap of these ellipsoids is at least |o| less twice
    the largest semi-axis), or surely overlapping by more than MAX_OVERLAP_M (the ball of the smallest
    semi-axis less |o| / 2 about the midpoint lies in both). Between these bounds either outcome is right (moving
    both alike, or a few millimetres, keeps a valid specimen); an accepted folder must give the files' meshes."""
    levels = [f["level"] for f in files.values()]
    if len(set(levels)) < len(levels) or any(f["broken"] for f in files.values()):
        return True
    idx = sorted(LEVELS3.index(lv) for lv in levels)
    if idx and idx[-1] - idx[0] + 1 != len(idx):
        return True
    centre = {f["level"]: f["centre"] for f in files.values()}
    order = [LEVELS3[i] for i in idx]
    half = SIZE_MM / 2
    for a, b in zip(order, order[1:]):
        o = centre[a] - centre[b]
        n = float(np.linalg.norm(o))
        if o[2] <= 0 or n - 2 * half.max() > S.MAX_NEIGHBOUR_GAP_M * 1e3 + 2 or \
                half.min() - n / 2 > S.MAX_OVERLAP_M * 1e3 + 1:
            return True
    return False


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ops=st.lists(OPS, min_size=1, max_size=3))
def test_corruptions_give_a_named_error_or_a_correct_result(ops):
    folder = Path(tempfile.mkdtemp(prefix="lumbar_spec_"))
    try:
        write_folder(folder)
        for op in ops:
            corrupt(folder, op)
        state = expected_state(ops)
        assert set(state) == {p.name for p in folder.iterdir()}          # the model of the corruptions holds
        touched = {op[1] for op in ops} | {LEVELS3[LEVELS3.index(op[1]) + 1] for op in ops if op[0] == "copy_onto_below"}
        try:
            r = S.read_specimen(folder)
        except GeometryError as exc:
            msg = str(exc)
            assert any(lv in msg for lv in touched), msg                # names a corrupted level or its file
            return
        assert not must_fail(state), f"accepted a corrupted folder: {ops}"
        assert r.levels == [lv for lv in LEVELS3 if any(f["level"] == lv for f in state.values())]
        ref = ellipsoid(0.0)
        holed = set()
        for name, f in state.items():
            lv = f["level"]
            m = r.meshes[lv]
            assert m.is_watertight and r.files[lv].name == name
            np.testing.assert_allclose(m.volume, ref.volume * 1e-9, rtol=2e-3 if f["holed"] else 1e-5)
            np.testing.assert_allclose(m.center_mass, f["centre"] * 1e-3, atol=2e-4 if f["holed"] else 1e-6)
            if f["holed"]:
                holed.add(lv)
        assert {x.level for x in r.repairs} == holed
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_dense_surface_decimated_for_the_landmarks_and_logged(tmp_path):
    """A CT surface exported at fine resolution (here 20x the triangles of the shipped ones) is decimated before the
    landmarks, stays closed and within a fraction of a millimetre of the input, and the log says so; a surface below
    the limit is read unchanged (control). In metres, as read (the simplifier's absolute merge tolerance opened
    such surfaces when they were decimated in metres)."""
    dense = trimesh.creation.icosphere(subdivisions=7, radius=0.02)          # 327,680 triangles, metres
    out, rep = S.working_density(dense, "L4", tmp_path / "L4.stl", max_faces=20_000)
    assert len(out.faces) <= 20_000 and out.is_watertight and out.is_winding_consistent and out.volume > 0
    assert len(rep) == 1 and "decimated 327680 -> " in rep[0].what and "mm of the decimated surface" in rep[0].what
    d = out.nearest.on_surface(dense.vertices[::97])[1]
    assert d.max() < 5e-4 and np.median(d) < 1e-4                           # a fraction of a CT voxel
    np.testing.assert_allclose(out.volume, dense.volume, rtol=0.01)
    same, none = S.working_density(out, "L4", tmp_path / "L4.stl", max_faces=20_000)
    assert same is out and none == []                                       # control: below the limit, untouched


def test_landmarks_command_takes_a_label_volume(tmp_path):
    """``lumbar landmarks`` on TotalSegmentator's masks (L4, L5): the masks are meshed into OUT/meshes as the
    workflow's label_volume geometry is, and the landmarks' input columns are the NIfTI world's (RAS, mm: each point
    within a voxel of its vertebra's voxels); the 3 mm voxels cannot resolve the facet joints, so levels.csv says so
    and leaves the facet numbers empty. Controls: --axes LPS with a label volume, and --label-table with surface
    files, are refused with exit 2 before any meshing."""
    import nibabel

    from lumbar.cli import main
    masks = tmp_path / "masks"
    masks.mkdir()
    for f in ("vertebrae_L4.nii.gz", "vertebrae_L5.nii.gz"):
        shutil.copy(TS_MASKS / f, masks / f)
    ellipsoid(0.0, subdivisions=2).export(masks / "preview.stl")      # a surface naming no vertebra: listed
    out = tmp_path / "out"
    assert main(["landmarks", str(masks), "--out", str(out), "--backend", "none"]) == 0
    assert sorted(p.name for p in (out / "meshes").glob("*.stl")) == ["L4.stl", "L5.stl"]
    import json
    rec = json.loads((out / "transform.json").read_text())
    assert [(Path(x["file"]).name, x["reason"]) for x in rec["ignored_files"]] == [
        ("preview.stl", "a surface file; this folder is read as label masks")]
    assert {v: Path(x["file"]).name for v, x in rec["inputs"].items()} == {"L4": "vertebrae_L4.nii.gz",
                                                                        "L5": "vertebrae_L5.nii.gz"}
    lm = pd.read_csv(out / "landmarks.csv")
    for body, f in (("L4", "vertebrae_L4.nii.gz"), ("L5", "vertebrae_L5.nii.gz")):
        img = nibabel.load(masks / f)
        ijk = np.argwhere(np.asarray(img.dataobj) > 0.5)
        world = ijk @ img.affine[:3, :3].T + img.affine[:3, 3]
        pts = lm.loc[lm["body"] == body, ["x_input", "y_input", "z_input"]].to_numpy()
        assert len(pts) > 20
        # within the table's tolerance of its vertebra's voxels (capsule ends 5 mm, via points 10 mm off the bone);
        # LPS coordinates would lie 100-200 mm away in x and y
        assert (pts >= world.min(0) - 10.0).all() and (pts <= world.max(0) + 10.0).all()
    lv = pd.read_csv(out / "levels.csv")
    assert lv["facet_numbers"].str.startswith("not supported").all()
    facet_cols = [c for c in lv.columns if c.startswith("facet_") and c != "facet_numbers"
                  and not c.endswith("_contact")]
    assert facet_cols and lv[facet_cols].isna().all().all()
    assert main(["landmarks", str(masks), "--axes", "LPS", "--out", str(tmp_path / "x"), "--backend", "none"]) == 2
    assert not (tmp_path / "x" / "meshes").exists()
    meshes = tmp_path / "stl"
    meshes.mkdir()
    shutil.copy(out / "meshes" / "L4.stl", meshes / "L4.stl")
    assert main(["landmarks", str(meshes), "--label-table", str(tmp_path / "t.csv"), "--out",
                 str(tmp_path / "y"), "--backend", "none"]) == 2
