"""3D figures of the model geometry (pyvista off-screen, matplotlib fallback).

``render_fsu(geometry, level, path)`` draws one functional spinal unit: the two vertebra
meshes (semi-transparent), the disc centre (black sphere), the facet landmarks (red: the
lower vertebra's superior articular process, blue: the upper vertebra's inferior articular
process), the facet regression surfaces when ``lumbar.mechanics.elements.facet.fit_surface`` exists,
and the ligament fibres (blue), in a sagittal and an oblique view side by side.

Rendering is deterministic: fixed cameras, fixed window size, PNG written without time
or software metadata. pyvista renders off-screen through the vtk wheel (EGL, then OSMesa);
when that fails (no libEGL/libOSMesa on the machine) the same items are drawn with
matplotlib and a warning is logged. Coordinates are drawn in millimetres.
"""
from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection
from PIL import Image

from ..mechanics.elements.facet import fit_surface
from ..inputs.io import atomic_writer

__all__ = ["render_fsu", "offscreen_available", "facet_surfaces"]

log = logging.getLogger(__name__)

WINDOW_SIZE = (1200, 900)
MM = 1000.0  # drawing unit: millimetres
UPPER_COLOUR = "#d9c7a3"
LOWER_COLOUR = "#bfb8ad"
LIGAMENT_COLOUR = "#1f4fbf"

_PROBE = (
    "import pyvista as pv\n"
    "p = pv.Plotter(off_screen=True, window_size=(64, 48))\n"
    "p.add_mesh(pv.Sphere(), color='red')\n"
    "img = p.screenshot(return_img=True)\n"
    "p.close()\n"
    "raise SystemExit(0 if img.std() > 1.0 else 3)\n"
)
_offscreen_cache: bool | None = None


def offscreen_available(timeout: float = 120.0) -> bool:
    """True if pyvista renders a non-blank image off-screen here.

    Probed once per process in a subprocess, because a vtk build without a usable
    OpenGL context (no EGL, no OSMesa) can abort the interpreter instead of raising.
    """
    global _offscreen_cache
    if _offscreen_cache is None:
        try:
            r = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, timeout=timeout)
            _offscreen_cache = r.returncode == 0
            if not _offscreen_cache:
                log.warning("pyvista off-screen probe failed (exit %s): %s", r.returncode,
                            r.stderr.decode(errors="replace")[-2000:])
        except (OSError, subprocess.TimeoutExpired) as exc:
            log.warning("pyvista off-screen probe failed: %s", exc)
            _offscreen_cache = False
    return _offscreen_cache


def facet_surfaces(lev, n: int = 12) -> dict[str, np.ndarray]:
    """Facet regression surfaces of one level as (n, n, 3) grids [m], keyed "left"/"right".

    Uses ``lumbar.mechanics.elements.facet.fit_surface(superior, inferior)`` (the mean of the fits to
    both articular processes); returns {} (and logs why) if that function is missing or fails.
    """
    out = {}
    for side, lm in sorted(lev.facets.items()):
        try:
            surf = fit_surface(np.asarray(lm.superior, float), np.asarray(lm.inferior, float))
            grid = np.asarray(surf.grid(n), float)
            if grid.ndim == 3 and grid.shape[2] == 3:
                out[side] = grid
        except Exception as exc:  # noqa: BLE001 - a figure must not fail because one surface fit does
            log.warning("facet surface %s not drawn: %s", side, exc)
    return out


def _items(geometry, level: str, surfaces):
    """Everything drawn, in millimetres, independent of the backend."""
    if level not in geometry.levels:
        raise KeyError(f"level {level!r} not in geometry {geometry.name!r}; "
                       f"available: {', '.join(sorted(geometry.levels))}")
    lev = geometry.levels[level]
    if surfaces is None:
        surfaces = facet_surfaces(lev)
    meshes = []
    for name, colour in ((lev.upper, UPPER_COLOUR), (lev.lower, LOWER_COLOUR)):
        m = geometry.vertebrae[name].mesh
        meshes.append((name, np.asarray(m.vertices, float) * MM, np.asarray(m.faces, np.int64), colour))
    sup = [np.asarray(f.superior, float) * MM for f in lev.facets.values()]
    inf = [np.asarray(f.inferior, float) * MM for f in lev.facets.values()]
    fibres = [(np.asarray(lig.upper, float) * MM, np.asarray(lig.lower, float) * MM) for lig in lev.ligaments]
    return dict(
        meshes=meshes,
        centre=np.asarray(lev.disc_centre, float) * MM,
        normal=np.asarray(lev.disc_normal, float),
        superior=np.vstack(sup) if sup else np.zeros((0, 3)),
        inferior=np.vstack(inf) if inf else np.zeros((0, 3)),
        fibres=fibres,
        surfaces={k: np.asarray(v, float) * MM for k, v in (surfaces or {}).items()},
        title=f"{geometry.name} {level}",
    )


def camera_views(points, oblique=(-0.75, 0.55, 0.37)):
    """[(label, (camera position, focal point, view-up))] of the sagittal view (from the left) and an oblique view
    (direction ``oblique``, posterior-left-superior) of ``points`` (n, 3) [mm]: the bounding sphere about the
    bounding-box centre fits the 600 px wide half-window (view angle 30 deg, aspect 2/3). The one camera rule of the
    3-D figures (motion segment, L2-S1 spine, a specimen's QA figure)."""
    pts = np.asarray(points, float)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    radius = float(np.max(np.linalg.norm(pts - centre, axis=1)))
    d = 1.02 * radius / (np.tan(np.radians(15.0)) * WINDOW_SIZE[0] / 2 / WINDOW_SIZE[1])
    up = (0.0, 0.0, 1.0)
    sagittal = (tuple(centre + d * np.array([0.0, 1.0, 0.0])), tuple(centre), up)
    obl = np.asarray(oblique, float)
    return [("sagittal (from left)", sagittal),
            ("oblique (posterior-left)", (tuple(centre + d * obl / np.linalg.norm(obl)), tuple(centre), up))]


def _views(items):
    """Camera views of a motion segment's two vertebrae (:func:`camera_views`)."""
    return camera_views(np.vstack([v for _, v, _, _ in items["meshes"]]))


def _atomic_png(path: Path, rgb: np.ndarray) -> None:
    with atomic_writer(path, "wb") as f:
        Image.fromarray(np.ascontiguousarray(rgb[..., :3]).astype(np.uint8)).save(f, format="PNG")


def pyvista_views(path: Path, title: str, views, draw) -> None:
    """Off-screen pyvista figure of one row of views (label, camera): ``draw(plotter)`` adds the scene to
    each; a title per view; the PNG is written atomically, and a blank render raises."""
    import pyvista as pv  # noqa: PLC0415 - optional engine; without GL the module imports, matplotlib draws

    p = pv.Plotter(off_screen=True, window_size=WINDOW_SIZE, shape=(1, len(views)), border=False)
    try:
        for col, (label, camera) in enumerate(views):
            p.subplot(0, col)
            p.set_background("white")
            draw(p)
            p.add_text(f"{title}: {label}", font_size=11, color="black")
            p.camera_position = list(camera)
            p.camera.view_angle = 30.0
        img = p.screenshot(return_img=True)
    finally:
        p.close()
    if float(np.asarray(img, float).std()) < 1.0:
        raise RuntimeError("pyvista produced a blank image")
    _atomic_png(path, img)


def _render_pyvista(items, path: Path) -> None:
    import pyvista as pv  # noqa: PLC0415 - optional engine; without GL the module imports, matplotlib draws

    def draw(p):
        for name, v, f, colour in items["meshes"]:
            faces = np.hstack([np.full((len(f), 1), 3, np.int64), f]).ravel()
            p.add_mesh(pv.PolyData(v, faces), color=colour, opacity=0.35, smooth_shading=False)
        p.add_mesh(pv.Sphere(radius=1.5, center=items["centre"]), color="black")
        if len(items["superior"]):
            p.add_points(items["superior"], color="red", point_size=9, render_points_as_spheres=True)
        if len(items["inferior"]):
            p.add_points(items["inferior"], color="blue", point_size=9, render_points_as_spheres=True)
        for grid in items["surfaces"].values():
            p.add_mesh(pv.StructuredGrid(grid[..., 0], grid[..., 1], grid[..., 2]),
                       color="orange", opacity=0.6)
        for up_pts, lo_pts in items["fibres"]:
            n = len(up_pts)
            if n == 0:
                continue
            pts = np.empty((2 * n, 3))
            pts[0::2], pts[1::2] = up_pts, lo_pts
            lines = np.hstack([np.full((n, 1), 2), np.arange(2 * n).reshape(n, 2)]).ravel()
            p.add_mesh(pv.PolyData(pts, lines=lines).tube(radius=0.35), color=LIGAMENT_COLOUR)

    pyvista_views(path, items["title"], _views(items), draw)


def _render_matplotlib(items, path: Path) -> None:
    fig = Figure(figsize=(WINDOW_SIZE[0] / 100, WINDOW_SIZE[1] / 100), dpi=100)
    for col, (label, (pos, focal, _up)) in enumerate(_views(items)):
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        for name, v, f, colour in items["meshes"]:
            step = max(1, len(f) // 6000)  # keep the fallback fast on fine meshes
            ax.add_collection3d(Poly3DCollection(v[f[::step]], facecolor=colour, edgecolor="none", alpha=0.3))
        ax.scatter(*items["centre"], color="black", s=60)
        if len(items["superior"]):
            ax.scatter(*items["superior"].T, color="red", s=12)
        if len(items["inferior"]):
            ax.scatter(*items["inferior"].T, color="blue", s=12)
        for grid in items["surfaces"].values():
            ax.plot_surface(grid[..., 0], grid[..., 1], grid[..., 2], color="orange", alpha=0.6)
        for up_pts, lo_pts in items["fibres"]:
            for a, b in zip(up_pts, lo_pts):
                ax.plot(*np.vstack([a, b]).T, color=LIGAMENT_COLOUR, lw=1.2)
        allv = np.vstack([v for _, v, _, _ in items["meshes"]])
        lo, hi = allv.min(0), allv.max(0)
        half = 0.5 * float(np.max(hi - lo))
        mid = 0.5 * (lo + hi)
        mpl_view(ax, mid, half, pos, focal, f"{items['title']}: {label}")
    save_png_closing(fig, path)


def mpl_view(ax, mid, half, pos, focal, title):
    """Equal-aspect 3D axes around ``mid`` (half-width ``half``) seen from camera ``pos`` towards ``focal``,
    labelled in the project frame (millimetres)."""
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))
    d = np.asarray(pos) - np.asarray(focal)
    ax.view_init(elev=float(np.degrees(np.arcsin(d[2] / np.linalg.norm(d)))),
                 azim=float(np.degrees(np.arctan2(d[1], d[0]))))
    ax.set_xlabel("x anterior [mm]")
    ax.set_ylabel("y left [mm]")
    ax.set_zlabel("z superior [mm]")
    ax.set_title(title)


def save_png_closing(fig, path):
    """Write ``fig`` atomically as PNG without time/software metadata, then close it if pyplot manages it (a
    ``matplotlib.figure.Figure`` of the object API, as the library makes, has nothing to close)."""
    try:
        with atomic_writer(path, "wb") as f:
            fig.savefig(f, format="png", metadata={"Software": None})
    finally:
        if getattr(fig.canvas, "manager", None) is not None:
            import matplotlib.pyplot as plt  # noqa: PLC0415 - only to close a figure pyplot manages (the caller's)
            plt.close(fig)


def render_fsu(geometry, level: str, path, surfaces=None, backend: str = "auto") -> str:
    """Render one motion segment of ``geometry`` (a ``lumbar.geometry.SpineGeometry``) to PNG.

    surfaces: optional {"left"|"right": (n, n, 3) grid [m]}; None = fit with
    ``lumbar.mechanics.elements.facet.fit_surface`` if available. backend: "auto" | "pyvista" |
    "matplotlib". Returns the backend actually used.
    """
    check_backend(backend)
    return render_with(backend, _items(geometry, level, surfaces), Path(path), _render_pyvista, _render_matplotlib)


def check_backend(backend):
    if backend not in ("auto", "pyvista", "matplotlib"):
        raise ValueError(f"backend must be auto, pyvista or matplotlib, not {backend!r}")


def render_with(backend, items, path: Path, pyvista_fn, matplotlib_fn) -> str:
    """pyvista off-screen where asked or available (``auto``), else (or if it fails under ``auto``) the
    matplotlib 3D fallback, with a warning; returns the backend used."""
    if backend == "pyvista" or (backend == "auto" and offscreen_available()):
        try:
            pyvista_fn(items, path)
            return "pyvista"
        except Exception as exc:
            if backend == "pyvista":
                raise
            log.warning("pyvista rendering failed (%s); falling back to matplotlib", exc)
    elif backend == "auto":
        log.warning("pyvista cannot render off-screen here (no EGL/OSMesa?); "
                    "falling back to matplotlib 3D. On Debian: apt-get install libegl1 libgl1-mesa-dri "
                    "or libosmesa6.")
    matplotlib_fn(items, path)
    return "matplotlib"
