"""Data classes and error type of :mod:`lumbar.geometry` (see docs/design.md)."""
from __future__ import annotations

from dataclasses import dataclass, field

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

LEVEL_NAMES = ("L1-L2", "L2-L3", "L3-L4", "L4-L5", "L5-S1")
VERTEBRA_NAMES = ("L1", "L2", "L3", "L4", "L5", "S1")
LIGAMENT_KINDS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL")
LIGAMENT_NAMES = ("ALL", "PLL", "FL", "CL_L", "CL_R", "ISL", "SSL", "ITL_L", "ITL_R")


class GeometryError(ValueError):
    """Invalid geometry input (missing/unreadable file, wrong units, malformed table)."""


@dataclass
class Vertebra:
    name: str
    mesh: trimesh.Trimesh          # project frame, metres
    centroid: np.ndarray           # (3,) volume centroid of the vertebral body (reference point c_b)


@dataclass
class FacetLandmarks:
    superior: np.ndarray           # (9,3) lower vertebra's superior articular process (medial face)
    inferior: np.ndarray           # (9,3) upper vertebra's inferior articular process (lateral face)
    # where the contact surface sits (lumbar.mechanics.elements.facet.fit_surface): "mean_surface" = the mean of the
    # two fitted surfaces (paper 1, Sect. 2.2.3; contact after closing about half the landmark gap), or
    # "touching" = the landmarks are the two subchondral faces of a cartilage-filled joint, whose cartilage
    # surfaces touch at rest (the CT joint space is cartilage): the surface passes through the nearest
    # upper-process landmark, so contact begins at once when the joint closes
    contact: str = "mean_surface"
    # optional (n,3) points of the upper vertebra's articular face that can touch the contact surface (e.g. every node
    # of the cartilage layer's upper sheet); None: the nine ``inferior`` landmarks. More points spread the contact over
    # the face instead of switching between nine points (a stiffness step whenever one of them leaves the surface)
    contact_points: np.ndarray | None = None

    @property
    def contact_set(self) -> np.ndarray:
        return self.inferior if self.contact_points is None else self.contact_points


@dataclass
class Ligament:
    name: str                      # ALL, PLL, FL, CL_L, CL_R, ISL, SSL, ITL_L, ITL_R
    kind: str                      # ALL, PLL, FL, CL, ISL, SSL, ITL
    upper: np.ndarray              # (n,3) fibre ends fixed to the upper vertebra
    lower: np.ndarray              # (n,3) fibre ends fixed to the lower vertebra
    extra_length: np.ndarray       # (n,) constant via-point path length within one body (m)

    @property
    def n_fibres(self) -> int:
        return int(self.upper.shape[0])

    @property
    def lengths(self) -> np.ndarray:
        """Reference fibre lengths (straight part + extra_length), metres."""
        return np.linalg.norm(self.upper - self.lower, axis=1) + self.extra_length


@dataclass
class Level:
    name: str                      # "L4-L5"
    upper: str                     # "L4"
    lower: str                     # "L5"
    disc_centre: np.ndarray        # (3,)
    disc_normal: np.ndarray        # (3,) unit, pointing superior
    disc_csa: float                # m^2
    disc_height: float             # m
    facets: dict = field(default_factory=dict)     # "left"/"right" -> FacetLandmarks
    ligaments: list = field(default_factory=list)  # list[Ligament]

    def ligament(self, name: str) -> Ligament:
        for lig in self.ligaments:
            if lig.name == name:
                return lig
        raise KeyError(f"level {self.name} has no ligament {name!r}")


@dataclass
class SpineGeometry:
    name: str
    source: str
    vertebrae: dict                # name -> Vertebra
    levels: dict                   # "L4-L5" -> Level
    # (nominal geometry, 4x4 similarity T): every mesh of this geometry is the nominal one mapped by T (a virtual
    # specimen's uniform scaling, lumbar.experiments.virtual_experiment.perturb_geometry), so results that depend on
    # the meshes alone (the cable registration of lumbar.experiments.l2s1) are carried over by T, not recomputed
    similarity: tuple | None = field(default=None, repr=False, compare=False)


def level_vertebrae(level: str) -> tuple[str, str]:
    up, lo = level.split("-")
    return up, lo


def levels_and_vertebrae(levels) -> tuple[list[str], list[str]]:
    """(levels in ``LEVEL_NAMES`` order, their vertebrae in ``VERTEBRA_NAMES`` order) for ``levels``: None
    (all levels), one level name or an iterable of them; unknown names raise :class:`GeometryError`."""
    if levels is None:
        levels = list(LEVEL_NAMES)
    if isinstance(levels, str):
        levels = [levels]
    bad = [lv for lv in levels if lv not in LEVEL_NAMES]
    if bad:
        raise GeometryError(f"unknown level(s) {bad}; expected some of {list(LEVEL_NAMES)}")
    levels = [lv for lv in LEVEL_NAMES if lv in levels]
    verts = sorted({v for lv in levels for v in level_vertebrae(lv)}, key=VERTEBRA_NAMES.index)
    return levels, verts
