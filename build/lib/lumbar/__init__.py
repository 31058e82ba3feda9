"""lumbar: reproducible lumbar-spine multibody biomechanics.

Units are SI everywhere inside the library (m, N, N*m, rad). One project frame
(the "reference frame") is used for all geometry: x anterior, y left, z superior,
origin as given by the geometry source. Conversion to mm, degrees or MPa happens
only at input and output (tables, figures, command-line).
"""

__version__ = "0.1.0"
