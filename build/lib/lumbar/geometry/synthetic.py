"""A synthetic, exactly mirror-symmetric L4-L5 unit for tests and examples.

Dimensions are typical adult lumbar values chosen by hand (not measured): vertebral body
35 x 45 x 27 mm, disc height 11 mm, facet joints 32 mm posterior and 16 mm lateral of the disc
centre with their articular planes 40 deg from the sagittal plane. Every left structure is the
mirror image (y -> -y) of its right counterpart, so left and right responses must be equal.
"""
from __future__ import annotations

import numpy as np
import trimesh

from .core import FacetLandmarks, Level, Ligament, SpineGeometry, Vertebra

BODY = np.array([0.035, 0.045, 0.027])
DISC_HEIGHT = 0.011


def _facet(side_sign, centre_z, gap=0.001, angle_deg=40.0, curvature=8.0):
    """Nine landmarks on each articular surface of one facet joint (side_sign +1 left, -1 right)."""
    a = np.radians(angle_deg)
    n = np.array([-np.sin(a), -side_sign * np.cos(a), 0.0])   # from the lower (L5) surface to L4's
    t1 = np.array([0.0, 0.0, 1.0])
    t2 = side_sign * np.cross(n, t1)   # mirrored ordering of the grid
    c = np.array([-0.032, side_sign * 0.016, centre_z])
    g = np.linspace(-0.004, 0.004, 3)
    U, V = np.meshgrid(g, g, indexing="ij")
    U, V = U.ravel(), V.ravel()
    w = curvature * (U**2 + V**2)        # gentle convexity, identical for both surfaces
    base = c + U[:, None] * t1 + V[:, None] * t2 + w[:, None] * n
    return FacetLandmarks(superior=base - 0.5 * gap * n, inferior=base + 0.5 * gap * n)


def _pair(name, kind, upper, lower):
    upper, lower = np.atleast_2d(upper), np.atleast_2d(lower)
    return Ligament(name, kind, upper, lower, np.zeros(len(upper)))


def symmetric_fsu(disc_csa=1.6e-3) -> SpineGeometry:
    """Geometry of a mirror-symmetric L4-L5 unit in the project frame (metres)."""
    zc = 0.0
    z5, z4 = zc - DISC_HEIGHT / 2 - BODY[2] / 2, zc + DISC_HEIGHT / 2 + BODY[2] / 2
    verts = {}
    for name, z in (("L4", z4), ("L5", z5)):
        mesh = trimesh.creation.box(extents=BODY)
        mesh.apply_translation([0.0, 0.0, z])
        verts[name] = Vertebra(name, mesh, np.array([0.0, 0.0, z]))
    up, lo = zc + DISC_HEIGHT / 2 + 0.003, zc - DISC_HEIGHT / 2 - 0.003
    ys = np.array([0.008, 0.0, -0.008])

    def row(x, y, z):
        return np.column_stack([np.full_like(y, x), y, np.full_like(y, z)])

    ligs = [
        _pair("ALL", "ALL", row(0.018, ys, up), row(0.018, ys, lo)),
        _pair("PLL", "PLL", row(-0.016, ys * 0.6, up), row(-0.016, ys * 0.6, lo)),
        _pair("FL", "FL", row(-0.030, ys * 0.8, up + 0.010), row(-0.030, ys * 0.8, lo + 0.004)),
        _pair("ISL", "ISL", row(-0.050, np.array([0.0, 0.0]), up + 0.012) + [[0, 0, 0], [-0.008, 0, 0]],
              row(-0.050, np.array([0.0, 0.0]), lo + 0.002) + [[0, 0, 0], [-0.008, 0, 0]]),
        _pair("SSL", "SSL", [[-0.064, 0.0, up + 0.012]], [[-0.064, 0.0, lo + 0.002]]),
    ]
    for side, s in (("L", 1.0), ("R", -1.0)):
        cu = np.array([[-0.030, s * 0.022, 0.006], [-0.036, s * 0.022, 0.006],
                       [-0.030, s * 0.026, 0.010], [-0.036, s * 0.026, 0.010]])
        ligs.append(_pair(f"CL_{side}", "CL", cu, cu - [0.0, 0.0, 0.012]))
        ligs.append(_pair(f"ITL_{side}", "ITL", [[-0.024, s * 0.040, up + 0.006]],
                          [[-0.024, s * 0.040, lo - 0.004]]))
    ligs.sort(key=lambda L: L.name)
    level = Level(
        name="L4-L5", upper="L4", lower="L5",
        disc_centre=np.array([0.0, 0.0, zc]), disc_normal=np.array([0.0, 0.0, 1.0]),
        disc_csa=disc_csa, disc_height=DISC_HEIGHT,
        facets={"left": _facet(1.0, zc + 0.006), "right": _facet(-1.0, zc + 0.006)},
        ligaments=ligs,
    )
    return SpineGeometry("synthetic_symmetric", "lumbar.geometry.synthetic (hand-chosen dimensions)",
                         verts, {"L4-L5": level})


def mirror_check(geometry: SpineGeometry, level="L4-L5", tol=1e-12) -> float:
    """Largest asymmetry (m) between left and right structures; 0 for an exactly symmetric unit."""
    lev = geometry.levels[level]
    M = np.diag([1.0, -1.0, 1.0])
    fl, fr = lev.facets["left"], lev.facets["right"]
    err = max(np.abs(fl.superior @ M - fr.superior).max(), np.abs(fl.inferior @ M - fr.inferior).max())
    for a, b in (("CL_L", "CL_R"), ("ITL_L", "ITL_R")):
        err = max(err, np.abs(lev.ligament(a).upper @ M - lev.ligament(b).upper).max())
    return float(err)
