"""The calibration as the workflow configures it: the reference table from the configured inputs, and
:func:`.stepwise.calibrate` with the config's settings. The one place rules ``calibrate`` and ``calibration_influence``
share (the second reruns the first, deterministically, with the diagnostic refits from its MAP). Plain paths and the
config's sections in; no snakemake.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import pandas as pd

from ...geometry.configured import load_configured
from ...inputs.characteristics import load_characteristic_set
from ..fsu import disc_shear_override
from ..stepwise_reduction import read_experiment_table, reference_table
from .admissible import admissible_fit_targets, read_fit_start
from .stepwise import CalibrationResult, calibrate

log = logging.getLogger(__name__)


@dataclass
class ConfiguredCalibration:
    """What a configured calibration returns: the result, the start set (the characteristic set ``calibrated`` of
    the characteristics folder), the rows the final fit is pinned to (None without real intact rows) and the data
    kind of the reference ("surrogate" or "measured")."""
    result: CalibrationResult
    start_set: object
    targets: pd.DataFrame | None
    data_kind: str


def reference_inputs(experiment, derived=None, real_targets=()) -> tuple[pd.DataFrame, pd.DataFrame | None, str]:
    """(reference table, real target rows or None, data kind) from the stepwise-reduction table ``experiment``, the
    derived disc-only rows ``derived`` (a path or None) and the real target tables ``real_targets`` (paths)."""
    exp = read_experiment_table(experiment)
    der = read_experiment_table(derived) if derived else None
    real = [read_experiment_table(p) for p in real_targets]
    real = pd.concat(real, ignore_index=True) if real else None
    ref = reference_table(exp, der, real)
    data_kind = "surrogate" if (ref["kind"] == "surrogate").any() else "measured"
    log.info("calibrating on %s (%d rows; kinds %s)", experiment, len(ref), dict(ref["kind"].value_counts()))
    return ref, real, data_kind


def calibrate_configured(geometry: dict, fsu: dict, solver: dict, sr: dict, experiment, derived, real_targets,
                         characteristics_dir, generator_fit=None, row_influence=False) -> ConfiguredCalibration:
    """The calibration of the config sections ``geometry``, ``fsu``, ``solver`` and ``stepwise_reduction`` (``sr``)
    on the inputs (:func:`reference_inputs`), started from the characteristics folder's set and the surrogate
    generator's anchoring fit ``generator_fit`` (a path or None); ``row_influence``: with the diagnostic refits from
    its MAP (:func:`.influence.row_influence`)."""
    ref, real, data_kind = reference_inputs(experiment, derived, real_targets)
    geo = load_configured(geometry, levels=[fsu["level"]])
    paper = load_characteristic_set("calibrated", data_dir=characteristics_dir)
    anchor = read_fit_start(generator_fit) if generator_fit else None
    targets, origin = admissible_fit_targets(ref, real)
    if targets is None:
        log.warning("no intact ROM rows at 10 N*m in %s nor in stepwise_reduction.real_targets: the calibration ends "
                    "at the stepwise fits, WITHOUT the admissibility constraints (the admissibility table of the "
                    "calibration stage says which criteria the set fails)", experiment)
    else:
        log.info("final fit (admissibility-constrained) pinned to %s (%d rows)", origin, len(targets))
    res = calibrate(geo, ref, initial=paper, level=fsu["level"], k_shear=disc_shear_override(fsu),
                    tolerance_deg=sr["outlier_tolerance_deg"], data_kind=data_kind, max_iter=solver["max_iter"],
                    surrogate_weight=sr["surrogate_weight"], family=sr["calibration_family"],
                    final_surrogate_weight=sr["final_surrogate_weight"], real_targets=targets,
                    transfer=sr["ligament_transfer"],
                    geometry_path=geometry["path"] if geometry["kind"] == "visible_human" else None,
                    anchor_start_values=anchor, prior=sr["ligament_prior"], row_influence=row_influence)
    log.info("calibration wall time %.1f s", res.wall_time_s)
    return ConfiguredCalibration(res, paper, targets, data_kind)


#: MAP agreement of the rerun with the shipped posterior, relative (fit units: log10 scales, mm, %; |difference| <=
#: MAP_TOLERANCE * (1 + |value|)): the CSV keeps six significant digits (measured: differences up to 5e-6 on values
#: of about 1); a larger difference means the two jobs fitted different problems
MAP_TOLERANCE = 1e-5


def check_same_map(shipped: pd.DataFrame, rerun: pd.DataFrame, path) -> None:
    """Raise if the rerun's MAP (``map_fit`` per parameter) is not the one in the shipped posterior ``path``."""
    a = shipped.set_index("parameter")["map_fit"]
    b = rerun.set_index("parameter")["map_fit"]
    if set(a.index) != set(b.index):
        raise RuntimeError(f"{path}: parameters {sorted(a.index)}; the rerun fitted {sorted(b.index)}: "
                           "rerun rule calibrate")
    d = (a - b.reindex(a.index)).abs()
    bad = d[~(d <= MAP_TOLERANCE * (1.0 + a.abs()))]
    if len(bad):
        raise RuntimeError(f"{path}: the rerun's MAP differs from the shipped one in "
                           + ", ".join(f"{k} by {v:.3g}" for k, v in bad.items())
                           + f" (fit units; tolerance {MAP_TOLERANCE} x (1 + |value|)): rerun rule calibrate")
