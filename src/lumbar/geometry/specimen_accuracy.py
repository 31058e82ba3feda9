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
                ref_total = float(r.lengths.mean())
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


def visible_human_accuracy(seed: int = 0, method: str = "full", leave_one_out: bool = True, folder=None,
                           vertebrae=("L1", "L2", "L3", "L4", "L5", "S1"), length_level: str = "L4-L5"):
    """Run the Visible Human meshes, posed as a CT (:func:`ct_pose`), through files and the whole path, and score them
    (:func:`accuracy_tables`, fibre lengths at ``length_level``, "all": every level). Returns dict(groups, facets,
    lengths, summary, specimen, pose)."""
    from .loader import load_geometry  # noqa: PLC0415 - the reference is read only here
    from .specimen_build import build_specimen  # noqa: PLC0415 - the path under test
    from .specimen_io import read_specimen_meshes  # noqa: PLC0415
    ref = load_geometry("visible_human")
    pose = ct_pose(seed)
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(folder) if folder is not None else Path(tmp)
        files = write_posed_meshes(ref, pose, where, vertebrae)
        meshes = read_specimen_meshes(where, units="mm", axes="LPS")
        sp = build_specimen(meshes, axes="LPS", sources={v: str(f) for v, f in files.items()},
                            leave_one_out=leave_one_out, method=method, units="mm", name="visible_human_posed")
    to_specimen = sp.alignment.transform @ pose
    groups, facets, lengths = accuracy_tables(sp, ref, to_specimen, length_level=length_level)
    return dict(groups=groups, facets=facets, lengths=lengths, summary=summary(groups, facets, lengths),
                specimen=sp, pose=pose, to_specimen=to_specimen)
