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
#: the spine check (:func:`check_specimen_spine`; design limits, far from the sourced and the measured values): the
#: disc height between the endplates. Middle disc heights of 7.9-12.0 mm from L1-L2 to L4-L5 and 11.1-11.3 mm at
#: L5-S1 (data/anatomy/lumbosacral_disc_height_original_text.csv); measured here 6.8-11.9 mm (the Visible Human set,
#: the morphable mean, TotalSegmentator's example meshed at 3 mm). Below 0.5 mm the endplates touch or cross (a
#: level fused, or two files overlapping); above 25 mm a vertebra is missing between the two or the files are in the
#: wrong order
DISC_HEIGHT_RANGE_M = (0.5e-3, 25e-3)
#: the disc cross-section 2 mm above the upper endplate: 1800 mm2 at L4-L5 (data/anatomy/l4l5_magnitudes_original_text
#: .csv), measured here 1431-1697 mm2 on the same sets; 500-4000 mm2 accepted (a section through a process or a
#: sacral wing is outside)
DISC_CSA_RANGE_M2 = (500e-6, 4000e-6)
#: lumbar vertebrae of one spine: the surface areas of the Visible Human L1-L5 differ by 15 % at most (138-160 cm2),
#: the morphable mean's L2-L5 by 8 %; the sacrum has 2.8-2.9 times L5's (Visible Human, TotalSegmentator's example).
#: A lumbar file with more than this times the median of the lumbar files present is refused (a sacrum, or two bones)
MAX_LUMBAR_AREA_RATIO = 1.8


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
    input_log: dict = field(default_factory=dict)    # the reader's record: files, repairs, files not read


def _named(v, sources):
    return f"{v} ({sources[v]})" if sources.get(v) else v


def check_lumbar_sizes(meshes: dict, sources: dict | None = None) -> None:
    """A lumbar file whose surface area is more than ``MAX_LUMBAR_AREA_RATIO`` times the median of the lumbar files
    present is refused, naming it (a sacrum, or two bones, under a lumbar name); needs two lumbar files."""
    sources = dict(sources or {})
    lumbar = [v for v in ("L1", "L2", "L3", "L4", "L5") if v in meshes]
    if len(lumbar) < 2:
        return
    area = {v: float(meshes[v].area) for v in lumbar}
    med = float(np.median(list(area.values()))) if len(lumbar) > 2 else min(area.values())
    for v in lumbar:
        if area[v] > MAX_LUMBAR_AREA_RATIO * med:
            raise GeometryError(f"{_named(v, sources)}: surface area {area[v] * 1e4:.0f} cm2, {area[v] / med:.1f} times "
                                f"that of the other lumbar files ({', '.join(f'{k} {a * 1e4:.0f}' for k, a in area.items())}"
                                f" cm2); expected lumbar vertebrae of one spine (within {MAX_LUMBAR_AREA_RATIO:g} times "
                                "of each other): a sacrum, or two bones, under a lumbar vertebra's name?")


def check_column(meshes: dict, centroids: dict, x_post: dict, sources: dict | None = None) -> dict:
    """The spine check of a specimen in the project frame, before its landmarks, naming the level and the files:
    each vertebra above the next in the column found from the anatomy (the levels in anatomical order), and every
    disc's height and cross-section (:func:`lumbar.geometry.specimen.disc_from_endplates`) within
    ``DISC_HEIGHT_RANGE_M`` and ``DISC_CSA_RANGE_M2``. Returns {level: disc}."""
    sources = dict(sources or {})
    order = [v for v in ("L1", "L2", "L3", "L4", "L5", "S1") if v in meshes]
    for up, lo in zip(order, order[1:]):
        d = np.asarray(centroids[up]) - np.asarray(centroids[lo])
        if not (d[2] > 0 and d[2] > max(abs(d[0]), abs(d[1]))):
            raise GeometryError(f"{_named(up, sources)} and {_named(lo, sources)}: {up} is not above {lo} in the column "
                                f"found from the anatomy (body centroids {np.round(d * 1e3, 1).tolist()} mm apart, "
                                "x anterior, y left, z superior); expected the levels in anatomical order: files "
                                "swapped or misnamed?")
    (hlo, hhi), (alo, ahi) = DISC_HEIGHT_RANGE_M, DISC_CSA_RANGE_M2
    discs = {}
    for name in levels_present(meshes):
        U, L = level_vertebrae(name)
        where = f"{name} ({_named(U, sources)}, {_named(L, sources)})"
        try:
            d = disc_from_endplates(meshes[U], meshes[L], centroids[U], centroids[L], x_post[U])
        except GeometryError as exc:
            raise GeometryError(f"{where}: {exc}") from None
        h, a = d["height"], d["csa"]
        if not hlo <= h <= hhi:
            raise GeometryError(f"{where}: disc height {h * 1e3:.1f} mm between the endplates; expected "
                                f"{hlo * 1e3:g}-{hhi * 1e3:g} mm (sourced middle heights 7.9-12 mm): "
                                + ("the endplates touch or cross (files overlapping, or a fused level)" if h < hlo
                                   else "a vertebra missing between the two, or the files in the wrong order"))
        if not alo <= a <= ahi:
            raise GeometryError(f"{where}: disc cross-section {a * 1e6:.0f} mm2 (the upper body's section 2 mm above "
                                f"its inferior endplate); expected {alo * 1e6:.0f}-{ahi * 1e6:.0f} mm2 (sourced 1800 "
                                "mm2 at L4-L5): not the vertebral body of a lumbar vertebra above a disc (a misnamed "
                                "file, a sacrum under a lumbar name, or not a vertebra)")
        discs[name] = d
    return discs


def check_built_spine(geo: SpineGeometry, sources: dict | None = None) -> None:
    """The checks of every geometry (:func:`lumbar.geometry.checks.check_spine`: sizes, sections, the vertebrae
    stacked, the insertions on their bones) on a built specimen, its message naming the files."""
    from .checks import check_spine  # noqa: PLC0415 - the checks every loaded geometry passes
    sources = dict(sources or {})
    try:
        check_spine(geo)
    except GeometryError as exc:
        files = "; ".join(f"{v}: {sources[v]}" for v in geo.vertebrae if sources.get(v))
        raise GeometryError(f"{exc} [files: {files}]" if files else str(exc)) from None


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
                   method: str = "full", turned=(), check: bool = True, input_log: dict | None = None) -> Specimen:
    """Align, place the landmarks of every level present and assemble the geometry (module doc).

    ``meshes``: {token: Trimesh} in metres in the input's axes (``lumbar.geometry.specimen_io.read_specimen_meshes``);
    ``axes``: the declared axes (:func:`lumbar.geometry.specimen.declared_matrix`); ``atlas``: default the embedded
    Visible Human set's; ``leave_one_out``: no vertebra of the atlas is used for itself (accuracy measurement);
    ``method``: the registration (:func:`lumbar.geometry.register.register`; "translation" only as a control);
    ``turned``: the vertebrae the reader turned outwards (``SpecimenMeshes.turned``, checked by the alignment);
    ``check``: the spine check (:func:`check_lumbar_sizes` before the alignment, :func:`check_column` before the
    landmarks, :func:`check_built_spine` after them); ``input_log``: the reader's record
    (``SpecimenMeshes.log()``), kept for transform.json."""
    sources = dict(sources or {})
    if check:
        check_lumbar_sizes(meshes, sources)
    al = align_to_project(meshes, axes=axes, sources=sources, turned=turned)
    proj = {v: m.copy().apply_transform(al.transform) for v, m in meshes.items()}
    atlas = default_atlas() if atlas is None else atlas
    cents, x_post = centroids_of(proj)
    if check:
        check_column(proj, cents, x_post, sources)
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
    if check:
        check_built_spine(geo, sources)
    return Specimen(geometry=geo, alignment=al, meshes=proj, landmarks=lms, facet_gaps=gaps, sources=sources,
                    units=units, input_log=dict(input_log or {}))
