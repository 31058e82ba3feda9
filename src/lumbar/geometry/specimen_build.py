"""A user's specimen end to end: meshes in the input's axes -> project frame (:mod:`lumbar.geometry.specimen`) ->
landmarks (:mod:`lumbar.geometry.specimen_landmarks`) -> a :class:`SpineGeometry` that
``lumbar.experiments.fsu.build_fsu`` accepts, with the landmark table, the per-level table and the transform
(:mod:`lumbar.geometry.specimen_tables` writes and reads them).

Facet contact rule for bone surfaces from CT (no cartilage segmented): the gap between the two bone faces is the
joint space, which in life is cartilage (Simon et al. 2012, in-vivo CT: 1.93 +- 0.51 mm central joint space,
data/anatomy/l4l5_magnitudes_original_text.csv). So the landmarks are the two subchondral faces of a cartilage-filled
joint and the contact rule is ``"touching"`` (``lumbar.mechanics.elements.facet.fit_surface``: the surface passes
through the nearest upper-face contact point; contact begins as soon as the joint closes). The measured bone gap
(median distance of the nine upper-face landmarks to the lower vertebra's surface) is recorded per joint and
compared with the sourced mean +- 2 SD; outside it, the joint is flagged (``facet_<side>_gap_in_sourced_range``
False, a warning logged): a wider gap is an eroded segmentation or a distracted joint, a gap near 0 fused or
over-grown bone surfaces; the rule stays ``"touching"`` and the user may edit the landmarks.
"""
from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..inputs import resources
from .core import FacetLandmarks, GeometryError, Level, Ligament, SpineGeometry, Vertebra, level_vertebrae
from .register import farthest_points
from .specimen import Alignment, align_to_project, body_centroid, body_split, disc_from_endplates, sacrum_centroid
from .specimen_landmarks import default_atlas, level_landmarks, levels_present

log = logging.getLogger(__name__)
CONTACT_POINTS_MAX = 40
CONTACT_PLANE_TOL_M = 1.5e-3


@functools.lru_cache(maxsize=1)
def facet_space_range_m() -> tuple[float, float, float]:
    """(mean, mean - 2 SD, mean + 2 SD) of the sourced facet joint space width [m] (data/anatomy/)."""
    p = resources.data_dir() / "anatomy" / "l4l5_magnitudes_original_text.csv"
    df = pd.read_csv(p)
    row = df[df["quantity"] == "facet_joint_space_width"]
    if row.empty:
        raise GeometryError(f"{p}: no row 'facet_joint_space_width' (expected the sourced facet joint space)")
    r = row.iloc[0]
    sd = float(r["high"]) - float(r["value"])
    return 1e-3 * float(r["value"]), 1e-3 * (float(r["value"]) - 2 * sd), 1e-3 * (float(r["value"]) + 2 * sd)


@dataclass
class Specimen:
    geometry: SpineGeometry
    alignment: Alignment
    meshes: dict                       # token -> Trimesh in the project frame (metres)
    landmarks: dict                    # level -> level_landmarks(...) output (project frame)
    facet_gaps: dict = field(default_factory=dict)   # (level, side) -> bone gap [m]
    sources: dict = field(default_factory=dict)
    units: str = "m"


def _dist_to(mesh, P):
    from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    return cKDTree(np.asarray(mesh.vertices)).query(np.asarray(P, float))[0]


def facet_contact_points(upper_mesh, lower_mesh, inferior):
    """Upper-face contact points of one joint: the upper vertebra's vertices within the articular face spanned by
    the nine ``inferior`` landmarks (within 1.5 mm of their plane, inside their extent grown by 1 mm) and within the
    landmarks' largest bone gap + 1 mm of the lower vertebra; at most ``CONTACT_POINTS_MAX`` (farthest-point
    sample), with the nine landmarks always included."""
    inferior = np.asarray(inferior, float)
    c = inferior.mean(0)
    _, _, vt = np.linalg.svd(inferior - c)
    V = np.asarray(upper_mesh.vertices)
    q = (V - c) @ vt.T
    qi = (inferior - c) @ vt.T
    lo, hi = qi[:, :2].min(0) - 1e-3, qi[:, :2].max(0) + 1e-3
    sel = (np.abs(q[:, 2]) < CONTACT_PLANE_TOL_M) & np.all((q[:, :2] > lo) & (q[:, :2] < hi), axis=1)
    cand = V[sel]
    if len(cand):
        gmax = _dist_to(lower_mesh, inferior).max()
        cand = cand[_dist_to(lower_mesh, cand) < gmax + 1e-3]
    if len(cand) > CONTACT_POINTS_MAX - 9:
        cand = farthest_points(cand, CONTACT_POINTS_MAX - 9)
    return np.vstack([inferior, cand])


def assemble_level(name, meshes, lm, centroids, x_post, gaps):
    """One :class:`Level` from the meshes (project frame) and the level's landmarks."""
    U, L = level_vertebrae(name)
    disc = disc_from_endplates(meshes[U], meshes[L], centroids[U], centroids[L], x_post[U])
    ligs = [Ligament(n, n.split("_")[0], np.asarray(u, float), np.asarray(lo, float), np.asarray(e, float))
            for n, (u, lo, e) in lm["ligaments"].items()]
    mean, low, high = facet_space_range_m()
    facets = {}
    for side, (sup, inf) in lm["facets"].items():
        g = float(np.median(_dist_to(meshes[L], inf)))
        gaps[(name, side)] = g
        if not (low <= g <= high):
            log.warning("%s %s facet: bone gap %.2f mm outside the sourced joint space %.2f-%.2f mm (mean +- 2 SD); "
                        "contact rule 'touching' kept; check the landmarks", name, side, g * 1e3, low * 1e3,
                        high * 1e3)
        facets[side] = FacetLandmarks(superior=np.asarray(sup, float), inferior=np.asarray(inf, float),
                                      contact="touching",
                                      contact_points=facet_contact_points(meshes[U], meshes[L], inf))
    return Level(name, U, L, disc["centre"], disc["normal"], disc["csa"], disc["height"], facets, ligs), disc


def centroids_of(meshes: dict):
    """(reference points c_b, x of the body's posterior wall) of every vertebra (project frame); the sacrum's from
    the L5-S1 superior endplate when L5 is present, else from its top 25 mm."""
    x_post, cents = {}, {}
    for v, m in meshes.items():
        if v != "S1":
            x_post[v] = body_split(m)[0]
            cents[v] = body_centroid(m, x_post[v])
    if "S1" in meshes:
        m = meshes["S1"]
        x_post["S1"] = body_split(m)[0]
        if "L5" in meshes:
            d = disc_from_endplates(meshes["L5"], m, cents["L5"], np.asarray(m.vertices).mean(0), x_post["L5"])
            cents["S1"] = sacrum_centroid(m, *d["superior"])
        else:
            v = np.asarray(m.vertices)
            cents["S1"] = v[v[:, 2] > v[:, 2].max() - 0.025].mean(0)
    return cents, x_post


def build_specimen(meshes: dict, axes: str = "LPS", sources: dict | None = None, atlas: dict | None = None,
                   leave_one_out: bool = False, name: str = "specimen", units: str = "m",
                   method: str = "full") -> Specimen:
    """Align, place the landmarks of every level present and assemble the geometry (module doc).

    ``meshes``: {token: Trimesh} in metres in the input's axes (``lumbar.geometry.specimen_io.read_specimen_meshes``);
    ``axes``: the declared axes (:func:`lumbar.geometry.specimen.declared_matrix`); ``atlas``: default the embedded
    Visible Human set's; ``leave_one_out``: no vertebra of the atlas is used for itself (accuracy measurement);
    ``method``: the registration (:func:`lumbar.geometry.register.register`; "translation" only as a control)."""
    sources = dict(sources or {})
    al = align_to_project(meshes, axes=axes, sources=sources)
    proj = {v: m.copy().apply_transform(al.transform) for v, m in meshes.items()}
    atlas = default_atlas() if atlas is None else atlas
    cents, x_post = centroids_of(proj)
    levels, lms, gaps = {}, {}, {}
    warps: dict = {}
    for lv in levels_present(proj):
        lms[lv] = level_landmarks(proj, lv, atlas, leave_one_out=leave_one_out, warps=warps, method=method)
        levels[lv], _ = assemble_level(lv, proj, lms[lv], cents, x_post, gaps)
    verts = {v: Vertebra(v, proj[v], np.asarray(cents[v], float)) for v in proj}
    src = ", ".join(f"{v}: {sources.get(v, 'mesh')}" for v in proj)
    geo = SpineGeometry(name=name, source=f"user specimen ({src}); axes {axes}; landmarks from the Visible Human "
                        "atlas (Remus et al. 2021, BSD-3-Clause) by surface registration", vertebrae=verts,
                        levels=levels)
    return Specimen(geometry=geo, alignment=al, meshes=proj, landmarks=lms, facet_gaps=gaps, sources=sources,
                    units=units)
