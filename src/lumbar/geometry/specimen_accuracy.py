"""Accuracy of the specimen path where the truth is known: the Visible Human meshes alone, given as a user gives them
(turned by a rotation, shifted into a CT-like pose, millimetres, LPS, written as STL files and read back with
:func:`lumbar.geometry.specimen_io.read_specimen_meshes`), through the whole path
(:func:`lumbar.geometry.specimen_build.build_specimen`) with **leave one out** (no vertebra is its own atlas
template), compared in the specimen's project frame with the model's own insertion sites and facet cartilage
(``load_geometry("visible_human")``, moved by the same transforms).

Scores (:func:`accuracy_tables`): per insertion group (one ligament's fibre ends on one vertebra of one level) the
distance between the centroids of the placed and the reference ends; per facet face the distance between the
centroid of the nine placed points and that of the reference 3x3 grid of cartilage nodes; at one level (L4-L5) the
mean straight fibre length per ligament against the reference (and, for ALL and PLL, whose reference fibres have
a via-point path, the total length). The sacrum has no other template, so ends on S1 are not scored.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from .core import level_vertebrae

CT_ROTATION_DEG = 35.0                          # the pose's rotation about a random axis, on top of LPS
CT_SHIFT_MM = np.array([-12.0, 160.0, -870.0])  # a CT table position (LPS, mm)
LPS_FROM_PROJECT = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def ct_pose(seed: int = 0, angle_deg: float = CT_ROTATION_DEG) -> np.ndarray:
    """4x4 (metres) from the Visible Human's project frame to a CT-like LPS pose: LPS axes, then a rotation of
    ``angle_deg`` about a random axis and a shift to a table position."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    a = np.radians(angle_deg)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    T = np.eye(4)
    T[:3, :3] = R @ LPS_FROM_PROJECT
    T[:3, 3] = CT_SHIFT_MM * 1e-3
    return T


def write_posed_meshes(geo, pose, folder, vertebrae=None) -> dict:
    """Write the geometry's vertebra meshes moved by ``pose`` as ``<token>.stl`` in millimetres; returns the paths."""
    out = {}
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for v in vertebrae or geo.vertebrae:
        m = geo.vertebrae[v].mesh.copy().apply_transform(pose)
        m.apply_scale(1e3)
        out[v] = folder / f"{v}.stl"
        m.export(out[v])
    return out


def _move(T, P):
    P = np.asarray(P, float)
    return P @ T[:3, :3].T + T[:3, 3]


def _contact_normal_angles(level, reference_level, to_specimen) -> dict:
    """{side: angle [deg] between the joint's Eq. 4 contact surface normal on the specimen's landmarks and on the
    reference's (carried into the specimen's frame)}: the orientation the facet force acts along, which the centroid
    distances do not score."""
    from lumbar.mechanics.elements.facet import fit_surface  # noqa: PLC0415 - the model's own Eq. 4 fit

    def normals(lev):
        out = {}
        for side, fl in lev.facets.items():
            medial = np.array([0.0, -1.0 if side == "left" else 1.0, 0.0])
            out[side] = fit_surface(fl.superior, fl.inferior, medial_hint=medial,
                                    contact=getattr(fl, "contact", "mean_surface"),
                                    contact_points=getattr(fl, "contact_points", None)).axes[2]
        return out
    if level is None:
        return {}
    ref = normals(reference_level)
    R = np.asarray(to_specimen, float)[:3, :3]
    return {side: float(np.degrees(np.arccos(np.clip(n @ (R @ ref[side]), -1.0, 1.0))))
            for side, n in normals(level).items() if side in ref}


def accuracy_tables(specimen, reference, to_specimen, length_level="L4-L5"):
    """(groups, facets, lengths) DataFrames comparing a specimen's landmarks with a reference geometry whose points
    ``to_specimen`` (4x4) carries into the specimen's project frame (module doc); fibre lengths at ``length_level``
    ("all": every level)."""
    import trimesh  # noqa: PLC0415 - mesh library, imported where used (docs/design.md)
    groups, facets, lengths = [], [], []
    size = float(np.cbrt(abs(np.linalg.det(np.asarray(to_specimen, float)[:3, :3]))))  # 1 unless the truth is scaled
    for lv, lm in specimen.landmarks.items():
        if lv not in reference.levels:
            continue
        ref = reference.levels[lv]
        U, L = level_vertebrae(lv)
        for name, (up, lo, extra) in lm["ligaments"].items():
            r = ref.ligament(name)
            ru, rl = _move(to_specimen, r.upper), _move(to_specimen, r.lower)
            for end, body, P, Q in (("upper", U, up, ru), ("lower", L, lo, rl)):
                if body == "S1":
                    continue
                groups.append(dict(level=lv, structure=name, kind=r.kind, end=end, body=body,
                                   centroid_error_mm=1e3 * float(np.linalg.norm(P.mean(0) - Q.mean(0)))))
            if length_level in (lv, "all"):
                straight = float(np.linalg.norm(up - lo, axis=1).mean())
                ref_straight = float(np.linalg.norm(ru - rl, axis=1).mean())
                total = straight + float(np.mean(extra))
                ref_total = size * float(r.lengths.mean())
                use_total = bool(np.mean(r.extra_length) > 0)
                got, want = (total, ref_total) if use_total else (straight, ref_straight)
                lengths.append(dict(level=lv, structure=name, compared="total (via points)" if use_total else
                                    "straight", length_mm=1e3 * got, reference_mm=1e3 * want,
                                    relative_error=got / want - 1.0))
        angles = _contact_normal_angles(specimen.geometry.levels.get(lv), ref, to_specimen)
        for side, (sup, inf) in lm["facets"].items():
            f = ref.facets[side]
            for face, body, P, Q in (("superior", L, sup, f.superior), ("inferior", U, inf, f.inferior)):
                if body == "S1":
                    continue
                # the reference grid is on the cartilage layer's sheet, 0.3-3 mm off the bone; its closest bone
                # points separate the placement error from that offset (a CT specimen has bone only)
                Qb = trimesh.proximity.closest_point(reference.vertebrae[body].mesh, Q)[0]
                facets.append(dict(level=lv, side=side, face=face, body=body,
                                   centroid_error_mm=1e3 * float(np.linalg.norm(P.mean(0) - _move(to_specimen,
                                                                                                    Q).mean(0))),
                                   bone_centroid_error_mm=1e3 * float(np.linalg.norm(
                                       P.mean(0) - _move(to_specimen, Qb).mean(0))),
                                   contact_normal_angle_deg=angles.get(side, np.nan)))
    return pd.DataFrame(groups), pd.DataFrame(facets), pd.DataFrame(lengths)


def summary(groups: pd.DataFrame, facets: pd.DataFrame, lengths: pd.DataFrame) -> pd.DataFrame:
    """Per structure kind: median and largest centroid error [mm] (and the facet faces as one row); overall rows."""
    rows = [dict(structure=k, n_groups=len(g), median_mm=float(g["centroid_error_mm"].median()),
                 max_mm=float(g["centroid_error_mm"].max())) for k, g in groups.groupby("kind")]
    rows.append(dict(structure="all ligament groups", n_groups=len(groups),
                     median_mm=float(groups["centroid_error_mm"].median()),
                     max_mm=float(groups["centroid_error_mm"].max())))
    rows.append(dict(structure="facet faces vs cartilage nodes", n_groups=len(facets),
                     median_mm=float(facets["centroid_error_mm"].median()),
                     max_mm=float(facets["centroid_error_mm"].max())))
    rows.append(dict(structure="facet faces vs their bone points", n_groups=len(facets),
                     median_mm=float(facets["bone_centroid_error_mm"].median()),
                     max_mm=float(facets["bone_centroid_error_mm"].max())))
    out = pd.DataFrame(rows)
    if len(lengths):
        out.attrs["largest_length_error"] = float(lengths["relative_error"].abs().max())
    return out


def _scored(sp, ref, to_specimen, length_level, **extra) -> dict:
    groups, facets, lengths = accuracy_tables(sp, ref, to_specimen, length_level=length_level)
    return dict(groups=groups, facets=facets, lengths=lengths, summary=summary(groups, facets, lengths),
                specimen=sp, to_specimen=to_specimen, **extra)


def visible_human_accuracy(seed: int = 0, method: str = "full", leave_one_out: bool = True, folder=None,
                           vertebrae=("L1", "L2", "L3", "L4", "L5", "S1"), length_level: str = "L4-L5",
                           scale: float = 1.0):
    """Run the Visible Human meshes, posed as a CT (:func:`ct_pose`), through files and the whole path, and score them
    (:func:`accuracy_tables`, fibre lengths at ``length_level``, "all": every level). ``scale``: the bones (and the
    truth with them) enlarged about the project origin, a specimen of another size than the atlas's. Returns
    dict(groups, facets, lengths, summary, specimen, pose)."""
    from .loader import load_geometry  # noqa: PLC0415 - the reference is read only here
    from .specimen_build import build_specimen  # noqa: PLC0415 - the path under test
    from .specimen_io import read_specimen_meshes  # noqa: PLC0415
    ref = load_geometry("visible_human")
    pose = ct_pose(seed) @ np.diag([scale, scale, scale, 1.0])
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(folder) if folder is not None else Path(tmp)
        files = write_posed_meshes(ref, pose, where, vertebrae)
        meshes = read_specimen_meshes(where, units="mm", axes="LPS")
        # the "translation" control's landmarks are scored, never used: the spine check after the landmarks refuses
        # them (an ALL end 11 mm off L1, seed 0), so it is left out there and the control is scored as it comes
        sp = build_specimen(meshes, axes="LPS", sources={v: str(f) for v, f in files.items()},
                            leave_one_out=leave_one_out, method=method, units="mm", name="visible_human_posed",
                            check=method != "translation")
    return _scored(sp, ref, sp.alignment.transform @ pose, length_level, pose=pose)


# ------------------------------------------------------------------------- a CT-like segmentation of the same bones
RAS_FROM_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])


def _inside_voxels(mesh, origin, shape, voxel_mm: float) -> np.ndarray:
    """Boolean [i, j, k] of the voxels (centres ``origin + voxel_mm * (i, j, k)``) whose centre lies inside the closed
    surface ``mesh`` (VTK's scan-line rasteriser, vtkPolyDataToImageStencil)."""
    import pyvista as pv  # noqa: PLC0415 - VTK, only to rasterise surfaces
    from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: PLC0415
    from vtkmodules.vtkImagingStencil import vtkImageStencilToImage, vtkPolyDataToImageStencil  # noqa: PLC0415
    stencil = vtkPolyDataToImageStencil()
    stencil.SetInputData(pv.PolyData.from_regular_faces(np.asarray(mesh.vertices, float), np.asarray(mesh.faces)))
    stencil.SetOutputOrigin(*map(float, origin))
    stencil.SetOutputSpacing(voxel_mm, voxel_mm, voxel_mm)
    stencil.SetOutputWholeExtent(0, shape[0] - 1, 0, shape[1] - 1, 0, shape[2] - 1)
    image = vtkImageStencilToImage()
    image.SetInputConnection(stencil.GetOutputPort())
    image.SetInsideValue(1)
    image.SetOutsideValue(0)
    image.SetOutputScalarTypeToUnsignedChar()
    image.Update()
    flat = vtk_to_numpy(image.GetOutput().GetPointData().GetScalars())
    return flat.reshape(tuple(shape[::-1])).transpose(2, 1, 0).astype(bool)


def _depth(mesh, points) -> np.ndarray:
    """Signed distance of ``points`` from the closed surface ``mesh`` (negative inside; VTK's implicit distance)."""
    import pyvista as pv  # noqa: PLC0415 - VTK, only to rasterise surfaces
    poly = pv.PolyData.from_regular_faces(np.asarray(mesh.vertices, float), np.asarray(mesh.faces))
    return np.asarray(pv.PolyData(np.asarray(points, float)).compute_implicit_distance(poly)["implicit_distance"])


def voxelise(meshes_mm: dict, voxel_mm: float, pad: int = 3):
    """A CT-like label volume of closed surfaces given in millimetres in world axes: a voxel belongs to a vertebra when
    its centre lies inside that vertebra's surface (a segmentation thresholded at half the partial volume, so the
    meshed label keeps the bone's volume instead of growing by half a voxel); a voxel whose centre lies inside two
    surfaces (meshes that interpenetrate, as the Visible Human bones do at the facet joints) goes to the one it lies
    deeper in. The grid is axis-aligned in the world axes (the scanner's), so a spine posed at an angle is
    staircased as in a CT. Returns (labels int16 [i, j, k], affine 4x4 voxel -> world mm, {level: label value},
    number of contested voxels)."""
    h = float(voxel_mm)
    if not h > 0:
        raise ValueError(f"voxel_mm {voxel_mm!r}: expected a voxel edge > 0 [mm]")
    levels = list(meshes_mm)
    values = {v: 20 + k for k, v in enumerate(levels)}
    lo = np.floor(np.min([m.bounds[0] for m in meshes_mm.values()], axis=0) / h).astype(int) - pad
    hi = np.ceil(np.max([m.bounds[1] for m in meshes_mm.values()], axis=0) / h).astype(int) + pad
    labels = np.zeros(tuple(hi - lo + 1), np.int16)
    contested = 0
    for v in levels:
        m = meshes_mm[v]
        a = np.floor(m.bounds[0] / h).astype(int) - 1 - lo
        b = np.ceil(m.bounds[1] / h).astype(int) + 1 - lo
        inside = _inside_voxels(m, (lo + a) * h, b - a + 1, h)
        sub = labels[a[0]:b[0] + 1, a[1]:b[1] + 1, a[2]:b[2] + 1]
        clash = inside & (sub != 0)
        if clash.any():
            contested += int(clash.sum())
            ijk = np.argwhere(clash)
            centres = (ijk + a + lo) * h
            owners = sub[clash]
            mine = _depth(m, centres)
            theirs = np.empty(len(ijk))
            for other, val in values.items():
                sel = owners == val
                if sel.any():
                    theirs[sel] = _depth(meshes_mm[other], centres[sel])
            keep_theirs = np.zeros_like(inside)
            keep_theirs[tuple(ijk[theirs < mine].T)] = True
            inside &= ~keep_theirs
        sub[inside] = values[v]
    affine = np.diag([h, h, h, 1.0])
    affine[:3, 3] = lo * h
    return labels, affine, values, contested


def voxelised_accuracy(voxel_mm: float = 1.0, seed: int = 0, folder=None, length_level: str = "all",
                       vertebrae=("L1", "L2", "L3", "L4", "L5", "S1")) -> dict:
    """The Visible Human meshes given as a CT segmentation would give them: posed as in :func:`ct_pose`, in NIfTI's
    RAS world axes, voxelised at ``voxel_mm`` (:func:`voxelise`) into one multi-label NIfTI file with its label
    table, meshed by the label-volume path (:func:`lumbar.geometry.specimen_io.label_volume_to_meshes`: marching
    cubes, smoothing, decimation), read back and placed with leave one out, scored like
    :func:`visible_human_accuracy`. The surfaces a user's CT gives are staircased, smoothed and separated at the
    joints by what the segmentation made of them; this scores the landmarks on such surfaces. Returns the dict of
    :func:`visible_human_accuracy` plus ``meshing`` (the meshing report), ``resolution`` (what the voxel size
    supports) and ``contested_voxels``."""
    import nibabel  # noqa: PLC0415 - NIfTI writer, only here
    from .loader import load_geometry  # noqa: PLC0415 - the reference is read only here
    from .specimen_build import build_specimen  # noqa: PLC0415 - the path under test
    from .specimen_io import label_volume_to_meshes, read_specimen_meshes  # noqa: PLC0415
    ref = load_geometry("visible_human")
    pose = RAS_FROM_LPS @ ct_pose(seed)
    meshes = {}
    for v in vertebrae:
        m = ref.vertebrae[v].mesh.copy().apply_transform(pose)
        m.apply_scale(1e3)
        meshes[v] = m
    labels, affine, values, contested = voxelise(meshes, voxel_mm)
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(folder) if folder is not None else Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        img = nibabel.Nifti1Image(labels, affine)
        img.header.set_xyzt_units("mm")
        nibabel.save(img, where / "labels.nii.gz")
        pd.DataFrame({"label": list(values), "value": list(values.values())}).to_csv(where / "labels.csv", index=False)
        files = label_volume_to_meshes(where / "labels.nii.gz", where / "meshes", label_table=where / "labels.csv")
        meshing = pd.read_csv(where / "meshes" / "meshing_report.csv")
        resolution = pd.read_csv(where / "meshes" / "resolution_limits.csv")
        read = read_specimen_meshes(where / "meshes", units="mm", axes="RAS")
        sp = build_specimen(read, axes="RAS", sources={v: str(f) for v, f in files.items()}, leave_one_out=True,
                            units="mm", name=f"visible_human_voxelised_{voxel_mm:g}mm")
    return _scored(sp, ref, sp.alignment.transform @ pose, length_level, pose=pose, meshing=meshing,
                   resolution=resolution, contested_voxels=contested)


def voxelised_tables(mesh_summary: pd.DataFrame, runs: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(summary, facets): the surface meshes' summary (:func:`visible_human_accuracy`) beside each label volume's
    (``runs``: voxel edge [mm] -> :func:`voxelised_accuracy` result), with whether the voxels resolve the facet joint
    space; and every label volume's facet faces."""
    rows = [mesh_summary.assign(input="surface meshes", voxel_mm=float("nan"), facet_surfaces_supported=True)]
    faces = []
    for h, v in runs.items():
        lim = v["resolution"]
        facet_ok = bool(lim.loc[lim["feature"].str.startswith("facet"), "supported"].all())
        rows.append(v["summary"].assign(input="label volume", voxel_mm=float(h), facet_surfaces_supported=facet_ok))
        faces.append(v["facets"].assign(voxel_mm=float(h)))
    cols = ["input", "voxel_mm", "structure", "n_groups", "median_mm", "max_mm", "facet_surfaces_supported"]
    facet_cols = ["voxel_mm", "level", "side", "face", "body", "centroid_error_mm", "bone_centroid_error_mm",
                  "contact_normal_angle_deg"]
    facets = pd.concat(faces, ignore_index=True)[facet_cols] if faces else pd.DataFrame(columns=facet_cols)
    return pd.concat(rows, ignore_index=True)[cols], facets
