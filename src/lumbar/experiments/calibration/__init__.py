"""Backward calibration of the L4-L5 unit on a stepwise-reduction ROM table (paper 1, Sect. 2.2.2-2.2.4, 3.1.1), and
the admissible (MAP) fit that ends it. Modules by job:

- :mod:`.disc`: Eq. 3 and its fit on the disc-only stage (step 1), its inverse (derived disc-only rows), the form of
  Eq. 7 that is zero at zero strain;
- :mod:`.stepwise`: :func:`calibrate`, the stepwise driver (step 0 on the real rows, steps 1-8 in reverse removal
  order, the final joint fit) and :class:`CalibrationResult`;
- :mod:`.real_targets`: :func:`fit_real_targets`, force scales fitted on measured ROM rows (strain transfer);
- :mod:`.prior`: the ligament laws on elongation the calibration starts from and their spreads;
- :mod:`.probe`, :mod:`.penalties`, :mod:`.admissible`: the admissible fit (:func:`fit_admissible`): its equilibria,
  the admissibility criteria as penalties, the MAP fit with its Laplace posterior and its tables;
- :mod:`.influence`: the MAP refitted without each real row in turn, and what that does to the judged internal
  loads (:func:`row_influence`);
- :mod:`.tables`: the calibrated characteristic directory and the Table 1-3 analogs;
- :mod:`.configured`: :func:`calibrate_configured`, the calibration as the workflow's config and inputs set it up
  (rules calibrate and calibration_influence);
- :mod:`.common`: what the fits share.

The figures (Figs. 4-5 analogs) are drawn by :mod:`lumbar.plots.calibration`. This package never imports snakemake.
"""
from .admissible import (BOUND_REASONS, DATA_SD_REL, DISC_TORQUE_SCALE_BOUNDS, FIT_SCALE_BOUNDS, MAX_PRESTRAIN_PCT,
                         PENALTY_WEIGHT, POSTERIOR_COLUMNS, PRE_ELONGATION_SLACK_MM, START_SCALES, TARGET_COLUMNS,
                         AdmissibleFit, admissible_fit_targets, fit_admissible, posterior_tables, read_fit_start,
                         shift_parameter)
from .common import AT_BOUND_FRACTION, IDENTIFIABLE_MIN_DEG, PENALTY
from .configured import (MAP_TOLERANCE, ConfiguredCalibration, calibrate_configured, check_same_map,
                         reference_inputs)
from .disc import (DISC_STAGE, P1_MIN_NM, c_zero, derived_disc_only_rows, eq3, fit_disc_direction, invert_eq3,
                   softplus_zero_law)
from .influence import COLUMNS as INFLUENCE_COLUMNS
from .influence import internal_loads, row_influence
from .penalties import COMPLIANCE_REFERENCE_WINDOW, FIT_MARGIN
from .prior import (ELONGATION_LIGAMENTS, PRIOR_SOURCE, calibration_prior, elongation_prior, paper_fibre_slack_length,
                    read_prior_set, rupp_as_softplus)
from .probe import PROBE_DIRECTIONS, PROBE_MOMENTS
from .real_targets import FACET_STIFFNESS_RANGE, REAL_FIT_LOG10_BOUNDS, REAL_FIT_PARAMETERS, RealFit, fit_real_targets
from .stepwise import (A_BOUNDS, B_BOUNDS, CALIBRATED_LIGAMENTS, CONCAVE_CANDIDATES, D_BOUNDS, F0_BOUNDS, FACET_STAGE,
                       K_FACET_BOUNDS, LIGAMENT_STAGE, ORDER, CalibrationResult, calibrate)
from .tables import table1, table2, table3, write_characteristics

__all__ = [
    # disc
    "DISC_STAGE", "P1_MIN_NM", "c_zero", "derived_disc_only_rows", "eq3", "fit_disc_direction", "invert_eq3",
    "softplus_zero_law",
    # stepwise driver
    "A_BOUNDS", "B_BOUNDS", "CALIBRATED_LIGAMENTS", "CONCAVE_CANDIDATES", "D_BOUNDS", "F0_BOUNDS", "FACET_STAGE",
    "K_FACET_BOUNDS", "LIGAMENT_STAGE", "ORDER", "CalibrationResult", "calibrate",
    # the calibration as the workflow configures it
    "MAP_TOLERANCE", "ConfiguredCalibration", "calibrate_configured", "check_same_map", "reference_inputs",
    # shared by the fits
    "AT_BOUND_FRACTION", "IDENTIFIABLE_MIN_DEG", "PENALTY",
    # real-target fit
    "FACET_STIFFNESS_RANGE", "REAL_FIT_LOG10_BOUNDS", "REAL_FIT_PARAMETERS", "RealFit", "fit_real_targets",
    # prior
    "ELONGATION_LIGAMENTS", "PRIOR_SOURCE", "calibration_prior", "elongation_prior", "paper_fibre_slack_length",
    "read_prior_set", "rupp_as_softplus",
    # admissible fit
    "BOUND_REASONS", "COMPLIANCE_REFERENCE_WINDOW", "DATA_SD_REL", "DISC_TORQUE_SCALE_BOUNDS", "FIT_MARGIN",
    "FIT_SCALE_BOUNDS", "MAX_PRESTRAIN_PCT", "PENALTY_WEIGHT", "POSTERIOR_COLUMNS", "PRE_ELONGATION_SLACK_MM",
    "PROBE_DIRECTIONS", "PROBE_MOMENTS", "START_SCALES", "TARGET_COLUMNS", "AdmissibleFit", "admissible_fit_targets",
    "fit_admissible", "posterior_tables", "read_fit_start", "shift_parameter",
    # which row decides which internal load
    "INFLUENCE_COLUMNS", "internal_loads", "row_influence",
    # output
    "table1", "table2", "table3", "write_characteristics",
]
