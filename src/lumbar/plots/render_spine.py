"""3D figure of a multi-level spine model with its cables (Fig. 3 of paper 1): pyvista off-screen,
matplotlib fallback, the same conventions as :mod:`lumbar.plots.render` (fixed cameras, millimetres, PNG
without time metadata).

``render_spine(geometry, levels, path, cables=None)`` draws the vertebra meshes of ``levels``
(semi-transparent), the vertebral-body centroids (black), the ligament fibres (blue) and the cables
(red: from the attachment towards the pulley, drawn ``cable_draw_m`` long).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from .render import (camera_views, LIGAMENT_COLOUR, MM, WINDOW_SIZE, check_backend, mpl_view, pyvista_views, render_with,
                     save_png_closing)

__all__ = ["render_spine"]

CABLE_COLOUR = "#d62728"
BONE = "#d9c7a3"


def _items(geometry, levels, cables, cable_draw_m):
    verts = []
    for lv in levels:
        if lv not in geometry.levels:
            raise KeyError(f"level {lv!r} not in geometry {geometry.name!r}; available: {sorted(geometry.levels)}")
        for v in (geometry.levels[lv].upper, geometry.levels[lv].lower):
            if v not in verts:
                verts.append(v)
    meshes = [(v, np.asarray(geometry.vertebrae[v].mesh.vertices, float) * MM,
               np.asarray(geometry.vertebrae[v].mesh.faces, np.int64)) for v in verts]
    fibres = [(np.asarray(lig.upper) * MM, np.asarray(lig.lower) * MM) for lv in levels
              for lig in geometry.levels[lv].ligaments]
    cab = []
    if cables is not None:
        for _, r in cables.iterrows():
            a = np.array([r.model_x_m, r.model_y_m, r.model_z_m])
            u = np.array([r.dir_x, r.dir_y, r.dir_z])
            cab.append((a * MM, (a + cable_draw_m * u) * MM))
    return dict(meshes=meshes, centroids=np.array([geometry.vertebrae[v].centroid for v in verts]) * MM,
                fibres=fibres, cables=cab, title=f"{geometry.name} {levels[0].split('-')[0]}-{levels[-1].split('-')[1]}")


def _views(items):
    return camera_views(np.vstack([v for _, v, _ in items["meshes"]]), oblique=(-0.6, 0.7, 0.25))


def _lines(pairs):
    n = len(pairs)
    pts = np.empty((2 * n, 3))
    pts[0::2] = [a for a, _ in pairs]
    pts[1::2] = [b for _, b in pairs]
    return pts, np.hstack([np.full((n, 1), 2), np.arange(2 * n).reshape(n, 2)]).ravel()


def _render_pyvista(items, path):
    import pyvista as pv  # noqa: PLC0415 - optional engine; without GL the module imports, matplotlib draws

    def draw(p):
        for _, v, f in items["meshes"]:
            faces = np.hstack([np.full((len(f), 1), 3, np.int64), f]).ravel()
            p.add_mesh(pv.PolyData(v, faces), color=BONE, opacity=0.35)
        p.add_points(items["centroids"], color="black", point_size=12, render_points_as_spheres=True)
        fib = [(a, b) for up, lo in items["fibres"] for a, b in zip(up, lo)]
        if fib:
            pts, lines = _lines(fib)
            p.add_mesh(pv.PolyData(pts, lines=lines).tube(radius=0.35), color=LIGAMENT_COLOUR)
        if items["cables"]:
            pts, lines = _lines(items["cables"])
            p.add_mesh(pv.PolyData(pts, lines=lines).tube(radius=0.7), color=CABLE_COLOUR)

    pyvista_views(path, items["title"], _views(items), draw)


def _render_matplotlib(items, path):

    fig = Figure(figsize=(WINDOW_SIZE[0] / 100, WINDOW_SIZE[1] / 100), dpi=100)
    allv = np.vstack([v for _, v, _ in items["meshes"]])
    lo, hi = allv.min(0), allv.max(0)
    half, mid = 0.5 * float(np.max(hi - lo)), 0.5 * (lo + hi)
    for col, (label, (pos, focal, _)) in enumerate(_views(items)):
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        for _, v, f in items["meshes"]:
            step = max(1, len(f) // 3000)
            ax.add_collection3d(Poly3DCollection(v[f[::step]], facecolor=BONE, edgecolor="none", alpha=0.3))
        ax.scatter(*items["centroids"].T, color="black", s=30)
        for up, lo_ in items["fibres"]:
            for a, b in zip(up, lo_):
                ax.plot(*np.vstack([a, b]).T, color=LIGAMENT_COLOUR, lw=0.8)
        for a, b in items["cables"]:
            ax.plot(*np.vstack([a, b]).T, color=CABLE_COLOUR, lw=2.0)
        mpl_view(ax, mid, half, pos, focal, f"{items['title']}: {label}")
    save_png_closing(fig, path)


def render_spine(geometry, levels, path, cables=None, cable_draw_m=0.04, backend="auto") -> str:
    """Render the vertebrae of ``levels`` with ligaments and ``cables`` (a ``lumbar.experiments.l2s1`` cable table with
    model_x/y/z_m and dir_x/y/z) to PNG. Returns the backend used."""
    check_backend(backend)
    return render_with(backend, _items(geometry, list(levels), cables, cable_draw_m), Path(path), _render_pyvista,
                       _render_matplotlib)
