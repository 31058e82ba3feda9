"""Spine geometry in the project frame (x anterior, y left, z superior; metres). See docs/design.md."""
from .core import (FacetLandmarks, GeometryError, Level, Ligament, SpineGeometry, Vertebra, LEVEL_NAMES,
                   LIGAMENT_KINDS, LIGAMENT_NAMES)
from .analysis import summary_table
from .loader import load_geometry

__all__ = ["load_geometry", "summary_table", "SpineGeometry", "Vertebra", "Level", "Ligament", "FacetLandmarks", "GeometryError",
           "LEVEL_NAMES", "LIGAMENT_KINDS", "LIGAMENT_NAMES"]
