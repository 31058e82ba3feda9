"""Landmarks of a user's specimen from an atlas: the Visible Human set's own insertion sites (Remus et al. 2021) and
facet articular faces, carried onto each target vertebra by surface registration (:mod:`lumbar.geometry.register`).

Atlas (:func:`build_atlas`): per Visible Human vertebra, its two roles -- "upper" (the vertebra is the upper body
of the level below it: the upper fibre ends of that level's ligaments and the 3x3 grid of its inferior articular
face per side) and "lower" (the lower fibre ends of the level above and the grid of its superior articular face).
The fibres of each ligament are put in one canonical order in every level (by their midpoints' position along the
ligament's principal spread axis), so that fibre k means the same fibre at every level.

Transfer (:func:`transfer`): each template vertebra that has the role (all five lumbar vertebrae, the sacrum only
for the sacrum; minus ``exclude``, the leave-one-out of :mod:`lumbar.geometry.specimen_accuracy`) is registered
onto the target vertebra (similarity ICP, affine ICP, smooth non-rigid field); its landmarks are carried by the
warp; the landmark is the coordinate-wise median over the templates, snapped to the target surface (closest
point) when the template point lay on its own surface (within ``ON_SURFACE_M``). ALL and PLL fibre ends of the
Visible Human model are via points off the bone (their path along the body is the fibre's ``extra_length``): they
are carried without snapping, and their extra length is the templates' median scaled by the registration's size
ratio; the ALL's whole fibre is then scaled with the target's own disc height (:func:`_fibre_rule`).
"""
from __future__ import annotations

import functools

import numpy as np

from .analysis import closest_point
from .core import LEVEL_NAMES, LIGAMENT_NAMES, level_vertebrae
from .register import mesh_sample, register, welded

ON_SURFACE_M = 1e-3
N_TEMPLATES = 3              # atlas vertebrae registered per target vertebra and role
REG_SAMPLES = 1500           # template/target vertices used by the registration (register.mesh_sample)
FACET_KEYS = {"upper": "facet_inferior", "lower": "facet_superior"}
SEGMENTS = "_segments"        # atlas key: per ligament and level the fibre vectors upper - lower (canonical order)
SPANS = "_spans"              # atlas key: per scaled ligament and level (mean fibre length, disc height) [m]
#: the articular process around a facet face: template vertices within this distance of the face's centre are fitted
#: rigidly onto the target after the warp (:func:`_process_fit`); 0 switches the fit off. The sphere holds the
#: cartilage face (5.5-8.8 mm across in the atlas) and the process's rim around it, whose edges fix the face's
#: position within its plane; on the face alone (6-9 mm) the fit slides along the nearly flat face
FACET_PROCESS_RADIUS_M = 10e-3
FACET_PROCESS_ITERATIONS = 20
#: ligaments whose fibre length (segment and via-point path) is scaled with the target's own disc height
#: (:func:`lumbar.geometry.specimen.level_disc`): the ALL's path spans the anterior disc and onto the bodies
DISC_SCALED = ("ALL",)
#: insertion groups (ligament, role) whose carried points are moved by the warp's miss at a bone feature of the
#: target (:mod:`lumbar.geometry.bone_features`): landmark = warp(template point) + (target feature - warp(template
#: feature)), per template, before the median. Kept where it beat the plain transfer leave one out on the Visible
#: Human surfaces and on their 3 mm label map (docs/specimen.md, "Bone-feature anchors"): both ends of the
#: intertransverse and supraspinous ligaments, the interspinous ligament's lower ends
ANCHORED: tuple = (("ITL_L", "upper"), ("ITL_L", "lower"), ("ITL_R", "upper"), ("ITL_R", "lower"),
                   ("SSL", "upper"), ("SSL", "lower"), ("ISL", "lower"))


def _canonical_order(up, lo):
    """Fibre order by the midpoints' position along their principal spread axis (sign: +y, else +z, else +x)."""
    mid = 0.5 * (up + lo)
    if len(mid) < 2:
        return np.arange(len(mid))
    _, _, vt = np.linalg.svd(mid - mid.mean(0), full_matrices=False)
    a = vt[0]
    k = 1 if abs(a[1]) > 0.5 else (2 if abs(a[2]) > 0.5 else 0)
    a = a * np.sign(a[k] or 1.0)
    return np.argsort(mid @ a, kind="stable")


#: the 8 symmetries of a 3x3 grid (index 3 * row + column): rotations and reflections of the square
_GRID_SYMMETRIES = tuple(
    np.array([3 * r + c for r, c in (f(i, j) for i in range(3) for j in range(3))])
    for f in (lambda i, j: (i, j), lambda i, j: (j, 2 - i), lambda i, j: (2 - i, 2 - j), lambda i, j: (2 - j, i),
              lambda i, j: (i, 2 - j), lambda i, j: (2 - i, j), lambda i, j: (j, i), lambda i, j: (2 - j, 2 - i)))


def canonical_grid(G):
    """A 3x3 grid of a facet face (index 3 * row + column) re-indexed so that its rows run superior (+z) and its
    columns anterior (+x) within the face's plane: every level's grid then means the same points. The Visible Human
    grids are built along the principal axes of each cartilage sheet, whose order and signs differ between levels
    (a face is nearly square); a coordinate-wise median over templates of grids in different orders shrinks the
    carried face towards its centre."""
    G = np.asarray(G, float)
    if G.shape != (9, 3):
        return G
    _, _, vt = np.linalg.svd(G - G.mean(0))
    n = vt[2]
    up = np.array([0.0, 0.0, 1.0]) - n[2] * n
    ant = np.array([1.0, 0.0, 0.0]) - n[0] * n
    best, score = G, -np.inf
    for p in _GRID_SYMMETRIES:
        H = G[p].reshape(3, 3, 3)
        col = (H[2] - H[0]).sum(0)          # along the rows' index: superior
        row = (H[:, 2] - H[:, 0]).sum(0)    # along the columns' index: anterior
        sc = col @ up / (np.linalg.norm(col) * np.linalg.norm(up) + 1e-30) + row @ ant / (
            np.linalg.norm(row) * np.linalg.norm(ant) + 1e-30)
        if sc > score + 1e-12:
            best, score = G[p], sc
    return best


def disc_height(level: str, meshes: dict) -> float:
    """The level's disc height [m] from the endplates of its two meshes (:func:`lumbar.geometry.specimen.level_disc`,
    the measurement ``specimen_build`` writes to levels.csv)."""
    from .specimen import level_disc  # noqa: PLC0415 - the disc from the endplates
    U, L = level_vertebrae(level)
    return float(level_disc(meshes[U], meshes[L], lower_is_sacrum=L == "S1")["height"])


def _surface_distance(mesh, P):
    return np.asarray(closest_point(mesh, np.asarray(P, float))[1], float)


@functools.lru_cache(maxsize=2)
def _atlas_cached(path):
    from .loader import load_geometry  # noqa: PLC0415 - the atlas source is read once, on first use
    return build_atlas(load_geometry("visible_human", path=path))


def default_atlas(path=None) -> dict:
    """The atlas of the embedded Visible Human set (cached per process)."""
    return _atlas_cached(None if path is None else str(path))


def build_atlas(geo) -> dict:
    """{vertebra: {"points": (n,3) registration samples, "mesh": Trimesh, "upper"/"lower": {structure: dict(
    points (k,3), on_surface (k,), extra (k,) or None)}}} from a geometry with insertion sites (Visible Human)."""
    atlas = {v: {"points": mesh_sample(welded(vt.mesh), REG_SAMPLES)[0], "mesh": vt.mesh, "upper": {}, "lower": {}}
             for v, vt in geo.vertebrae.items()}
    atlas[SEGMENTS], atlas[SPANS] = {}, {}
    for lv, lev in geo.levels.items():
        U, L = lev.upper, lev.lower
        for lig in lev.ligaments:
            o = _canonical_order(lig.upper, lig.lower)
            atlas[SEGMENTS].setdefault(lig.name, {})[lv] = (lig.upper - lig.lower)[o]
            if lig.name in DISC_SCALED:
                length = float(np.mean(np.linalg.norm(lig.upper - lig.lower, axis=1) + lig.extra_length))
                height = disc_height(lv, {v: geo.vertebrae[v].mesh for v in (U, L)})
                atlas[SPANS].setdefault(lig.name, {})[lv] = (length, height)
            for role, body, pts in (("upper", U, lig.upper[o]), ("lower", L, lig.lower[o])):
                on = _surface_distance(geo.vertebrae[body].mesh, pts) < ON_SURFACE_M
                atlas[body][role][lig.name] = dict(points=pts, on_surface=on,
                                                   extra=np.asarray(lig.extra_length, float)[o], level=lv)
        for side, f in lev.facets.items():
            for role, body, pts in (("upper", U, f.inferior), ("lower", L, f.superior)):
                atlas[body][role][f"{FACET_KEYS[role]}:{side}"] = dict(
                    points=canonical_grid(pts), on_surface=np.ones(len(pts), bool), extra=None, level=lv)
    return atlas


def templates_for(target: str, role: str, atlas: dict, exclude=(), n: int = N_TEMPLATES) -> list[str]:
    """Template vertebrae of ``role`` for ``target``: the sacrum for the sacrum, else the ``n`` lumbar vertebrae
    nearest to it in the column (the same level first, then the nearer neighbours, the upper one first)."""
    if target == "S1":
        pool = ["S1"]
    else:
        lumbar = ["L1", "L2", "L3", "L4", "L5"]
        k = lumbar.index(target) if target in lumbar else 2
        pool = sorted(lumbar, key=lambda v: (abs(lumbar.index(v) - k), lumbar.index(v)))
    return [v for v in pool if v in atlas and atlas[v][role] and v not in exclude][:n]


def _rigid(P, Q):
    """Rotation R and translation t minimising |R P + t - Q|^2 (Kabsch)."""
    mp, mq = P.mean(0), Q.mean(0)
    U, _, Vt = np.linalg.svd((Q - mq).T @ (P - mp))
    D = np.eye(3)
    if np.linalg.det(U @ Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    return R, mq - R @ mp


def _process_fit(template_mesh, grid, warp, target_vertices, tree, radius=None):
    """The carried facet grid after a rigid fit of its articular process: the template's vertices within ``radius``
    (default :data:`FACET_PROCESS_RADIUS_M`) of the face's centre, carried by ``warp``, are fitted onto the target's
    vertices (rigid point-to-point ICP, :data:`FACET_PROCESS_ITERATIONS` steps), and the warped grid moves with them.
    The warp of the whole vertebra leaves the face up to 2 mm off along its own plane (the in-plane error of the
    carried superior faces, Visible Human leave one out); the process's own shape places it."""
    radius = FACET_PROCESS_RADIUS_M if radius is None else radius
    G = warp(grid)
    V = np.asarray(template_mesh.vertices)
    P = V[np.linalg.norm(V - np.asarray(grid).mean(0), axis=1) < radius]
    if radius <= 0 or len(P) < 10:
        return G
    Z = warp(P)
    R, t = np.eye(3), np.zeros(3)
    for _ in range(FACET_PROCESS_ITERATIONS):
        j = tree.query(Z)[1]
        Ri, ti = _rigid(Z, target_vertices[j])
        Z = Z @ Ri.T + ti
        R, t = Ri @ R, Ri @ t + ti
    return G @ R.T + t


def _anchor_shifts(s, role, target, mesh, temps, atlas, warps, anchored, cache):
    """Per template, the warp's miss at the bone feature of ``s`` (target feature - carried template feature), or
    None where the group is not anchored or a feature is missing (:data:`ANCHORED`)."""
    if (s, role) not in anchored or target == "S1":
        return None
    from .bone_features import feature_point  # noqa: PLC0415 - only for anchored groups
    f = feature_point(mesh, s, role, cache)
    ft = [feature_point(atlas[t]["mesh"], s, role, atlas[t].setdefault("_features", {})) for t in temps]
    if f is None or any(x is None for x in ft):
        return None
    return [f - warps[t](x[None])[0] for t, x in zip(temps, ft)]


def transfer(target: str, mesh, role: str, atlas: dict, exclude=(), warps: dict | None = None,
             method: str = "full", anchored=None) -> dict:
    """Landmarks of ``role`` on the target vertebra ``mesh`` (project frame): {structure: dict(points (k,3),
    extra (k,) or None, spread_m (k,): largest distance of a template's point from the median, templates,
    anchor: the bone feature that moved the group or None)}; ``anchored``: the (ligament, role) groups anchored on
    a bone feature (default :data:`ANCHORED`)."""
    anchored = ANCHORED if anchored is None else tuple(anchored)
    fcache: dict = {}
    temps = templates_for(target, role, atlas, exclude)
    if not temps and target == "S1":      # the atlas's only sacrum: kept under leave-one-out (S1 ends not scored)
        temps = templates_for(target, role, atlas)
    if not temps:
        raise ValueError(f"no atlas template for the {role} role of {target} (excluded: {list(exclude)})")
    surf = welded(mesh)
    Y, iy = mesh_sample(surf, REG_SAMPLES)
    normals = np.asarray(surf.vertex_normals)[iy]
    warps = {} if warps is None else warps
    for t in temps:
        if t not in warps:
            warps[t] = register(atlas[t]["points"], Y, method=method, normals=normals,
                                dense=(np.asarray(surf.vertices), np.asarray(surf.vertex_normals)))
    out = {}
    names = sorted(set.intersection(*[set(atlas[t][role]) for t in temps]))
    tree = None
    for s in names:
        if s.startswith("facet_") and FACET_PROCESS_RADIUS_M > 0:
            if tree is None:
                from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
                tree = cKDTree(np.asarray(mesh.vertices))
            cand = [_process_fit(atlas[t]["mesh"], atlas[t][role][s]["points"], warps[t],
                                 np.asarray(mesh.vertices), tree) for t in temps]
        else:
            cand = [warps[t](atlas[t][role][s]["points"]) for t in temps]
        shifts = _anchor_shifts(s, role, target, mesh, temps, atlas, warps, anchored, fcache)
        if shifts is not None:
            cand = [c + d for c, d in zip(cand, shifts)]
        if len({c.shape for c in cand}) != 1:
            continue
        P = np.median(np.stack(cand), axis=0)
        spread = np.max(np.linalg.norm(np.stack(cand) - P, axis=-1), axis=0)
        on = np.all([atlas[t][role][s]["on_surface"] for t in temps], axis=0)
        if on.any():
            snapped, _, _ = closest_point(mesh, P[on])
            P[on] = snapped
        extra = None
        if atlas[temps[0]][role][s]["extra"] is not None:
            extra = np.median([atlas[t][role][s]["extra"] * warps[t].scale for t in temps], axis=0)
        anchor = None
        if shifts is not None:
            from .bone_features import FEATURE_OF  # noqa: PLC0415
            anchor = FEATURE_OF[s]
        out[s] = dict(points=P, extra=extra, spread_m=spread, on_surface=on, templates=list(temps), anchor=anchor)
    return out


def level_landmarks(meshes: dict, level: str, atlas: dict, leave_one_out: bool = False, warps=None,
                    method: str = "full") -> dict:
    """{"ligaments": {name: (upper (n,3), lower (n,3), extra (n,))}, "facets": {side: (superior (9,3),
    inferior (9,3))}, "spread": {...}} for one level from the transfers of its two vertebrae; ``leave_one_out``:
    no vertebra is its own template (the accuracy measurement on the atlas's own specimen)."""
    U, L = level_vertebrae(level)
    warps = {} if warps is None else warps
    up = transfer(U, meshes[U], "upper", atlas, exclude=(U,) if leave_one_out else (), warps=warps.setdefault(U, {}),
                  method=method)
    lo = transfer(L, meshes[L], "lower", atlas, exclude=(L,) if leave_one_out else (), warps=warps.setdefault(L, {}),
                  method=method)
    ligs, facets, spread = {}, {}, {}
    # the size of the level against the atlas's vertebrae: every registration onto its two vertebrae (the via-point
    # extra lengths are scaled by their own template's; the fibre vectors of _fibre_rule by this)
    size = float(np.median([w.scale for v in (U, L) for w in warps[v].values()]))
    for name in LIGAMENT_NAMES:
        if name in up and name in lo and len(up[name]["points"]) == len(lo[name]["points"]):
            ex = [e for e in (up[name]["extra"], lo[name]["extra"]) if e is not None]
            extra = np.mean(ex, axis=0) if ex else np.zeros(len(up[name]["points"]))
            u, lo_, extra = _fibre_rule(name, up[name]["points"], lo[name]["points"], extra, level, meshes, atlas,
                                        exclude=(U, L) if leave_one_out else (), size=size)
            ligs[name] = (u, lo_, extra)
            spread[name] = (up[name]["spread_m"], lo[name]["spread_m"])
    for side in ("left", "right"):
        ki, ks = f"facet_inferior:{side}", f"facet_superior:{side}"
        if ki in up and ks in lo:
            # the upper face is the upper vertebra's bone facing the carried lower face across the joint (closest
            # points): the inferior articular processes vary more between levels than the superior ones, and the
            # carried upper face missed its own bone points by 3 mm (median, Visible Human, leave one out)
            sup = lo[ks]["points"]
            facets[side] = (sup, _facing_face(meshes[U], meshes[L], sup))
            spread[f"facet_{side}"] = (lo[ks]["spread_m"], up[ki]["spread_m"])
    templates = {"upper": next(iter(up.values()))["templates"], "lower": next(iter(lo.values()))["templates"]}
    anchors = {(name, role): d["anchor"] for role, tr in (("upper", up), ("lower", lo)) for name, d in tr.items()
               if d.get("anchor")}
    return dict(ligaments=ligs, facets=facets, spread=spread, templates=templates, anchors=anchors)


def _facing_face(upper_mesh, lower_mesh, sup):
    """The upper vertebra's inferior articular face across the joint from the lower vertebra's superior face ``sup``:
    the upper bone's closest points, where they lie on the joint side of ``sup`` (along the lower face's outward
    normal, from the lower bone's own face normals there); where they lie behind it (the two bone surfaces
    interpenetrate at the joint: surfaces modelled or segmented without a joint space, as the Visible Human meshes
    are at every lumbar level), the faces touch: the inferior face is ``sup`` itself. An inferior face behind the
    superior one turns the joint's contact surface around (its normal is oriented from the superior to the inferior
    face): the facet then resists the wrong motions (Visible Human L4-L5, leave one out: no facet force in axial
    rotation, twice the reference's axial range of motion)."""
    inf = _closest(upper_mesh, sup)
    tri = closest_point(lower_mesh, sup)[2]
    n = np.asarray(lower_mesh.face_normals)[tri].sum(0)
    n /= np.linalg.norm(n) or 1.0
    if float((inf.mean(0) - np.asarray(sup).mean(0)) @ n) < 0:
        return np.array(sup, float)
    return inf


def _closest(mesh, P):
    return np.asarray(closest_point(mesh, np.asarray(P, float))[0], float)


def _allowed(per_level: dict, exclude, shape=None) -> list:
    """The atlas levels' entries not involving a vertebra in ``exclude`` (and of ``shape`` when given)."""
    return [v for lv, v in per_level.items() if not set(level_vertebrae(lv)) & set(exclude)
            and (shape is None or np.shape(v) == shape)]


def _fibre_rule(name, up, lo, extra, level, meshes, atlas, exclude=(), size: float = 1.0):
    """Fibres that span a narrow gap keep their own geometry instead of two independently carried ends; returns
    (upper (k,3), lower (k,3), extra (k,)):

    * capsule fibres (CL, 2-2.6 mm across the joint's rim) and via-point fibres (ALL, PLL with ``extra`` > 0: a
      short segment at the disc, off the bone): the fibre is centred on the carried midpoint (the mean of its two
      carried ends) with the atlas's own fibre vector (median over the atlas levels not involving ``exclude``) times
      ``size``, the registrations' size ratio (target / atlas vertebrae), not snapped: its length is the atlas's at
      the target's size, which the two independently carried and snapped ends do not keep (the capsule fibres came
      out twice or half as long, and a unit with half-length capsule fibres was twice as stiff).
    * ``DISC_SCALED`` ligaments (ALL): the whole fibre (segment and via-point path) is then scaled so that its mean
      length is the target's own disc height (:func:`disc_height`, measured on the target's endplates) times the
      atlas's ratio of mean length to disc height (median over the same atlas levels, their disc heights measured
      the same way on the atlas's bones): the ALL's path spans its own level's disc, which the other levels'
      paths, of shorter discs or taller, do not.

    Other fibres keep their two carried ends."""
    mid = 0.5 * (up + lo)
    vecs = _allowed(atlas.get(SEGMENTS, {}).get(name, {}), exclude, up.shape)
    if not vecs or not (name.startswith("CL") or np.any(extra > 0)):
        return up, lo, extra
    vec = float(size) * np.median(np.stack(vecs), axis=0)
    spans = _allowed(atlas.get(SPANS, {}).get(name, {}), exclude)
    if name in DISC_SCALED and spans:
        ratio = float(np.median([length / height for length, height in spans]))
        want = ratio * disc_height(level, meshes)
        k = want / float(np.mean(np.linalg.norm(vec, axis=1) + extra))
        vec, extra = k * vec, k * np.asarray(extra, float)
    return mid + 0.5 * vec, mid - 0.5 * vec, extra


def levels_present(meshes: dict) -> list[str]:
    return [lv for lv in LEVEL_NAMES if all(v in meshes for v in level_vertebrae(lv))]
