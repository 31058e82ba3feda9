"""A user's specimen geometry: a folder of vertebra surfaces (or a CT label map, meshed into one) in, validated
meshes out. See docs/design.md ("Your own specimen") and docs/workflow.md ("Your own specimen: inputs").

Input form
    A folder with one surface per vertebra, the level read from the file name: ``L1``..``L5``, ``S1`` (also
    ``sacrum`` -> ``S1``) as a token separated by ``_``, ``-``, ``.`` or a space (``L4.stl``, ``vertebrae_L4.stl``,
    ``spec12_L4.ply``), in STL, OBJ, PLY or VTK/VTP polydata. A folder with several surfaces of one level (the
    Visible Human's ``L4_body.obj`` beside ``L4_vertebra.obj``) needs ``pattern`` (a glob with ``{level}``, e.g.
    ``"{level}_vertebra.obj"``): the reader never picks one of them itself.

Output
    Meshes in metres, in the input's own axes (``LPS``, ``RAS`` or ``project``; all three have +z superior, which
    is all the checks use); the caller aligns them to the project frame.

Checks (each a :class:`SpecimenError`, a :class:`~lumbar.geometry.core.GeometryError`, naming the file and what is
wrong, before any long computation): an unknown unit or axes name; no surface found; two files for one level; a
level missing between the highest and the lowest present (or one of ``require``); an empty or unreadable file; a
vertebra whose size does not fit the declared units (factor 1000); a surface that is not closed (holes up to
``MAX_HOLE_PERIMETER_M`` around are filled and listed in ``SpecimenMeshes.repairs``, larger ones refused);
neighbouring vertebrae overlapping, more than ``MAX_NEIGHBOUR_GAP_M`` apart, or not stacked along +z.
"""
from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .checks import MAX_EXTENT_M, MIN_EXTENT_M
from .core import LEVEL_NAMES, VERTEBRA_NAMES, GeometryError, level_vertebrae
from .meshio import read_mesh_arrays

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".vtk", ".vtp")
UNITS = {"mm": 1e-3, "m": 1.0}
AXES = ("LPS", "RAS", "project")
# a hole whose boundary loop is at most this long (about 5 mm across) is filled; a longer one is refused: a surface
# with such a hole is not a segmented bone surface, and no fill can say what was there
MAX_HOLE_PERIMETER_M = 0.015
# neighbouring vertebrae: the disc between two bodies is 5-17 mm tall and the facet joint space 1-2 mm, so the
# nearest points of two neighbours are far closer than this; 30 mm apart is a missing vertebra or a shifted file
MAX_NEIGHBOUR_GAP_M = 0.030
# neighbours overlapping: a surface point of one vertebra deeper than this inside its neighbour. Segmented facet
# processes interpenetrate a little: the embedded Visible Human set (data/geometry/visible_human_lss, L*_vertebra.obj)
# has up to 3.6 mm (L3 in L4); a shifted, doubled or mislabelled vertebra goes a body height (25-35 mm) deep
MAX_OVERLAP_DEPTH_M = 0.006

_TOKEN = {f"l{i}": f"L{i}" for i in range(1, 6)} | {"s1": "S1", "sacrum": "S1"}


class SpecimenError(GeometryError):
    """Specimen geometry that cannot be used; the message names the file (or folder) and what is wrong."""


@dataclass
class Repair:
    level: str
    file: Path
    what: str

    def __str__(self):
        return f"{self.level} ({self.file}): {self.what}"


@dataclass
class SpecimenMeshes:
    meshes: dict                    # level -> trimesh.Trimesh, metres, the input's axes
    files: dict                     # level -> Path
    units: str
    axes: str
    repairs: list = field(default_factory=list)     # list[Repair]: what was changed to close a surface
    ignored: list = field(default_factory=list)     # list[(Path, reason)]: mesh files that name no single level

    @property
    def levels(self) -> list[str]:
        return [v for v in VERTEBRA_NAMES if v in self.meshes]


def level_of(name: str) -> list[str]:
    """The distinct level tokens (``L1``..``L5``, ``S1``; ``sacrum`` -> ``S1``) in a file name, in order."""
    stem = str(name)
    for suf in MESH_SUFFIXES + (".nii.gz", ".nii"):
        if stem.lower().endswith(suf):
            stem = stem[: -len(suf)]
            break
    out = []
    for tok in re.split(r"[^A-Za-z0-9]+", stem):
        lv = _TOKEN.get(tok.lower())
        if lv and lv not in out:
            out.append(lv)
    return out


def _is_mesh(p: Path) -> bool:
    return p.is_file() and p.suffix.lower() in MESH_SUFFIXES


def check_units_axes(units: str, axes: str) -> None:
    if units not in UNITS:
        raise SpecimenError(f"units {units!r}: expected one of {list(UNITS)} (the length unit of the mesh files)")
    if axes not in AXES:
        raise SpecimenError(f"axes {axes!r}: expected one of {list(AXES)} (LPS: x left, y posterior, z superior, "
                            "DICOM/ITK; RAS: x right, y anterior, z superior, NIfTI; project: x anterior, y left, "
                            "z superior)")


def _scan(path, pattern: str | None) -> tuple[dict[str, list[Path]], list[tuple[Path, str]]]:
    folder = Path(path)
    if not folder.is_dir():
        raise SpecimenError(f"{folder}: specimen folder missing (expected a folder of vertebra surfaces, "
                            "e.g. L4.stl, L5.stl)")
    files = sorted(p for p in folder.iterdir() if _is_mesh(p))
    found: dict[str, list[Path]] = {}
    ignored: list[tuple[Path, str]] = []
    if pattern is None:
        for p in files:
            lv = level_of(p.name)
            if len(lv) == 1:
                found.setdefault(lv[0], []).append(p)
            else:
                ignored.append((p, "names no level" if not lv else f"names several levels {lv}"))
        return found, ignored
    if pattern.count("{level}") != 1 or re.search(r"\{(?!level\})", pattern) or "/" in pattern:
        raise SpecimenError(f"pattern {pattern!r}: expected a file-name glob with {{level}} once, "
                            "e.g. '{level}_vertebra.obj' or 'spec12_{level}.stl'")
    used = set()
    for lv in VERTEBRA_NAMES:
        names = [lv, "sacrum"] if lv == "S1" else [lv]
        pats = [pattern.replace("{level}", n).lower() for n in names]
        hits = [p for p in files if any(fnmatch.fnmatchcase(p.name.lower(), q) for q in pats)]
        if hits:
            found[lv] = hits
            used.update(hits)
    ignored = [(p, f"does not match pattern {pattern!r}") for p in files if p not in used]
    return found, ignored


def find_level_files(path, pattern: str | None = None) -> dict[str, Path]:
    """Level (``L1``..``L5``, ``S1``) -> mesh file of the folder ``path``; the level is a token of the file name,
    or ``pattern``'s ``{level}`` (a glob, e.g. ``"{level}_vertebra.obj"``). Two files for one level are an error
    naming both (pass ``pattern`` to choose); so is a folder without any vertebra surface."""
    found, ignored = _scan(path, pattern)
    clash = {lv: ps for lv, ps in found.items() if len(ps) > 1}
    if clash:
        lines = "; ".join(f"{lv}: {', '.join(p.name for p in ps)}" for lv, ps in clash.items())
        hint = ("pass pattern= (a glob with {level}, e.g. '{level}_vertebra.obj') to choose one surface per level"
                if pattern is None else f"pattern {pattern!r} matches several files of one level; make it narrower")
        raise SpecimenError(f"{Path(path)}: several surfaces for one level ({lines}); {hint}")
    if not found:
        nii = sorted(p.name for p in Path(path).iterdir() if p.name.lower().endswith((".nii.gz", ".nii")))
        what = (f"; it holds label volumes ({', '.join(nii[:3])}{', ...' if len(nii) > 3 else ''}): mesh them first "
                "with lumbar.geometry.specimen_io.label_volume_to_meshes") if nii else ""
        skipped = f"; files not used: {', '.join(f'{p.name} ({r})' for p, r in ignored[:6])}" if ignored else ""
        raise SpecimenError(f"{Path(path)}: no vertebra surface found (expected files {list(MESH_SUFFIXES)} named "
                            f"with a level L1..L5, S1 or sacrum, e.g. L4.stl or spec12_L4.ply{'' if pattern is None else f', matching {pattern!r}'})"
                            f"{what}{skipped}")
    return {lv: found[lv][0] for lv in VERTEBRA_NAMES if lv in found}


def _units_hint(extent_m: float, units: str) -> str:
    raw = extent_m / UNITS[units]            # the size in the file's numbers
    fits = [u for u, f in UNITS.items() if MIN_EXTENT_M <= raw * f <= MAX_EXTENT_M]
    if fits:
        return f"the numbers fit units={fits[0]!r}"
    return f"the numbers fit neither {list(UNITS)} (scaled by {'1000' if raw * 1e-3 > MAX_EXTENT_M else '0.001'}?)"


def _boundary_loops(faces: np.ndarray) -> list[list[int]] | None:
    """Boundary loops (vertex indices, in the faces' orientation) of a triangle mesh; None where an edge has more
    than two faces or a boundary vertex is pinched (not a hole a fill can close)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    if np.any(cnt > 2):
        return None
    half = e[cnt[inv.ravel()] == 1]
    nxt: dict[int, int] = {}
    for a, b in half:
        if int(a) in nxt:
            return None
        nxt[int(a)] = int(b)
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt.get(v)
            if v is None:
                return None
        if v != start:
            return None
        loops.append(loop)
    return loops


def close_surface(mesh, level: str, file: Path, max_hole_m: float = MAX_HOLE_PERIMETER_M):
    """The mesh closed: holes whose boundary is at most ``max_hole_m`` long filled (a fan from the hole's centre),
    an inside-out surface turned; returns (mesh, list[Repair]). A larger hole, an edge shared by three faces or a
    surface still open after filling is a :class:`SpecimenError` naming ``file``."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    repairs: list[Repair] = []
    if not mesh.is_watertight:
        loops = _boundary_loops(np.asarray(mesh.faces))
        if loops is None:
            raise SpecimenError(f"{file}: {level} surface is not a closed 2-manifold (an edge of three or more "
                                "triangles, or a pinched boundary); expected one closed surface per vertebra")
        v = np.asarray(mesh.vertices)
        per = [float(np.sum(np.linalg.norm(v[np.roll(lp, -1)] - v[lp], axis=1))) for lp in loops]
        big = [p for p in per if p > max_hole_m]
        if big:
            raise SpecimenError(f"{file}: {level} surface is not closed: {len(big)} hole(s) with a boundary of "
                                f"{max(big) * 1e3:.0f} mm (largest); holes up to {max_hole_m * 1e3:.0f} mm around "
                                "are filled, larger ones must be closed in the segmentation")
        new_v, new_f = [v], [np.asarray(mesh.faces)]
        n = len(v)
        for lp in loops:
            c = v[lp].mean(axis=0)
            new_v.append(c[None])
            # a boundary half-edge a->b of the surface gets the fill triangle (b, a, c): consistent orientation
            new_f.append(np.array([[b, a, n] for a, b in zip(lp, np.roll(lp, -1))]))
            n += 1
        mesh = trimesh.Trimesh(np.concatenate(new_v), np.concatenate(new_f), process=True)
        repairs.append(Repair(level, file, f"filled {len(loops)} hole(s), boundary up to {max(per) * 1e3:.1f} mm"))
        if not mesh.is_watertight:
            raise SpecimenError(f"{file}: {level} surface is not closed after filling its holes; expected one "
                                "closed surface per vertebra")
    if not mesh.is_winding_consistent:
        raise SpecimenError(f"{file}: {level} surface has inconsistent triangle orientation (some faces inside-out); "
                            "expected a consistently oriented closed surface")
    if mesh.volume < 0:
        mesh.invert()
        repairs.append(Repair(level, file, "surface was inside-out (negative volume): normals turned"))
    return mesh, repairs


def read_specimen(path, units: str = "mm", axes: str = "LPS", pattern: str | None = None,
                  require=None, max_hole_m: float = MAX_HOLE_PERIMETER_M) -> SpecimenMeshes:
    """Read and check a folder of vertebra surfaces (see the module doc); ``require``: vertebrae (``"L4"``) or
    units (``"L4-L5"``) that must be present. Returns the meshes in metres, in the input's axes, with the repair
    log."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    check_units_axes(units, axes)
    files = find_level_files(path, pattern)
    _, ignored = _scan(path, pattern)
    present = list(files)
    need = set()
    for r in [require] if isinstance(require, str) else (require or []):
        if r in LEVEL_NAMES:
            need.update(level_vertebrae(r))
        elif r in VERTEBRA_NAMES:
            need.add(r)
        else:
            raise SpecimenError(f"require={r!r}: expected vertebrae {list(VERTEBRA_NAMES)} or units {list(LEVEL_NAMES)}")
    idx = [VERTEBRA_NAMES.index(v) for v in present]
    gaps = [VERTEBRA_NAMES[i] for i in range(min(idx), max(idx) + 1) if VERTEBRA_NAMES[i] not in files]
    missing = sorted(need - set(files), key=VERTEBRA_NAMES.index)
    if gaps or missing:
        why = []
        if gaps:
            why.append(f"{', '.join(gaps)} missing between {present[0]} and {present[-1]} (every vertebra between "
                       "the highest and the lowest present is needed)")
        if missing:
            why.append(f"{', '.join(missing)} required but missing")
        raise SpecimenError(f"{Path(path)}: {'; '.join(why)}; found {', '.join(f'{k}: {v.name}' for k, v in files.items())}")
    scale = UNITS[units]
    meshes, repairs = {}, []
    for lv, f in files.items():
        vertices, faces = read_mesh_arrays(f)
        if not np.all(np.isfinite(vertices)):
            raise SpecimenError(f"{f}: {lv} mesh has non-finite vertex coordinates")
        mesh = trimesh.Trimesh(vertices * scale, faces, process=True)
        if len(mesh.faces) < 4:
            raise SpecimenError(f"{f}: {lv} mesh has {len(mesh.faces)} triangle(s); expected a closed vertebra surface")
        ext = float(np.max(mesh.extents))
        if not MIN_EXTENT_M <= ext <= MAX_EXTENT_M:
            raise SpecimenError(f"{f}: {lv} is {ext:.3g} m across with units={units!r}; a lumbar vertebra or the "
                                f"sacrum spans {MIN_EXTENT_M}-{MAX_EXTENT_M} m: {_units_hint(ext, units)}")
        mesh, rep = close_surface(mesh, lv, f, max_hole_m)
        repairs += rep
        meshes[lv] = mesh
    check_neighbours(meshes, files)
    return SpecimenMeshes(meshes=meshes, files=files, units=units, axes=axes, repairs=repairs, ignored=ignored)


def read_specimen_meshes(path, units: str = "mm", axes: str = "LPS", pattern: str | None = None) -> dict:
    """Level -> ``trimesh.Trimesh`` in metres, in the input's own axes (no axis change; the caller aligns),
    validated (:func:`read_specimen`; its ``repairs`` say what was closed)."""
    return read_specimen(path, units=units, axes=axes, pattern=pattern).meshes


def _dense_points(mesh) -> np.ndarray:
    return np.concatenate([np.asarray(mesh.vertices), np.asarray(mesh.triangles_center)])


def check_neighbours(meshes: dict, files: dict) -> None:
    """Neighbouring vertebrae (L4 and L5, ...) stacked along +z, not overlapping (a surface point deeper than
    ``MAX_OVERLAP_DEPTH_M`` inside the other) and not apart (nearest points more than ``MAX_NEIGHBOUR_GAP_M``)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - scipy.spatial where geometry is computed (docs/design.md)
    order = [v for v in VERTEBRA_NAMES if v in meshes]
    for up, lo in zip(order, order[1:]):
        A, B = meshes[up], meshes[lo]
        where = f"{up} ({files[up]}) and {lo} ({files[lo]})"
        pa, pb = _dense_points(A), _dense_points(B)
        gap = float(cKDTree(pb).query(pa)[0].min())
        if gap > MAX_NEIGHBOUR_GAP_M:
            raise SpecimenError(f"{where}: neighbouring vertebrae {gap * 1e3:.0f} mm apart (nearest surface points); "
                                f"expected within {MAX_NEIGHBOUR_GAP_M * 1e3:.0f} mm (a disc is 5-17 mm tall): a "
                                "vertebra shifted, or one missing between them")
        for X, Y, nx, ny in ((A, B, up, lo), (B, A, lo, up)):
            depth = _overlap_depth(X, Y)
            if depth > MAX_OVERLAP_DEPTH_M:
                raise SpecimenError(f"{where}: the vertebrae overlap: a point of {nx} lies {depth * 1e3:.1f} mm "
                                    f"inside {ny} (allowed {MAX_OVERLAP_DEPTH_M * 1e3:.0f} mm); expected separate "
                                    "bones (a shifted or mislabelled file?)")
        ca, cb = A.center_mass, B.center_mass
        if not ca[2] > cb[2]:
            raise SpecimenError(f"{where}: {up} is not above {lo} along +z (volume centroids z = {ca[2]:.4f} m and "
                                f"{cb[2]:.4f} m); expected +z superior (LPS, RAS and the project frame all have it)")


def _overlap_depth(X, Y) -> float:
    """Largest depth (m) of a vertex of X inside the closed surface Y (0 if none)."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    v = np.asarray(X.vertices)
    lo, hi = Y.bounds
    cand = v[np.all((v >= lo) & (v <= hi), axis=1)]
    if len(cand) == 0:
        return 0.0
    if len(cand) > 2000:
        cand = cand[np.random.default_rng(0).choice(len(cand), 2000, replace=False)]
    inside = cand[Y.contains(cand)]
    if len(inside) == 0:
        return 0.0
    return float(trimesh.proximity.closest_point(Y, inside)[1].max())
