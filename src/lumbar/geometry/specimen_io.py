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
level missing between the highest and the lowest present (or one of ``require``); an empty or unreadable file, or
one with non-finite coordinates; more than one body in a file (:func:`single_body`: a second large component or
many fragments refused, a few tiny islands dropped); a vertebra whose size does not fit the declared units; a
surface that is not closed (holes up to ``MAX_HOLE_PERIMETER_M`` around are filled, larger ones refused);
neighbouring vertebrae overlapping, more than ``MAX_NEIGHBOUR_GAP_M`` apart, or not stacked along +z.

Repairs (each a :class:`Repair` in ``SpecimenMeshes.repairs``, with its ``kind``): vertices merged, repeated or
degenerate triangles removed, tiny islands dropped, holes filled, triangles turned to one orientation, a surface
wound inside-out turned outwards (:func:`close_surface`: the anatomy is checked against the declared axes later,
:func:`lumbar.geometry.specimen.align_to_project`), a dense surface decimated (:func:`working_density`).
"""
from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .analysis import closest_point
from .checks import MAX_EXTENT_M, MIN_EXTENT_M
from .core import LEVEL_NAMES, VERTEBRA_NAMES, GeometryError, level_vertebrae
from .meshio import read_mesh_arrays

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".vtk", ".vtp")
UNITS = {"mm": 1e-3, "m": 1.0}
AXES = ("LPS", "RAS", "project", "any")
# a hole whose boundary loop is at most this long (about 5 mm across) is filled; a longer one is refused: a surface
# with such a hole is not a segmented bone surface, and no fill can say what was there
MAX_HOLE_PERIMETER_M = 0.015
# neighbouring vertebrae touch at their facet joints: the nearest surface points of the neighbours of the embedded
# Visible Human set and of TotalSegmentator's example (meshed here) are less than 0.3 mm apart; 30 mm apart is a
# vertebra missing between them or a shifted file (a design limit, far from both)
MAX_NEIGHBOUR_GAP_M = 0.030
# neighbours overlapping: the radius of the largest ball inside both (half the thickness of their common volume).
# Segmented facet processes interpenetrate a little: 1.0-1.8 mm for the neighbours of the embedded Visible Human set
# (L*_vertebra.obj) and 0.9-1.5 mm for TotalSegmentator's 3 mm example meshed here (overlap_radius on a 1 mm grid);
# a shifted, doubled or mislabelled vertebra shares far more (a doubled one: the whole bone)
MAX_OVERLAP_M = 0.004
# a surface denser than this is decimated (quadric, kept only where it stays closed) before the landmarks: a CT
# surface exported at 0.3-0.5 mm has 100,000-500,000 triangles per vertebra and every step that follows (neighbour
# checks, registration, closest points) grows with the count; the shipped surfaces have 8,000-34,000 (Visible Human
# lumbar 8,052-9,262, its sacrum 26,550; the morphable mean 31,780-33,822), so they are read unchanged
MAX_WORKING_FACES = 40_000
# one body per file (:func:`single_body`; design limits): the components of a surface other than the largest are
# islands (segmentation noise, a loose voxel, a detached spur) that are dropped, unless one of them has at least
# SECOND_BODY_AREA_FRACTION of the largest one's area (a second vertebra or bone in the file: refused) or there are
# more than MAX_ISLANDS of them or together more than MAX_ISLANDS_AREA_FRACTION of its area (a noisy surface whose
# largest part may not be the whole bone: refused). The shipped surfaces (Visible Human, the morphable mean) and the
# label-volume meshes are one component each
SECOND_BODY_AREA_FRACTION = 0.10
MAX_ISLANDS = 20
MAX_ISLANDS_AREA_FRACTION = 0.05

_TOKEN = {f"l{i}": f"L{i}" for i in range(1, 6)} | {"s1": "S1", "sacrum": "S1"}


class SpecimenError(GeometryError):
    """Specimen geometry that cannot be used; the message names the file (or folder) and what is wrong."""


#: the kinds of :class:`Repair`
REPAIR_KINDS = ("merged_vertices", "degenerate_triangles", "islands_dropped", "holes_filled", "orientation",
                "inside_out", "decimation")


@dataclass
class Repair:
    level: str
    file: Path
    what: str
    kind: str = ""          # one of REPAIR_KINDS ("" for a note that changed nothing)

    def __str__(self):
        return f"{self.level} ({self.file}): {self.what}"

    def record(self) -> dict:
        return {"kind": self.kind, "what": self.what}


@dataclass
class SpecimenMeshes:
    meshes: dict                    # level -> trimesh.Trimesh, metres, the input's axes
    files: dict                     # level -> Path
    units: str
    axes: str
    repairs: list = field(default_factory=list)     # list[Repair]: what was changed to close a surface
    ignored: list = field(default_factory=list)     # list[(Path, reason)]: every file of the folder not read

    @property
    def levels(self) -> list[str]:
        return [v for v in VERTEBRA_NAMES if v in self.meshes]

    @property
    def turned(self) -> list[str]:
        """The vertebrae whose surface was wound inside-out and turned outwards (their anatomy is checked against
        the declared axes when the frame is found)."""
        return [v for v in self.levels if any(r.level == v and r.kind == "inside_out" for r in self.repairs)]

    def log(self) -> dict:
        """Per vertebra its file and repairs, and the files not read with the reason (transform.json)."""
        return {"files": {v: {"file": str(self.files[v]),
                              "repairs": [r.record() for r in self.repairs if r.level == v]} for v in self.levels},
                "ignored_files": [{"file": str(p), "reason": why} for p, why in self.ignored]}


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
                            "z superior; any: right-handed coordinates at any angle, the orientation from the "
                            "anatomy alone)")


def _is_volume(p: Path) -> bool:
    return p.is_file() and p.name.lower().endswith((".nii.gz", ".nii"))


def input_kind(path, pattern: str | None = None) -> str:
    """"label_volume" for a NIfTI file or a folder whose vertebrae are NIfTI masks, else "meshes". A folder whose
    file names give vertebrae both as masks and as surfaces is a :class:`SpecimenError` naming both (which of them
    the user means is not guessed); surface files that name no vertebra beside the masks (a preview) are not read
    and listed as such (:func:`unread_files`)."""
    p = Path(path)
    if p.is_file():
        return "label_volume" if _is_volume(p) else "meshes"
    if p.is_dir():
        vols, _ = _scan(p, pattern, keep=_is_volume)
        surfs, _ = _scan(p, pattern, keep=_is_mesh)
        if vols and surfs:
            def names(found):
                return ", ".join(f.name for lv in VERTEBRA_NAMES for f in found.get(lv, []))
            raise SpecimenError(f"{p}: the folder holds vertebrae both as label masks ({names(vols)}) and as surfaces "
                                f"({names(surfs)}); expected one kind: move the other files out (or give the folder "
                                "of one kind)")
        if vols or (any(_is_volume(f) for f in p.iterdir()) and not any(_is_mesh(f) for f in p.iterdir())):
            return "label_volume"
    return "meshes"


def unread_files(path, used, kind: str = "meshes", pattern: str | None = None) -> list[tuple[Path, str]]:
    """Every entry of the folder ``path`` that is not in ``used`` (the files read), with the reason it was not read:
    a file name naming no level or several, not matching ``pattern``, a file of the other kind (a surface among
    label masks, a mask among surfaces), another file type, a sub-folder. Empty when ``path`` is not a folder."""
    folder = Path(path)
    if not folder.is_dir():
        return []
    used = {Path(u) for u in used}
    keep = _is_mesh if kind == "meshes" else _is_volume
    _, named = _scan(folder, pattern, keep)
    reasons = {q: r for q, r in named}
    what = (f"a surface file ({', '.join(MESH_SUFFIXES)})" if kind == "meshes"
            else "a NIfTI mask (.nii, .nii.gz)")
    out = []
    for q in sorted(folder.iterdir()):
        if q in used:
            continue
        if q in reasons:
            why = reasons[q]
        elif q.is_dir():
            why = "a folder (sub-folders are not searched)"
        elif kind == "meshes" and _is_volume(q):
            why = "a label volume (NIfTI); this folder is read as vertebra surfaces"
        elif kind != "meshes" and _is_mesh(q):
            why = "a surface file; this folder is read as label masks"
        else:
            why = f"not {what}"
        out.append((q, why))
    return out


def _scan(path, pattern: str | None, keep=_is_mesh) -> tuple[dict[str, list[Path]], list[tuple[Path, str]]]:
    """Level -> the files of folder ``path`` (those ``keep`` accepts) naming it, and the files naming none."""
    folder = Path(path)
    if not folder.is_dir():
        raise SpecimenError(f"{folder}: specimen folder missing (expected a folder of vertebra surfaces, "
                            "e.g. L4.stl, L5.stl)")
    files = sorted(p for p in folder.iterdir() if keep(p))
    found: dict[str, list[Path]] = {}
    ignored: list[tuple[Path, str]] = []
    if pattern is None:
        for p in files:
            lv = level_of(p.name)
            if len(lv) == 1:
                found.setdefault(lv[0], []).append(p)
            else:
                ignored.append((p, "the name gives no level (expected L1..L5, S1 or sacrum as a word of its own, "
                                   "e.g. spec12_L4.stl; or pass pattern)" if not lv
                                else f"the name gives several levels {lv}"))
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


#: the largest extent of a lumbar vertebra or the sacrum, about (m): the size the units hint compares with
TYPICAL_EXTENT_M = 0.08


def _units_hint(extent_m: float, units: str) -> str:
    """Which declared unit the file's numbers fit; else the power of ten they are off by (e.g. centimetres given
    as millimetres: 10 times too small)."""
    raw = extent_m / UNITS[units]            # the size in the file's numbers
    fits = [u for u, f in UNITS.items() if MIN_EXTENT_M <= raw * f <= MAX_EXTENT_M]
    if fits:
        return f"the numbers fit units={fits[0]!r}"
    if not np.isfinite(raw) or raw <= 0:
        return f"the numbers fit neither {list(UNITS)}"
    k = 10.0 ** round(float(np.log10(TYPICAL_EXTENT_M / extent_m)))      # what brings it to a vertebra's size
    guess = {10.0: " (centimetres?)", 0.1: " (tenths of a millimetre?)", 1e-3: " (micrometres?)"}.get(k, "")
    return (f"the numbers fit neither {list(UNITS)}: they are about {1 / k:g} times a vertebra's size in "
            f"{units}{guess}; multiply the coordinates by {k:g}")


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


def single_body(mesh, level: str, file: Path):
    """The largest connected part of ``mesh`` (triangles joined by shared edges, by area) and the repairs: the other
    parts (islands) dropped when they are few and tiny; a :class:`SpecimenError` naming ``file`` when one of them has
    at least ``SECOND_BODY_AREA_FRACTION`` of the largest one's area (two bodies in one file) or when there are more
    than ``MAX_ISLANDS`` or together more than ``MAX_ISLANDS_AREA_FRACTION`` of its area (a noisy surface). Returns
    (mesh, list[Repair])."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    faces = np.asarray(mesh.faces)
    if len(faces) == 0:
        return mesh, []
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(faces))
    area = np.bincount(labels, weights=np.asarray(mesh.area_faces))
    if len(area) == 1:
        return mesh, []
    order = np.argsort(-area, kind="stable")
    main, rest = area[order[0]], area[order[1:]]
    if main <= 0:
        return mesh, []
    if rest[0] >= SECOND_BODY_AREA_FRACTION * main:
        raise SpecimenError(f"{file}: {level} surface holds {len(area)} separate parts, the second "
                            f"{rest[0] / main:.0%} of the largest one's area: a second body (another vertebra or "
                            "bone, or an inner surface); expected one vertebra per file, its largest part at least "
                            f"{1 / SECOND_BODY_AREA_FRACTION:.0f} times the area of any other")
    if len(rest) > MAX_ISLANDS or rest.sum() > MAX_ISLANDS_AREA_FRACTION * main:
        raise SpecimenError(f"{file}: {level} surface holds {len(rest)} fragments beside its largest part, together "
                            f"{rest.sum() / main:.1%} of its area: a noisy surface; expected one closed vertebra "
                            f"surface (at most {MAX_ISLANDS} tiny islands, together at most "
                            f"{MAX_ISLANDS_AREA_FRACTION:.0%} of its area, are dropped): keep the segmentation's "
                            "largest connected part before exporting")
    keep = labels == order[0]
    out = trimesh.Trimesh(np.asarray(mesh.vertices), faces[keep], process=True)
    return out, [Repair(level, file, f"dropped {len(rest)} island(s) not connected to the vertebra (largest "
                                     f"{rest[0] / main:.2%}, together {rest.sum() / main:.2%} of its area)",
                        "islands_dropped")]


def close_surface(mesh, level: str, file: Path, max_hole_m: float = MAX_HOLE_PERIMETER_M,
                  turn_inside_out: bool = False, axes: str = "LPS"):
    """The mesh closed and oriented: repeated and degenerate triangles removed, holes whose boundary is at most
    ``max_hole_m`` long filled (a fan from the hole's centre), inconsistently oriented triangles turned (trimesh);
    returns (mesh, list[Repair]) naming each change. A larger hole, an edge shared by three faces, or a surface
    still open or inconsistent afterwards is a :class:`SpecimenError` naming ``file``.

    A surface whose triangles all wind inwards (negative enclosed volume) is turned outwards and the repair says so
    (kind ``inside_out``). Tools that mesh label maps whose voxel axes run against the patient axes write such
    surfaces on correct coordinates; so does a mirrored export (one axis flipped without re-ordering the faces).
    The two differ in the anatomy: a mirror about the antero-posterior or the superior-inferior axis puts the
    vertebral bodies posterior or the column upside down against the declared axes, which
    :func:`lumbar.geometry.specimen.align_to_project` and :func:`check_neighbours` refuse; a mirror about the
    left-right axis alone cannot be told (a vertebra is nearly its own mirror image), as with outward faces. With
    ``axes="any"`` no declared axis can show a mirror: the surface is refused unless ``turn_inside_out`` (the user
    states that the coordinates are not mirrored). A surface that needed its orientation made consistent and then
    enclosed a negative volume is turned either way (kind ``orientation``)."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    repairs: list[Repair] = []
    keep = mesh.unique_faces() & mesh.nondegenerate_faces()
    if not keep.all():
        mesh = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=True)
        repairs.append(Repair(level, file, f"removed {int((~keep).sum())} repeated or degenerate triangle(s)",
                              "degenerate_triangles"))
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
        repairs.append(Repair(level, file, f"filled {len(loops)} hole(s), boundary up to {max(per) * 1e3:.1f} mm",
                              "holes_filled"))
        if not mesh.is_watertight:
            raise SpecimenError(f"{file}: {level} surface is not closed after filling its holes; expected one "
                                "closed surface per vertebra")
    mixed = not mesh.is_winding_consistent
    if mixed:
        trimesh.repair.fix_winding(mesh)
        if mesh.is_winding_consistent:
            repairs.append(Repair(level, file, "triangles turned to one consistent orientation", "orientation"))
    if not mesh.is_winding_consistent:
        raise SpecimenError(f"{file}: {level} surface has inconsistent triangle orientation (some faces inside-out); "
                            "expected a consistently oriented closed surface")
    if mesh.volume < 0:
        vol = mesh.volume * 1e6
        if mixed:
            mesh.invert()
            repairs.append(Repair(level, file, "surface inside-out after its orientation was made consistent "
                                               f"(enclosed volume {vol:.3g} cm^3): turned outwards", "orientation"))
            return mesh, repairs
        if str(axes).lower() == "any" and not turn_inside_out:
            raise SpecimenError(
                f"{file}: {level} surface is inside-out (every triangle winds inwards, enclosed volume {vol:.3g} "
                "cm^3) and the axes are 'any': without declared axes the anatomy cannot tell a mirrored export (one "
                "axis flipped without re-ordering the faces: left and right exchanged) from a tool that writes "
                "inward faces on correct coordinates. Declare the axes (LPS, RAS or project: the anatomy is then "
                "checked against them), or pass --turn-inside-out (geometry.turn_inside_out: true) if the "
                "coordinates are not mirrored")
        mesh.invert()
        why = ("turn_inside_out: the user states the coordinates are not mirrored" if str(axes).lower() == "any"
               else f"the anatomy is checked against the declared axes {axes}; a mirror about the left-right axis "
                    "alone cannot be told")
        repairs.append(Repair(level, file, f"every triangle wound inwards (enclosed volume {vol:.3g} cm^3): turned "
                                           f"outwards ({why})", "inside_out"))
    return mesh, repairs


def check_levels(files: dict, require, where) -> None:
    """No vertebra missing between the highest and the lowest present, and every one of ``require`` (vertebrae
    ``"L4"`` or units ``"L4-L5"``) present; ``files``: level -> file; ``where`` (the folder) starts the message."""
    need = set()
    for r in [require] if isinstance(require, str) else (require or []):
        if r in LEVEL_NAMES:
            need.update(level_vertebrae(r))
        elif r in VERTEBRA_NAMES:
            need.add(r)
        else:
            raise SpecimenError(f"require={r!r}: expected vertebrae {list(VERTEBRA_NAMES)} or units {list(LEVEL_NAMES)}")
    present = [v for v in VERTEBRA_NAMES if v in files]
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
        found = ", ".join(f"{k}: {Path(files[k]).name}" for k in present)
        raise SpecimenError(f"{Path(where)}: {'; '.join(why)}; found {found}")


def check_size(mesh, level: str, file, units: str) -> None:
    """A vertebra (metres) spans ``MIN_EXTENT_M``..``MAX_EXTENT_M``; else the message says which unit fits."""
    ext = float(np.max(mesh.extents))
    if not MIN_EXTENT_M <= ext <= MAX_EXTENT_M:
        raise SpecimenError(f"{file}: {level} is {ext:.3g} m across with units={units!r}; expected "
                            f"{MIN_EXTENT_M}-{MAX_EXTENT_M} m for a lumbar vertebra or the sacrum "
                            f"(lumbar.geometry.checks): {_units_hint(ext, units)}")


def working_density(mesh, level: str, file: Path, max_faces: int = MAX_WORKING_FACES):
    """``mesh`` with at most ``max_faces`` triangles (quadric decimation, trimesh / fast-simplification), kept only
    where it stays a closed, consistently oriented surface of positive volume; (mesh, list[Repair]): the repair
    names the counts and how far the decimated surface lies from the input's vertices (largest and 99th
    percentile, by the decimated surface's closest points of a strided sample). A denser surface whose
    decimation opens it is kept as it is (slower, never wrong), and the log says so."""
    if len(mesh.faces) <= max_faces:
        return mesh, []
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    n0 = len(mesh.faces)
    # decimated in millimetres: in metres the simplifier's merge of coincident vertices (an absolute tolerance)
    # joins distinct vertices of a bone surface and opens it
    mm = trimesh.Trimesh(np.asarray(mesh.vertices) * 1e3, np.asarray(mesh.faces), process=False)
    dec = mm.simplify_quadric_decimation(face_count=max_faces)
    dec = trimesh.Trimesh(np.asarray(dec.vertices) * 1e-3, np.asarray(dec.faces), process=False)
    if not (dec.is_watertight and dec.is_winding_consistent and dec.volume > 0):
        return mesh, [Repair(level, file, f"not decimated: decimating {n0} to {max_faces} triangles opened the "
                                          "surface; the landmarks take longer on the full surface")]   # a note
    v = np.asarray(mesh.vertices)[:: max(1, len(mesh.vertices) // 2000)]
    d = closest_point(dec, v)[1]
    return dec, [Repair(level, file, f"decimated {n0} -> {len(dec.faces)} triangles for the landmarks (the input's "
                                     f"vertices lie within {np.max(d) * 1e3:.2f} mm of the decimated surface, 99 % "
                                     f"within {np.quantile(d, 0.99) * 1e3:.2f} mm)", "decimation")]


def read_specimen(path, units: str = "mm", axes: str = "LPS", pattern: str | None = None,
                  require=None, max_hole_m: float = MAX_HOLE_PERIMETER_M,
                  turn_inside_out: bool = False, max_faces: int = MAX_WORKING_FACES) -> SpecimenMeshes:
    """Read and check a folder of vertebra surfaces (see the module doc); ``require``: vertebrae (``"L4"``) or
    units (``"L4-L5"``) that must be present; ``turn_inside_out``: see :func:`close_surface` (with ``axes="any"``
    an inside-out surface is an error otherwise); ``max_faces``: see :func:`working_density`. Returns the meshes in
    metres, in the input's axes, with the repair log and the files of the folder not read (``ignored``)."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    check_units_axes(units, axes)
    files = find_level_files(path, pattern)
    ignored = unread_files(path, files.values(), "meshes", pattern)
    check_levels(files, require, path)
    scale = UNITS[units]
    meshes, repairs = {}, []
    for lv, f in files.items():
        vertices, faces = read_mesh_arrays(f)
        if not np.all(np.isfinite(vertices)):
            raise SpecimenError(f"{f}: {lv} mesh has {int(np.sum(~np.all(np.isfinite(vertices), axis=1)))} vertices "
                                "with non-finite coordinates (NaN or infinite); expected finite numbers")
        mesh = trimesh.Trimesh(vertices * scale, faces, process=True)
        # a vertex repeated per face (STL; OBJ vertices split by their texture coordinates) is the format's, not a
        # repair; distinct vertices merged (within trimesh's 10 nm in metres) or unused ones dropped are
        distinct = len(np.unique(vertices, axis=0))
        if len(mesh.vertices) < distinct:
            repairs.append(Repair(lv, f, f"{distinct - len(mesh.vertices)} distinct vertices merged (within 10 nm) or "
                                         "dropped (used by no triangle)", "merged_vertices"))
        mesh, rep = single_body(mesh, lv, f)
        repairs += rep
        if len(mesh.faces) < 4:
            raise SpecimenError(f"{f}: {lv} mesh has {len(mesh.faces)} triangle(s); expected a closed vertebra surface")
        check_size(mesh, lv, f, units)
        mesh, rep = close_surface(mesh, lv, f, max_hole_m, turn_inside_out=turn_inside_out, axes=axes)
        repairs += rep
        mesh, rep = working_density(mesh, lv, f, max_faces)
        repairs += rep
        meshes[lv] = mesh
    inside_out = [r.level for r in repairs if r.kind == "inside_out"]
    hint = ABOVE_HINT_SURFACES if not inside_out else (
        f"The surfaces of {', '.join(inside_out)} were wound inside-out: with the column upside down, the signature "
        "of an export mirrored about the superior-inferior axis. " + ABOVE_HINT_SURFACES)
    check_neighbours(meshes, files, axes, hint=hint)
    return SpecimenMeshes(meshes=meshes, files=files, units=units, axes=axes, repairs=repairs, ignored=ignored)


def read_specimen_meshes(path, units: str = "mm", axes: str = "LPS", pattern: str | None = None,
                         turn_inside_out: bool = False) -> dict:
    """Level -> ``trimesh.Trimesh`` in metres, in the input's own axes (no axis change; the caller aligns),
    validated (:func:`read_specimen`; its ``repairs`` say what was closed)."""
    return read_specimen(path, units=units, axes=axes, pattern=pattern, turn_inside_out=turn_inside_out).meshes


def _dense_points(mesh) -> np.ndarray:
    return np.concatenate([np.asarray(mesh.vertices), np.asarray(mesh.triangles_center)])


#: what a "not above" error suggests, per input kind: surfaces may be declared ``any``; a label volume is always in
#: its NIfTI world (RAS), so there the masks' names or the label table are what to check
ABOVE_HINT_SURFACES = ("A specimen scanned at another angle (an in-vitro specimen lying in the scanner): axes 'any' "
                       "takes the orientation from the anatomy alone")
ABOVE_HINT_LABELS = ("A label volume is in its NIfTI world (RAS, z superior): check that each mask's file name (or "
                     "each value of the label table) names its own vertebra")


def check_neighbours(meshes: dict, files: dict, axes: str = "LPS", hint: str = ABOVE_HINT_SURFACES) -> None:
    """Neighbouring vertebrae (L4 and L5, ...) not overlapping (:func:`overlap_radius` above ``MAX_OVERLAP_M``),
    not apart (nearest points more than ``MAX_NEIGHBOUR_GAP_M``) and, with declared axes (not ``"any"``), stacked
    along their +z; ``files``: level -> what the message names (a file); ``hint``: what a "not above" error
    suggests."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - scipy.spatial where geometry is computed (docs/design.md)
    order = [v for v in VERTEBRA_NAMES if v in meshes]
    for up, lo in zip(order, order[1:]):
        A, B = meshes[up], meshes[lo]
        where = f"{up} ({files[up]}) and {lo} ({files[lo]})"
        pa, pb = _dense_points(A), _dense_points(B)
        # the gap between the two point sets: a subsample of one against all of the other bounds it from above,
        # which settles the usual case (neighbours touching, far within the limit) without querying every point;
        # only a bound above the limit is refined on all points near the other bone (and exactly for the message)
        tree = cKDTree(pb)
        gap = float(tree.query(pa[:: max(1, len(pa) // 2000)])[0].min())
        if gap > MAX_NEIGHBOUR_GAP_M:
            box_lo, box_hi = pb.min(0) - MAX_NEIGHBOUR_GAP_M, pb.max(0) + MAX_NEIGHBOUR_GAP_M
            near = pa[np.all((pa >= box_lo) & (pa <= box_hi), axis=1)]   # the rest are farther than the limit
            if len(near):
                gap = min(gap, float(tree.query(near)[0].min()))
        if gap > MAX_NEIGHBOUR_GAP_M:
            raise SpecimenError(f"{where}: neighbouring vertebrae {gap * 1e3:.0f} mm apart (nearest surface points); "
                                f"expected within {MAX_NEIGHBOUR_GAP_M * 1e3:.0f} mm (neighbours touch at their facet "
                                "joints): a vertebra shifted, or one missing between them")
        r = overlap_radius(A, B)
        if r > MAX_OVERLAP_M:
            raise SpecimenError(f"{where}: the vertebrae overlap: their common volume holds a ball of radius "
                                f"{r * 1e3:.1f} mm (allowed {MAX_OVERLAP_M * 1e3:.0f} mm); expected separate bones "
                                "(a shifted, doubled or mislabelled file?)")
        ca, cb = A.center_mass, B.center_mass
        if axes != "any" and not ca[2] > cb[2]:
            raise SpecimenError(f"{where}: {up} is not above {lo} along +z (volume centroids z = {ca[2]:.4f} m and "
                                f"{cb[2]:.4f} m); expected +z superior (LPS, RAS and the project frame all have it). "
                                f"{hint}")


def _inside_distance(mesh, pts):
    """(distance to the nearest face centre, inside by that face's normal) of ``pts``: a screen, exact enough
    away from the surface; the points that decide are confirmed by :func:`overlap_radius`. The KD-tree of the
    face centres is kept on the mesh (a vertebra is the lower and then the upper one of two neighbour pairs)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - scipy.spatial where geometry is computed (docs/design.md)
    centres = np.asarray(mesh.triangles_center)
    key = "lumbar_face_centre_tree"
    if key not in mesh._cache:
        mesh._cache[key] = cKDTree(centres)
    d, i = mesh._cache[key].query(pts)
    inside = np.einsum("ij,ij->i", pts - centres[i], np.asarray(mesh.face_normals)[i]) < 0
    return d, inside


def overlap_radius(A, B, step_m: float = 0.001, max_points: int = 15_000) -> float:
    """Radius (m) of the largest ball inside both closed surfaces A and B (0 when they do not overlap): half the
    thickness of their common volume. Grid points (``step_m``, coarser when the boxes' overlap would need more
    than ``max_points``: a ball of radius ``MAX_OVERLAP_M`` holds a grid point whenever the step is below 2 /
    sqrt(3) of it, 4.6 mm; 15,000 points keep neighbouring lumbar vertebrae at a 1-1.5 mm step) inside both, screened
    by the nearest face (:func:`_inside_distance`); the points screened
    beyond ``MAX_OVERLAP_M`` are confirmed by trimesh's ray test and measured to both surfaces exactly (the ray
    test on every point took seconds per pair of Visible Human vertebrae)."""
    lo = np.maximum(A.bounds[0], B.bounds[0])
    hi = np.minimum(A.bounds[1], B.bounds[1])
    if np.any(hi <= lo):
        return 0.0
    step = max(step_m, float(np.prod(hi - lo) / max_points) ** (1 / 3))
    axes = [np.arange(a + step / 2, b, step) for a, b in zip(lo, hi)]
    if any(len(x) == 0 for x in axes):
        return 0.0
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    da, ina = _inside_distance(A, pts)
    pts, da = pts[ina], da[ina]
    if len(pts) == 0:
        return 0.0
    db, inb = _inside_distance(B, pts)
    if not np.any(inb):
        return 0.0
    r = np.minimum(da, db)[inb]
    cand = pts[inb]
    deep = r > MAX_OVERLAP_M
    if not np.any(deep):
        return float(r.max())
    top = cand[deep][np.argsort(-r[deep])[:64]]
    top = top[A.contains(top) & B.contains(top)]
    if len(top) == 0:
        return float(r[~deep].max()) if np.any(~deep) else 0.0
    ra = closest_point(A, top)[1]
    rb = closest_point(B, top)[1]
    return float(np.minimum(ra, rb).max())


# ------------------------------------------------------------------ what the levels present allow
def buildable_units(levels) -> list[str]:
    """The units (``"L1-L2"`` .. ``"L5-S1"``) whose two vertebrae are among ``levels``."""
    have = set(levels)
    return [u for u in LEVEL_NAMES if set(level_vertebrae(u)) <= have]


def skipped_stages(levels, calibrated_level: str = "L4-L5", other_levels=None) -> list[tuple[str, str]]:
    """(stage, reason) for every workflow stage the vertebrae ``levels`` cannot feed; empty when all can run.

    Stages by their configuration section: ``fsu``, ``stepwise_reduction`` and ``calibration`` on the calibrated
    unit (``fsu.level``), ``l2s1`` (the L2-S1 model with cables and the L4-L5 IDP; discovery on IDP data uses it),
    ``muscle_model`` (without a sacrum), ``load_sharing.other_levels <unit>`` (the calibrated characteristics on the
    other units; default all four)."""
    have = set(levels)
    units = buildable_units(have)
    out = []

    def missing(vs):
        return ", ".join(v for v in vs if v not in have)
    if calibrated_level not in LEVEL_NAMES:
        raise SpecimenError(f"calibrated level {calibrated_level!r}: expected one of {list(LEVEL_NAMES)}")
    if calibrated_level not in units:
        why = (f"no {calibrated_level} unit ({missing(level_vertebrae(calibrated_level))} missing): the calibrated "
               f"level must be named in the config (fsu.level), one of {units}" if units
               else f"no unit at all (vertebrae present: {sorted(have, key=VERTEBRA_NAMES.index)})")
        out += [(st, why) for st in ("fsu", "stepwise_reduction", "calibration")]
    l2s1 = ("L2", "L3", "L4", "L5", "S1")
    if not set(l2s1) <= have:
        why = ("no sacrum (S1): no L5-S1 unit and no L2-S1 model" if "S1" not in have
               else f"{missing(l2s1)} missing: the L2-S1 model needs L2, L3, L4, L5 and S1")
        out.append(("l2s1", why))
    if "S1" not in have:
        out.append(("muscle_model", "no sacrum (S1): the muscle model's spine is L1-S1 with its fascicles on the "
                    "sacrum and pelvis; it is run only for a specimen with a sacrum"))
    others = [u for u in LEVEL_NAMES if u != calibrated_level] if other_levels is None else list(other_levels)
    for u in others:
        if u not in units:
            why = ("no sacrum (S1): no L5-S1 unit" if u == "L5-S1" and "S1" not in have
                   else f"no {u} unit ({missing(level_vertebrae(u))} missing)")
            out.append((f"load_sharing.other_levels {u}", why))
    return out


# ------------------------------------------------------------------ label volumes (CT segmentations) -> meshes
ANATOMY_TABLE = "anatomy/l4l5_magnitudes_original_text.csv"
NIFTI_UNITS_MM = {"unknown": 1.0, "mm": 1.0, "meter": 1000.0, "micron": 1e-3}   # xyzt_units -> mm


def resolution_limits(voxel_mm) -> list[dict]:
    """What a label volume with voxel edges ``voxel_mm`` (mm) can and cannot support, one dict per feature
    (``feature``, ``supported``, ``reason``). Facet articular surfaces: the two faces of a joint are separated by
    the joint space (sourced in data/anatomy/l4l5_magnitudes_original_text.csv, its low end mean - 1 SD); a gap of
    width w always contains a whole voxel only if the voxel edge is at most w / 2, so larger voxels can merge the
    two faces and cannot place them."""
    import pandas as pd  # noqa: PLC0415 - only the meshing report reads the anatomy table
    from ..inputs import resources  # noqa: PLC0415 - data location, only for the meshing report
    a = pd.read_csv(resources.data_dir() / ANATOMY_TABLE).set_index("quantity").loc["facet_joint_space_width"]
    low, high = float(a["low"]), float(a["high"])
    vmax = float(np.max(voxel_mm))
    ok = vmax <= low / 2
    return [
        {"feature": "facet articular surfaces (facet landmarks, joint gap, contact surface)", "supported": ok,
         "reason": (f"largest voxel edge {vmax:g} mm {'<=' if ok else '>'} half the facet joint space "
                    f"(mean -+ 1 SD {low:g}-{high:g} mm, {a['source'].split(';')[0]}): "
                    + ("the joint space is resolved" if ok else "the two articular faces can fall into the same or "
                       "touching voxels; facet landmarks from these meshes are not measurements"))},
        {"feature": "vertebral body and disc dimensions (disc height, endplate area)", "supported": True,
         "reason": f"each surface is placed to within about half a voxel ({vmax / 2:g} mm); a disc height or "
                   "endplate width from these meshes carries that uncertainty on both of its sides"},
    ]


def _read_nifti(path: Path):
    import nibabel  # noqa: PLC0415 - NIfTI reader, only for label volumes
    try:
        img = nibabel.load(str(path))
        data = np.asarray(img.dataobj)
    except Exception as exc:  # noqa: BLE001 - nibabel and gzip raise many types; all mean "not readable"
        raise SpecimenError(f"{path}: label volume not readable ({type(exc).__name__}: {exc}); expected a NIfTI "
                            "file (.nii or .nii.gz)") from exc
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    if data.ndim != 3:
        raise SpecimenError(f"{path}: label volume has shape {data.shape}; expected a 3-D volume")
    aff = np.asarray(img.affine, float)
    if not np.all(np.isfinite(aff)) or abs(np.linalg.det(aff[:3, :3])) < 1e-12:
        raise SpecimenError(f"{path}: the NIfTI affine is singular or not finite; expected the voxel-to-world map "
                            "(RAS, millimetres)")
    # the header's spatial unit (NIfTI: millimetres unless it says otherwise); the meshes are written in millimetres
    get_units = getattr(img.header, "get_xyzt_units", None)
    unit = get_units()[0] if get_units else "unknown"
    to_mm = NIFTI_UNITS_MM.get(unit)
    if to_mm is None:
        raise SpecimenError(f"{path}: NIfTI spatial unit {unit!r}; expected one of {sorted(NIFTI_UNITS_MM)}")
    aff[:3, :] *= to_mm
    return data, aff


def _mask_to_mesh(mask: np.ndarray, affine: np.ndarray, smooth_iterations: int, max_faces: int):
    """Closed surface (world millimetres) of the largest connected part of ``mask``, its enclosed cavities filled
    (a gap in a bone's segmentation, whose inner surface is not the bone's); (mesh, voxels dropped, voxels filled,
    what the decimation did: a decimation that opens the surface is not kept)."""
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    from scipy import ndimage  # noqa: PLC0415 - connected parts of the mask, only for label volumes
    from skimage.measure import marching_cubes  # noqa: PLC0415 - scikit-image (1 s import), only for label volumes
    lab, n = ndimage.label(mask)
    dropped = 0
    if n > 1:
        sizes = np.bincount(lab.ravel())[1:]
        keep = int(np.argmax(sizes)) + 1
        dropped = int(sizes.sum() - sizes[keep - 1])
        mask = lab == keep
    full = ndimage.binary_fill_holes(mask)
    filled = int(full.sum() - mask.sum())
    mask = full
    idx = np.argwhere(mask)
    lo, hi = idx.min(axis=0), idx.max(axis=0) + 1
    crop = np.pad(mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]], 1).astype(np.float32)   # closed at the border
    verts, faces, _, _ = marching_cubes(crop, level=0.5)
    ijk = verts + lo - 1
    world = ijk @ affine[:3, :3].T + affine[:3, 3]
    mesh = trimesh.Trimesh(world, faces, process=True)
    if mesh.volume < 0:
        mesh.invert()
    if smooth_iterations:
        trimesh.smoothing.filter_taubin(mesh, lamb=0.5, nu=0.53, iterations=smooth_iterations)
    note = "none"
    if len(mesh.faces) > max_faces:
        dec = mesh.simplify_quadric_decimation(face_count=max_faces)
        if dec.is_watertight and dec.is_winding_consistent and dec.volume > 0:
            note = f"{len(mesh.faces)} -> {len(dec.faces)} triangles"
            mesh = dec
        else:
            note = f"skipped: decimating {len(mesh.faces)} to {max_faces} triangles opened the surface"
    return mesh, dropped, filled, note


def _volume_inputs(path: Path, label_table, pattern=None) -> list[tuple[str, Path, int | None]]:
    """(level, file, voxel value or None for a binary mask) of a folder of masks or a multi-label file."""
    if path.is_dir():
        if label_table is not None:
            raise SpecimenError(f"{path}: a folder of per-structure masks takes no label_table (each file is one "
                                "vertebra, named vertebrae_L4.nii.gz or sacrum.nii.gz); pass a multi-label file with it")
        found, _ = _scan(path, pattern, keep=_is_volume)
        clash = {lv: ps for lv, ps in found.items() if len(ps) > 1}
        if clash:
            raise SpecimenError(f"{path}: several masks for one level ("
                                + "; ".join(f"{lv}: {', '.join(p.name for p in ps)}" for lv, ps in clash.items())
                                + "); pass pattern= (a glob with {level}, e.g. 'vertebrae_{level}.nii.gz') to "
                                "choose one per level")
        if not found:
            raise SpecimenError(f"{path}: no vertebra masks found; expected TotalSegmentator's per-structure files "
                                "vertebrae_L1.nii.gz .. vertebrae_L5.nii.gz, sacrum.nii.gz (or one multi-label "
                                "NIfTI file with a label_table)")
        return [(lv, found[lv][0], None) for lv in VERTEBRA_NAMES if lv in found]
    if not path.is_file():
        raise SpecimenError(f"{path}: label volume missing (expected a folder of masks or a NIfTI file)")
    if label_table is None:
        raise SpecimenError(f"{path}: a multi-label volume needs label_table= (a CSV with columns label,value, e.g. "
                            "'L4,24'); the voxel values of a segmentation are not guessed")
    from ..inputs.io import TableError  # noqa: PLC0415 - table reading only for multi-label volumes
    from ..inputs.tables import read_kind  # noqa: PLC0415
    try:
        t = read_kind(label_table, "label_table")
    except TableError as exc:
        raise SpecimenError(str(exc)) from exc
    out, seen = [], {}
    for row, (lab, val) in enumerate(zip(t["label"], t["value"]), 1):
        lv = level_of(lab)
        if len(lv) != 1:
            raise SpecimenError(f"{label_table}: row {row}, column label: {lab!r} names "
                                f"{'no level' if not lv else f'several levels {lv}'}; expected one of L1..L5, S1, sacrum")
        if lv[0] in seen:
            raise SpecimenError(f"{label_table}: rows {seen[lv[0]]} and {row} both name {lv[0]}; expected one row per "
                                "vertebra")
        seen[lv[0]] = row
        out.append((lv[0], path, int(val)))
    vals = [v for _, _, v in out]
    if len(set(vals)) != len(vals):
        raise SpecimenError(f"{label_table}: one voxel value for two vertebrae ({vals}); expected distinct values")
    return sorted(out, key=lambda r: VERTEBRA_NAMES.index(r[0]))


def volume_files(path, label_table=None, pattern: str | None = None) -> dict[str, Path]:
    """Level -> NIfTI file of a label volume input (a folder of per-structure masks or one multi-label file with
    ``label_table``), with the checks :func:`label_volume_to_meshes` runs before reading any voxel (file names,
    the label table, no vertebra missing between the highest and the lowest present); nothing is read but the
    folder listing and the label table."""
    path = Path(path)
    items = _volume_inputs(path, label_table, pattern)
    files = {lv: f for lv, f, _ in items}
    check_levels(files, None, path)
    return files


def label_volume_to_meshes(path, out_dir, label_table=None, *, pattern: str | None = None, require=None,
                           smooth_iterations: int = 10, max_faces: int = 20000) -> dict[str, Path]:
    """Mesh a CT segmentation into the mesh-folder form: ``out_dir/<level>.stl`` in millimetres, RAS (NIfTI
    world), one closed surface per vertebra; read them with ``read_specimen(out_dir, units="mm", axes="RAS")``.

    ``path``: TotalSegmentator's per-structure masks (a folder with ``vertebrae_L1.nii.gz`` ..
    ``vertebrae_L5.nii.gz``, ``sacrum.nii.gz``) or one multi-label NIfTI file with ``label_table`` (CSV
    ``label,value``); ``pattern`` picks one mask per level where a folder holds several (TotalSegmentator 2 writes
    ``sacrum.nii.gz`` and ``vertebrae_S1.nii.gz``: ``pattern="vertebrae_{level}.nii.gz"`` takes the latter).
    Marching cubes (scikit-image) on each mask's largest connected part, its enclosed cavities filled, at the
    header's affine
    (voxel spacing, orientation), Taubin smoothing (``smooth_iterations``; keeps the volume, unlike plain Laplacian
    smoothing), quadric decimation to at most ``max_faces`` triangles (kept only where the result stays closed).
    Before anything is written, the meshes pass the reader's checks (:func:`check_levels` with ``require``, size,
    closed, neighbours), each error naming the NIfTI file (and the label value).
    Also writes ``out_dir/meshing_report.csv`` (per vertebra: source, voxel size, voxels, voxels of smaller parts
    dropped, voxels of enclosed cavities filled, what the decimation did, triangles) and ``out_dir/resolution_limits.csv`` (:func:`resolution_limits`: what the voxel size cannot
    support). Returns level -> STL path.
    """
    import pandas as pd  # noqa: PLC0415 - only the meshing report writes tables
    from ..inputs.io import write_table_atomic  # noqa: PLC0415 - atomic writes, only for the meshing report
    path = Path(path)
    items = _volume_inputs(path, label_table, pattern)
    check_levels({lv: f for lv, f, _ in items}, require, path)
    cache: dict[Path, tuple] = {}
    uses = {f: sum(g == f for _, g, _ in items) for _, f, _ in items}
    masks = []
    for lv, f, val in items:            # every volume read and checked before any meshing
        if f not in cache:
            cache[f] = _read_nifti(f)
        data, aff = cache[f]
        uses[f] -= 1
        if uses[f] == 0:                # the last label of this file: its volume is not kept
            del cache[f]
        if val is None:
            mask = data > 0.5
            if not mask.any():
                raise SpecimenError(f"{f}: the {lv} mask is empty (no voxel above 0.5); expected the vertebra's voxels")
        else:
            mask = data == val
            if not mask.any():
                present = np.unique(data[data != 0]).astype(float)
                raise SpecimenError(f"{f}: no voxel has the value {val} of {lv} (label table {label_table}); values "
                                    f"present: {present[:20].tolist()}{' ...' if len(present) > 20 else ''}")
        # kept as the mask's bounding box and the affine of its first voxel: six full-size masks of a 512^3 CT
        # would hold 0.8 GB
        nz = [np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != k))) for k in range(3)]
        lo = np.array([n[0] for n in nz])
        hi = np.array([n[-1] + 1 for n in nz])
        shift = np.eye(4)
        shift[:3, 3] = lo
        masks.append((lv, f, val, mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].copy(), aff @ shift))
    built, rows, sources = {}, [], {}
    for lv, f, val, mask, aff in masks:
        spacing = np.linalg.norm(aff[:3, :3], axis=0)
        mesh, dropped, filled, decimation = _mask_to_mesh(mask, aff, smooth_iterations, max_faces)
        where = f if val is None else f"{f} (value {val})"
        metres = mesh.copy()
        metres.apply_scale(1e-3)
        check_size(metres, lv, where, "mm")
        if not (mesh.is_watertight and mesh.is_winding_consistent):
            raise SpecimenError(f"{where}: the {lv} surface meshed from the mask is not closed; expected a closed "
                                "surface (report this volume)")
        built[lv], sources[lv] = (mesh, metres), where
        rows.append({"level": lv, "source": f.name, "label_value": "" if val is None else val,
                     "voxel_mm": "x".join(f"{s:g}" for s in spacing), "n_voxels": int(mask.sum()),
                     "voxels_dropped": dropped, "voxels_filled": filled, "decimation": decimation,
                     "n_faces": len(mesh.faces),
                     "units": "mm", "axes": "RAS"})
    check_neighbours({lv: m for lv, (_, m) in built.items()}, sources, hint=ABOVE_HINT_LABELS)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = {}
    for lv, (mesh, _) in built.items():
        dest = out_dir / f"{lv}.stl"
        tmp = dest.with_name(f".{dest.name}.tmp")
        mesh.export(str(tmp), file_type="stl")
        tmp.replace(dest)
        written[lv] = dest
    write_table_atomic(pd.DataFrame(rows), out_dir / "meshing_report.csv")
    spacing = np.max([np.linalg.norm(a[:3, :3], axis=0) for _, _, _, _, a in masks], axis=0)
    write_table_atomic(pd.DataFrame(resolution_limits(spacing)), out_dir / "resolution_limits.csv")
    return written
