"""What the calibration's fits share: the residual of a scenario without equilibrium, the at-bound and
identifiability thresholds, and small helpers on characteristic sets, models and reference rows."""
from __future__ import annotations

import copy
import dataclasses

import numpy as np

#: residual of a scenario without equilibrium (every fit of the calibration)
PENALTY = 10.0
AT_BOUND_FRACTION = 0.01          # a parameter within 1 % of its bound range from a bound is flagged at_bound
IDENTIFIABLE_MIN_DEG = 0.05       # ROM change [deg] per decade below which a parameter is not identifiable


def replace_fields(obj, **kw):
    """``obj`` with the fields ``kw`` replaced (``dataclasses.replace`` for a dataclass, a shallow copy otherwise)."""
    if dataclasses.is_dataclass(obj):
        return dataclasses.replace(obj, **kw)
    out = copy.copy(obj)
    for k, v in kw.items():
        setattr(out, k, v)
    return out


def kind_groups(model, kind):
    """Indices of the model's fibre groups of ligament ``kind``."""
    return [g for g, (_, k, _) in enumerate(model.fibre_groups) if k == kind]


def stage_rows(ref, stage):
    """The reference rows of ``stage`` (a clear error when there are none)."""
    r = ref[ref["stage"] == stage].reset_index(drop=True)
    if r.empty:
        raise ValueError(f"reference table has no rows for stage {stage!r} (needed to calibrate it)")
    return r


def rom_widths(rows, tolerance_deg):
    """Residual scale [deg] per reference row: its max - min where it has a range, else 2 x ``tolerance_deg``."""
    lo, hi = rows["rom_min_deg"].to_numpy(float), rows["rom_max_deg"].to_numpy(float)
    w = np.where(np.isfinite(lo) & np.isfinite(hi), hi - lo, 2.0 * tolerance_deg)
    return np.maximum(w, 0.05)
