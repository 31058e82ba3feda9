"""Force laws of the passive and active elements, as pure vectorised functions.

Every law returns its value and its analytic derivative so that the equilibrium
solver can assemble an exact tangent stiffness. Units: see each function.
"""
from .disc import disc_axial_force, disc_torque, torque_angle
from .facet import FacetSurface, contact_penalty, fit_surface
from .ligament import rupp_force, slack_length, slack_ramp, softplus_force, softplus_law

__all__ = [
    "disc_axial_force", "disc_torque", "torque_angle",
    "FacetSurface", "contact_penalty", "fit_surface",
    "rupp_force", "slack_length", "slack_ramp", "softplus_force", "softplus_law",
]
