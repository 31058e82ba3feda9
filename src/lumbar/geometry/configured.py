"""The geometry a configuration's ``geometry:`` section names -> :class:`SpineGeometry` (what every workflow job
loads), and a user's specimen through the workflow.

Kinds: ``visible_human`` and ``myo_sim`` (:func:`lumbar.geometry.loader.load_geometry`), and a user's specimen:
``meshes`` (a folder of vertebra surfaces: ``path``, ``units`` mm|m, ``axes`` LPS|RAS|project, optional
``pattern``; :mod:`lumbar.geometry.specimen_io`) or ``label_volume`` (a CT segmentation: a folder of
TotalSegmentator masks, or one multi-label NIfTI file with ``label_table``; meshed by
:func:`lumbar.geometry.specimen_io.label_volume_to_meshes` in millimetres, RAS). A specimen is built by
:func:`lumbar.geometry.specimen_build.build_specimen` (alignment, registration of the atlas, discs, facets).

Checks first (:func:`specimen_inputs`, :func:`check_config`): the names of the files, the levels present, units and
axes, the calibrated unit (``fsu.level``) among the units present, before any mesh is read.

Cache: building a specimen takes seconds per vertebra, and dozens of workflow jobs load its geometry. The built
geometry is kept in :mod:`lumbar.geometry.diskcache` (kind ``specimen``), addressed by the SHA-256 of every input
file's bytes, the settings, the source of the modules that compute it and the atlas files: a changed input, setting,
build code or atlas gives another entry, never a stale one. With the cache switched off every job builds it again.
This module sits above :mod:`lumbar.geometry.loader` (``specimen_landmarks`` reads its atlas through the loader, so
the loader cannot import the specimen build).
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import json
import logging
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import analysis, checks, core, diskcache, meshio, register, specimen, specimen_build, specimen_io
from . import specimen_landmarks
from .core import (LEVEL_NAMES, VERTEBRA_NAMES, FacetLandmarks, GeometryError, Level, Ligament, SpineGeometry,
                   Vertebra, level_vertebrae)
from .loader import embedded_visible_human_path, load_geometry

log = logging.getLogger(__name__)

SPECIMEN_KINDS = ("meshes", "label_volume")
KINDS = ("visible_human", "myo_sim") + SPECIMEN_KINDS
#: the geometry every job of the workflow builds from the same inputs: cache kind of the built specimen
CACHE_KIND = "specimen"
# the modules whose code decides the built geometry (their source text is part of the cache address)
_BUILD_MODULES = (analysis, checks, core, meshio, register, specimen, specimen_build, specimen_io, specimen_landmarks)


@dataclass
class SpecimenInputs:
    """What the configuration names, checked: the files per vertebra and the settings of the build."""
    kind: str                       # "meshes" | "label_volume"
    path: Path
    files: dict                     # vertebra -> Path (mesh or NIfTI file)
    units: str                      # the mesh files' units ("mm" for a label volume's meshes)
    axes: str                       # the mesh files' axes ("RAS" for a label volume's meshes)
    pattern: str | None = None
    label_table: Path | None = None
    turn_inside_out: bool = False   # an inside-out mesh turned instead of refused (specimen_io.close_surface)

    @property
    def vertebrae(self) -> list[str]:
        return [v for v in VERTEBRA_NAMES if v in self.files]

    @property
    def units_present(self) -> list[str]:
        return specimen_io.buildable_units(self.vertebrae)


def specimen_inputs(g: dict) -> SpecimenInputs:
    """The checked inputs of a ``meshes`` or ``label_volume`` geometry section ``g`` (module doc); each error a
    :class:`~lumbar.geometry.specimen_io.SpecimenError` naming the configuration key, the file or folder and the
    expected form. Reads the folder listing (and a label table), never a mesh or a voxel."""
    kind = g.get("kind")
    if kind not in SPECIMEN_KINDS:
        raise GeometryError(f"geometry.kind {kind!r}: not a specimen kind; expected one of {list(SPECIMEN_KINDS)}")
    if not g.get("path"):
        raise specimen_io.SpecimenError(f"geometry.path missing: expected the folder of the specimen's "
                                        f"{'vertebra surfaces' if kind == 'meshes' else 'label masks'} (kind {kind})")
    path = Path(g["path"])
    pattern = g.get("pattern") or None
    if kind == "meshes":
        units, axes = g.get("units"), g.get("axes")
        for key, v in (("units", units), ("axes", axes)):
            if v is None:
                raise specimen_io.SpecimenError(
                    f"geometry.{key} missing (kind meshes, path {path}): expected "
                    + ("mm or m, the unit of the files' coordinates" if key == "units" else
                       "LPS, RAS or project, the axes of the files' coordinates")
                    + " (declared, never guessed)")
        try:
            specimen_io.check_units_axes(units, axes)
        except specimen_io.SpecimenError as exc:
            raise specimen_io.SpecimenError(f"geometry (kind meshes, path {path}): {exc}") from None
        turn = g.get("turn_inside_out", False)
        if not isinstance(turn, bool):
            raise specimen_io.SpecimenError(f"geometry.turn_inside_out {turn!r} (kind meshes, path {path}): expected "
                                            "true or false")
        files = specimen_io.find_level_files(path, pattern)
        specimen_io.check_levels(files, None, path)
        return SpecimenInputs(kind, path, files, units, axes, pattern, turn_inside_out=turn)
    for key in ("units", "axes"):
        if g.get(key) not in (None, {"units": "mm", "axes": "RAS"}[key]):
            raise specimen_io.SpecimenError(f"geometry.{key} {g[key]!r} with kind label_volume: the meshes of a label "
                                            "volume are in the NIfTI header's world frame (RAS, millimetres); leave "
                                            f"geometry.{key} out")
    table = Path(g["label_table"]) if g.get("label_table") else None
    files = specimen_io.volume_files(path, table, pattern)
    return SpecimenInputs(kind, path, files, "mm", "RAS", pattern, table)


def check_config(g: dict, calibrated_level: str = "L4-L5", other_levels=None) -> list[tuple[str, str]]:
    """Check a geometry section before any computation and return the stages it cannot feed, (stage, reason)
    (:func:`lumbar.geometry.specimen_io.skipped_stages`; empty for the embedded geometries). The calibrated unit
    (``fsu.level``) must be one of the specimen's units: the error names the units present."""
    kind = g.get("kind", "visible_human")
    if kind not in KINDS:
        raise GeometryError(f"geometry.kind {kind!r}: expected one of {list(KINDS)}")
    if kind not in SPECIMEN_KINDS:
        return []
    si = specimen_inputs(g)
    units = si.units_present
    if not units:
        raise specimen_io.SpecimenError(f"{si.path}: no motion segment (vertebrae present: {si.vertebrae}); expected "
                                        "at least two neighbouring vertebrae")
    if calibrated_level not in units:
        raise specimen_io.SpecimenError(
            f"fsu.level {calibrated_level!r}: the specimen in {si.path} has no {calibrated_level} unit "
            f"(vertebrae present: {', '.join(si.vertebrae)}); expected fsu.level to name the unit to calibrate, one "
            f"of {units}")
    return specimen_io.skipped_stages(si.vertebrae, calibrated_level, other_levels)


# ------------------------------------------------------------------ the built geometry, as arrays (cache entries)
def geometry_to_arrays(geo: SpineGeometry) -> dict[str, np.ndarray]:
    """Every field of ``geo`` as named numpy arrays (no pickled objects): :func:`geometry_from_arrays` inverts it."""
    a = {"name": np.array(geo.name), "source": np.array(geo.source),
         "vertebrae": np.array(list(geo.vertebrae), dtype=str), "levels": np.array(list(geo.levels), dtype=str)}
    for v, vb in geo.vertebrae.items():
        a[f"v.{v}.vertices"] = np.array(vb.mesh.vertices, float)
        a[f"v.{v}.faces"] = np.array(vb.mesh.faces, np.int64)
        a[f"v.{v}.centroid"] = np.array(vb.centroid, float)
    for name, lev in geo.levels.items():
        p = f"l.{name}."
        a[p + "bodies"] = np.array([lev.upper, lev.lower])
        a[p + "disc"] = np.concatenate([np.array(lev.disc_centre, float), np.array(lev.disc_normal, float),
                                        [lev.disc_csa, lev.disc_height]])
        a[p + "facets"] = np.array(list(lev.facets), dtype=str)
        for side, f in lev.facets.items():
            a[p + f"f.{side}.superior"] = np.array(f.superior, float)
            a[p + f"f.{side}.inferior"] = np.array(f.inferior, float)
            a[p + f"f.{side}.contact"] = np.array(f.contact)
            if f.contact_points is not None:
                a[p + f"f.{side}.contact_points"] = np.array(f.contact_points, float)
        a[p + "ligaments"] = np.array([[g.name, g.kind] for g in lev.ligaments], dtype=str).reshape(-1, 2)
        for i, g in enumerate(lev.ligaments):
            a[p + f"g{i}.upper"] = np.array(g.upper, float)
            a[p + f"g{i}.lower"] = np.array(g.lower, float)
            a[p + f"g{i}.extra_length"] = np.array(g.extra_length, float)
    return a


def geometry_from_arrays(a: dict) -> SpineGeometry:
    import trimesh  # noqa: PLC0415 - mesh library where meshes are built (docs/design.md)
    verts = {}
    for v in a["vertebrae"].tolist():
        mesh = trimesh.Trimesh(a[f"v.{v}.vertices"], a[f"v.{v}.faces"], process=False)
        verts[v] = Vertebra(v, mesh, a[f"v.{v}.centroid"])
    levels = {}
    for name in a["levels"].tolist():
        p = f"l.{name}."
        up, lo = a[p + "bodies"].tolist()
        d = a[p + "disc"]
        facets = {side: FacetLandmarks(superior=a[p + f"f.{side}.superior"], inferior=a[p + f"f.{side}.inferior"],
                                       contact=str(a[p + f"f.{side}.contact"]),
                                       contact_points=a.get(p + f"f.{side}.contact_points"))
                  for side in a[p + "facets"].tolist()}
        ligs = [Ligament(n, k, a[p + f"g{i}.upper"], a[p + f"g{i}.lower"], a[p + f"g{i}.extra_length"])
                for i, (n, k) in enumerate(a[p + "ligaments"].tolist())]
        levels[name] = Level(name, up, lo, d[:3], d[3:6], float(d[6]), float(d[7]), facets, ligs)
    return SpineGeometry(name=str(a["name"]), source=str(a["source"]), vertebrae=verts, levels=levels)


def select_levels(geo: SpineGeometry, levels=None) -> SpineGeometry:
    """``geo`` with only ``levels`` (a name or a list; None: all) and their vertebrae; a unit the specimen does not
    have is a :class:`GeometryError` naming the units it has."""
    if levels is None:
        return geo
    want = [levels] if isinstance(levels, str) else list(levels)
    missing = [lv for lv in want if lv not in geo.levels]
    if missing:
        raise GeometryError(f"geometry {geo.name!r} has no unit {', '.join(missing)}; units present: "
                            f"{list(geo.levels)} (a stage on a missing unit is skipped by the workflow: "
                            "lumbar.geometry.specimen_io.skipped_stages)")
    order = [lv for lv in LEVEL_NAMES if lv in want]
    vs = {v for lv in order for v in level_vertebrae(lv)}
    return SpineGeometry(name=geo.name, source=geo.source,
                         vertebrae={v: b for v, b in geo.vertebrae.items() if v in vs},
                         levels={lv: geo.levels[lv] for lv in order})


# ------------------------------------------------------------------ the cache address
def _file_digest(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def build_tag() -> str:
    """Version tag of the built geometry: the source of the build modules, the atlas files and the versions of the
    libraries that mesh and register (trimesh, numpy, scipy, scikit-image)."""
    h = hashlib.sha256()
    for m in _BUILD_MODULES:
        h.update(Path(m.__file__).read_bytes())
    h.update(Path(__file__).read_bytes())
    atlas = embedded_visible_human_path()
    for f in sorted(p for p in atlas.rglob("*") if p.is_file()):
        h.update(f"{f.relative_to(atlas)}:{_file_digest(f)}".encode())
    for lib in ("trimesh", "numpy", "scipy", "scikit-image", "nibabel"):
        try:
            h.update(f"{lib} {importlib.metadata.version(lib)}".encode())
        except importlib.metadata.PackageNotFoundError:
            h.update(f"{lib} absent".encode())
    return h.hexdigest()[:32]


def cache_content(si: SpecimenInputs) -> bytes:
    """The bytes the built geometry depends on: every input file's digest by level and the settings."""
    rec = dict(kind=si.kind, units=si.units, axes=si.axes, name=si.path.name,
               files={v: _file_digest(f) for v, f in si.files.items()},
               label_table=_file_digest(si.label_table) if si.label_table else None)
    if si.turn_inside_out:
        rec["turn_inside_out"] = True
    return json.dumps(rec, sort_keys=True).encode()


# ------------------------------------------------------------------ building and loading
@dataclass
class SpecimenBuild:
    inputs: SpecimenInputs
    read: specimen_io.SpecimenMeshes          # the validated meshes (repairs, ignored files)
    specimen: specimen_build.Specimen         # geometry, alignment, landmarks, facet gaps
    mesh_dir: Path | None = None              # a label volume's meshes (meshing_report.csv, resolution_limits.csv)


def build(g: dict, mesh_dir=None) -> SpecimenBuild:
    """Build the specimen a geometry section names (checks first, :func:`specimen_inputs`) and keep its geometry in
    the cache. A label volume is meshed into ``mesh_dir`` (default a temporary folder, removed afterwards)."""
    si = specimen_inputs(g)
    if si.kind == "label_volume" and mesh_dir is None:
        with tempfile.TemporaryDirectory(prefix="lumbar_label_meshes_") as tmp:
            out = _build(si, Path(tmp))
            out.mesh_dir = None
            return out
    return _build(si, Path(mesh_dir) if mesh_dir is not None else None)


def _meshing_repairs(si: SpecimenInputs, mesh_dir: Path) -> list:
    """The label volume's meshing as repairs (per vertebra: the voxels of smaller parts dropped, the decimation),
    from ``mesh_dir/meshing_report.csv``, naming the NIfTI file."""
    import pandas as pd  # noqa: PLC0415 - only the label-volume report reads tables
    rep = pd.read_csv(mesh_dir / "meshing_report.csv", keep_default_na=False)
    out = []
    for r in rep.itertuples():
        f = si.files.get(r.level, si.path)
        if int(r.voxels_dropped):
            out.append(specimen_io.Repair(r.level, f, f"kept the mask's largest connected part: {int(r.voxels_dropped)} "
                                          f"voxel(s) of smaller parts dropped (of {int(r.n_voxels) + int(r.voxels_dropped)})",
                                          "islands_dropped"))
        if int(getattr(r, "voxels_filled", 0) or 0):
            out.append(specimen_io.Repair(r.level, f, f"filled {int(r.voxels_filled)} voxel(s) of cavities enclosed by "
                                          "the mask (a gap in the segmentation, not a surface of the bone)",
                                          "holes_filled"))
        if str(r.decimation) not in ("none", ""):
            out.append(specimen_io.Repair(r.level, f, f"meshed surface decimated: {r.decimation}",
                                          "decimation" if not str(r.decimation).startswith("skipped") else ""))
    return out


def _build(si: SpecimenInputs, mesh_dir: Path | None) -> SpecimenBuild:
    if si.kind == "label_volume":
        specimen_io.label_volume_to_meshes(si.path, mesh_dir, si.label_table, pattern=si.pattern)
        read = specimen_io.read_specimen(mesh_dir, units="mm", axes="RAS")
        sources = {v: str(si.files[v]) for v in read.files}
        # the record names the user's files, not the meshes made from them
        read.repairs = _meshing_repairs(si, mesh_dir) + read.repairs
        read.files = {v: si.files[v] for v in read.files}
        read.ignored = specimen_io.unread_files(si.path, si.files.values(), "label_volume", si.pattern)
    else:
        read = specimen_io.read_specimen(si.path, units=si.units, axes=si.axes, pattern=si.pattern,
                                         turn_inside_out=si.turn_inside_out)
        sources = {v: str(f) for v, f in read.files.items()}
    sp = specimen_build.build_specimen(read.meshes, axes=si.axes, sources=sources, units=si.units,
                                       name=si.path.name, turned=read.turned, input_log=read.log())
    diskcache.load_or_compute(cache_content(si), CACHE_KIND, build_tag(), lambda: geometry_to_arrays(sp.geometry),
                              what=str(si.path))
    return SpecimenBuild(si, read, sp, mesh_dir)


def visible_human_path(g: dict):
    """The folder of the Visible Human set a ``geometry:`` section names (its ligament insertion and material tables
    are read beside the meshes), or None for any other kind of geometry."""
    g = g or {}
    return g.get("path") if g.get("kind") == "visible_human" else None


def load_configured(g: dict, levels=None) -> SpineGeometry:
    """The geometry a configuration's ``geometry:`` section names (module doc), with only ``levels`` (None: all
    present). A specimen comes from the cache when it was built before from the same inputs, else it is built."""
    kind = g.get("kind", "visible_human")
    if kind not in SPECIMEN_KINDS:
        return load_geometry(kind, path=g.get("path") if kind == "visible_human" else None, levels=levels)
    si = specimen_inputs(g)
    if levels is not None:
        want = [levels] if isinstance(levels, str) else list(levels)
        missing = [lv for lv in want if lv not in si.units_present]
        if missing:                      # before any build: the files say which units exist
            raise GeometryError(f"{si.path}: no unit {', '.join(missing)} (vertebrae present: {si.vertebrae}; units "
                                f"{si.units_present})")

    def compute():
        log.info("building the specimen geometry of %s (not in the cache)", si.path)
        if si.kind == "label_volume":
            with tempfile.TemporaryDirectory(prefix="lumbar_label_meshes_") as tmp:
                return geometry_to_arrays(_build(si, Path(tmp)).specimen.geometry)
        return geometry_to_arrays(_build(si, None).specimen.geometry)
    arrays = diskcache.load_or_compute(cache_content(si), CACHE_KIND, build_tag(), compute, what=str(si.path))
    return select_levels(geometry_from_arrays(arrays), levels)


# ------------------------------------------------------------------ what the workflow's geometry rule writes
def facet_numbers_supported(b: SpecimenBuild) -> tuple[bool, str]:
    """Whether the specimen's facet landmarks are worth a number: for a label volume, what its voxel size supports
    (:func:`lumbar.geometry.specimen_io.resolution_limits`); meshes are taken as the user's surfaces."""
    if b.inputs.kind != "label_volume":
        return True, ""
    import pandas as pd  # noqa: PLC0415 - only the label-volume report reads tables
    if b.mesh_dir is None or not (b.mesh_dir / "meshing_report.csv").is_file():
        raise GeometryError("label volume built without its meshing report (build(g, mesh_dir=...))")
    rep = pd.read_csv(b.mesh_dir / "meshing_report.csv")
    voxel = np.max([[float(x) for x in str(v).split("x")] for v in rep["voxel_mm"]], axis=0)
    lim = next(r for r in specimen_io.resolution_limits(voxel) if r["feature"].startswith("facet"))
    return bool(lim["supported"]), lim["reason"]


def write_specimen_tables(b: SpecimenBuild, out_dir) -> dict:
    """landmarks.csv, levels.csv, transform.json (:func:`lumbar.geometry.specimen_tables.write_tables`) in
    ``out_dir``. Where a label volume's voxels cannot resolve the facet joints, the facet columns of levels.csv (bone
    gap, Eq. 4 fits) are left empty and ``facet_numbers`` says why, instead of precise-looking numbers; returns the
    paths."""
    from ..inputs.io import write_table_atomic  # noqa: PLC0415 - table writing, only for the specimen's tables
    from .specimen_tables import level_table, write_tables  # noqa: PLC0415 - the rule's tables only
    paths = write_tables(b.specimen, out_dir)
    ok, why = facet_numbers_supported(b)
    lv = level_table(b.specimen.geometry, b.specimen.facet_gaps)
    facet_cols = [c for c in lv.columns if c.startswith("facet_") and not c.endswith("_contact")]
    if not ok:
        lv[facet_cols] = np.nan
    lv["facet_numbers"] = "measured from the surfaces" if ok else f"not supported: {why}"
    write_table_atomic(lv, paths["levels"])
    return paths


def write_outputs(b: SpecimenBuild, out_dir, skipped: list[tuple[str, str]]) -> dict:
    """The specimen's tables (:func:`write_specimen_tables`) and skipped_stages.csv (stage, reason) in ``out_dir``;
    returns the paths."""
    import pandas as pd  # noqa: PLC0415 - table writing, only in the geometry rule
    from ..inputs.io import write_table_atomic  # noqa: PLC0415
    paths = write_specimen_tables(b, out_dir)
    paths["skipped_stages"] = Path(out_dir) / "skipped_stages.csv"
    write_table_atomic(pd.DataFrame(skipped, columns=["stage", "reason"]), paths["skipped_stages"])
    return paths
