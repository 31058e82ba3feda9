"""lumbar: reproducible lumbar-spine multibody biomechanics.

Units are SI everywhere inside the library (m, N, N*m, rad). One project frame
(the "reference frame") is used for all geometry: x anterior, y left, z superior,
origin as given by the geometry source. Conversion to mm, degrees or MPa happens
only at input and output (tables, figures, command-line).

Lazy imports: trimesh, shapely, scipy.spatial and numba (with the compiled solver core,
:mod:`lumbar.mechanics.kernel`) are imported by the functions that use them, not at module level, so that the
workflow's table, figure and report jobs, which read results and never build a mesh or solve an equilibrium, do
not pay about a second of imports each (tests/test_architecture.py keeps it so).
"""

__version__ = "0.1.0"
