"""Validated, cached mesh reading."""
from __future__ import annotations

import functools
import os
from pathlib import Path

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

from . import diskcache
from .core import GeometryError

MAX_EXTENT_M = 0.3


VTK_SUFFIXES = (".vtk", ".vtp")


def _parse_mesh(path: str) -> dict:
    """Vertices and faces of a mesh file as trimesh loads and processes it (merged vertices); STL, OBJ, PLY through
    trimesh, VTK/VTP polydata through pyvista (the VTK reader; trimesh has none). Non-finite coordinates are an
    error naming their count: trimesh's processing drops such vertices with their triangles, which left a surface
    with holes and a misleading error about its closedness."""
    import trimesh  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    expected = "expected an STL/OBJ/PLY/VTK/VTP triangle mesh"
    if Path(path).stat().st_size == 0:
        raise GeometryError(f"{path}: mesh file is empty (0 bytes); {expected}")

    def finite(v):
        bad = ~np.all(np.isfinite(np.asarray(v, float)), axis=1)
        if bad.any():
            raise GeometryError(f"{path}: {int(bad.sum())} vertices with non-finite coordinates (NaN or infinite); "
                                "expected finite numbers")
    try:
        if Path(path).suffix.lower() in VTK_SUFFIXES:
            import pyvista  # noqa: PLC0415 - VTK's reader (pyvista, vtk) only for the VTK formats, 1 s to import
            data = pyvista.read(path)
            if not isinstance(data, pyvista.PolyData):
                data = data.extract_surface()
            data = data.triangulate()
            faces = np.asarray(data.faces).reshape(-1, 4)[:, 1:] if data.n_cells else np.zeros((0, 3), int)
            finite(data.points)
            mesh = trimesh.Trimesh(vertices=np.asarray(data.points, float), faces=faces, process=True)
        else:
            raw = trimesh.load(path, force="mesh", process=False)
            if isinstance(raw, trimesh.Trimesh) and len(raw.vertices):
                finite(raw.vertices)
            # OBJ: trimesh's own processing on load (it keeps vertices split by their texture coordinates); the
            # other formats give the same arrays processed after loading
            mesh = (trimesh.load(path, force="mesh", process=True) if Path(path).suffix.lower() == ".obj"
                    or not isinstance(raw, trimesh.Trimesh) else trimesh.Trimesh(raw.vertices, raw.faces, process=True))
    except GeometryError:
        raise
    except Exception as exc:  # noqa: BLE001 - trimesh and VTK raise many types; all mean "not readable"
        raise GeometryError(f"{path}: mesh not readable ({type(exc).__name__}: {exc}); {expected}") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0 or len(mesh.vertices) < 4:
        raise GeometryError(f"{path}: mesh not readable or empty (no triangles); {expected}")
    return {"vertices": np.asarray(mesh.vertices, dtype=np.float64), "faces": np.asarray(mesh.faces, dtype=np.int64)}


def read_mesh_arrays(path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a mesh file in the file's own units, cached across processes by content
    (:mod:`lumbar.geometry.diskcache`); no unit check (the caller knows the declared units)."""
    import trimesh  # noqa: PLC0415
    p = Path(path)
    if not p.is_file():
        raise GeometryError(f"{p}: mesh file missing (expected a triangle mesh file)")
    arr = diskcache.load_or_parse(str(p), "mesh", f"trimesh {trimesh.__version__} process, finite checked",
                                  lambda: _parse_mesh(str(p)))
    return arr["vertices"], arr["faces"]


@functools.lru_cache(maxsize=64)
def _read_mesh_cached(path: str, mtime_ns: int) -> trimesh.Trimesh:
    # parsed once per file content across processes (lumbar.geometry.diskcache); every process builds the mesh from
    # the same two arrays, whether parsed here or read from the cache
    import trimesh  # noqa: PLC0415
    vertices, faces = read_mesh_arrays(path)
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    if len(mesh.faces) == 0 or len(mesh.vertices) < 4:
        raise GeometryError(f"{path}: mesh not readable or empty (no triangles); "
                            "expected an STL/OBJ triangle mesh in metres")
    if not np.all(np.isfinite(mesh.vertices)):
        raise GeometryError(f"{path}: mesh has non-finite vertex coordinates")
    ext = mesh.extents
    if np.any(ext > MAX_EXTENT_M):
        raise GeometryError(
            f"{path}: mesh extent {np.round(ext, 4).tolist()} exceeds {MAX_EXTENT_M} m in some axis; "
            "looks like millimetres, expected metres")
    return mesh


def read_mesh(path, *, max_extent: float = MAX_EXTENT_M) -> trimesh.Trimesh:
    """Read a mesh (cached in the process by path + modification time, across processes by content:
    :mod:`lumbar.geometry.diskcache`); returns a private copy."""
    p = Path(path)
    if not p.is_file():
        raise GeometryError(f"{p}: mesh file missing (expected a triangle mesh file in metres)")
    mesh = _read_mesh_cached(str(p.resolve()), os.stat(p).st_mtime_ns)
    return mesh.copy()


def require_dir(path, what: str) -> Path:
    p = Path(path)
    if not p.is_dir():
        raise GeometryError(f"{p}: {what} directory missing")
    return p
