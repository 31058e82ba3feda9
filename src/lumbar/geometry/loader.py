"""``load_geometry``: dispatch to the geometry sources."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

from ..inputs import resources
from . import analysis as A
from .core import GeometryError, Level, SpineGeometry, Vertebra, level_vertebrae, levels_and_vertebrae

CSA_OFFSET_M = 0.002   # section plane this far inside the upper vertebral body, above its inferior endplate


def embedded_visible_human_path():
    """The Visible Human geometry embedded in the repository (data/geometry/visible_human_lss, BSD-3).

    Found from ``$LUMBAR_DATA_DIR`` (the repository ``data`` directory), else the package data
    (:func:`lumbar.inputs.resources.data_dir`: the checkout's or the wheel's copy), else ``./data``.
    """
    import os  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415
    cands = []
    if os.environ.get("LUMBAR_DATA_DIR"):
        cands.append(Path(os.environ["LUMBAR_DATA_DIR"]) / "geometry" / "visible_human_lss")
    cands.append(resources.data_dir() / "geometry" / "visible_human_lss")
    cands.append(Path.cwd() / "data" / "geometry" / "visible_human_lss")
    for c in cands:
        if (c / "meshes").is_dir():
            return c
    raise GeometryError(f"embedded Visible Human geometry not found; tried {[str(c) for c in cands]} "
                        "(set LUMBAR_DATA_DIR to the repository 'data' directory, or pass path=)")


def load_geometry(kind: str = "visible_human", path=None, levels=None) -> SpineGeometry:
    """Load a spine geometry in the project frame (x anterior, y left, z superior; metres).

    kind: "visible_human" (the default of the passive models: the Visible Human Male L1-S1 set; ``path`` =
    a visible_human_lss folder, default the embedded copy ``data/geometry/visible_human_lss``) or
    "myo_sim" (myo-sim meshes + data/landmarks/myo_sim_landmarks.csv; ``path`` optionally overrides the
    landmark CSV; the muscle model's geometry). "default" is the former name of "myo_sim" and still
    accepted. levels: None (all of "L1-L2".."L5-S1") or an iterable of level names; only their vertebrae
    are loaded.
    """
    from ..mechanics import profile  # noqa: PLC0415
    with profile.phase("geometry"):
        return _load_geometry(kind, path, levels)


def _load_geometry(kind, path, levels) -> SpineGeometry:
    k = str(kind).lower()
    if k in ("default", "myo_sim", "myo-sim"):
        return _checked(load_myo_sim(landmarks_csv=path, levels=levels))
    if k in ("visible_human", "visible-human", "vh"):
        if path is None:
            path = embedded_visible_human_path()
        from .visible_human import load_visible_human  # noqa: PLC0415
        return _checked(load_visible_human(path, levels=levels))
    if k == "synthetic":
        from .synthetic import symmetric_fsu  # noqa: PLC0415
        return symmetric_fsu()
    raise GeometryError(f"unknown geometry kind {kind!r}; expected 'default'/'myo_sim', 'visible_human' or 'synthetic'")


def _checked(geo: SpineGeometry) -> SpineGeometry:
    """Units, closedness and frame of every vertebra mesh (lumbar.geometry.checks)."""
    from .checks import check_spine  # noqa: PLC0415
    check_spine(geo)
    return geo


def _body_centroid(mesh: trimesh.Trimesh, x_post: float) -> np.ndarray:
    """Volume centroid of the convex hull of the vertebra's vertices anterior to the posterior wall of the
    body (the vertebral body; a capped slice would need a polygon triangulation engine)."""
    v = mesh.vertices
    return A.hull_centroid(v[v[:, 0] > x_post])


def load_myo_sim(landmarks_csv=None, levels=None) -> SpineGeometry:
    from . import myo_sim  # noqa: PLC0415
    from .landmarks import (ENDPLATE_RADIUS, VertebraFeatures, default_csv_path,  # noqa: PLC0415
                            landmarks_to_level_parts, read_landmarks)
    levels, verts = levels_and_vertebrae(levels)
    need = list(verts)
    if "S1" in need and "L5" not in need:
        need.append("L5")
    meshes = myo_sim.load_raw_meshes(tuple(need))
    csv = default_csv_path() if landmarks_csv is None else landmarks_csv
    df = read_landmarks(csv, meshes)
    feats = {v: VertebraFeatures(v, meshes[v]) for v in need if v != "S1"}
    if "S1" in need:
        feats["S1"] = VertebraFeatures("S1", meshes["S1"], x_post=feats["L5"].x_post, x_lam=feats["L5"].x_lam)
    geo_levels, s1_endplate = {}, None
    for lv in levels:
        U, L = level_vertebrae(lv)
        fu, fl = feats[U], feats[L]
        c_inf, n_inf, _ = A.inferior_endplate(fu.mesh, fu.mesh.triangles_center[:, 0] > fu.x_post)
        c_sup, n_sup, _ = A.facing_endplate(fl.mesh, c_inf, n_inf, radius=ENDPLATE_RADIUS)
        n = n_inf + n_sup
        n /= np.linalg.norm(n)
        centre = 0.5 * (c_inf + c_sup)
        height = float((c_inf - c_sup) @ n)
        origin = c_inf + CSA_OFFSET_M * n_inf
        csa = A.section_area(fu.mesh, origin, n_inf, inside_point=origin)
        proj = A.projected_area(fu.body, n_inf)
        if not (0 < csa < proj):
            raise GeometryError(f"myo-sim {lv}: disc CSA {csa} m^2 not in (0, projected body area {proj})")
        if L == "S1":
            s1_endplate = (c_sup, n_sup)
        ligs, facets = landmarks_to_level_parts(df, lv, U, L)
        geo_levels[lv] = Level(name=lv, upper=U, lower=L, disc_centre=centre, disc_normal=n,
                               disc_csa=float(csa), disc_height=height, facets=facets, ligaments=ligs)
    vertebrae = {}
    for v in verts:
        if v == "S1":
            # sacrum: hull centroid of its vertices within 25 mm below the S1 endplate and 20 mm of its axis
            if s1_endplate is None:  # pragma: no cover - S1 only loaded with L5-S1
                raise GeometryError("S1 needs level L5-S1")
            c, n = s1_endplate
            d = meshes["S1"].vertices - c
            h = d @ n
            r = np.linalg.norm(d - np.outer(h, n), axis=1)
            cen = A.hull_centroid(meshes["S1"].vertices[(h < 0.5e-3) & (h > -0.025) & (r < 0.02)])
        else:
            cen = _body_centroid(meshes[v], feats[v].x_post)
        vertebrae[v] = Vertebra(name=v, mesh=meshes[v], centroid=cen)
    ver = myo_sim.package_version()
    return SpineGeometry(name="myo_sim", source=f"myo-sim {ver} (Apache-2.0) torso chain, qpos0; landmarks {csv}",
                         vertebrae=vertebrae, levels=geo_levels)
