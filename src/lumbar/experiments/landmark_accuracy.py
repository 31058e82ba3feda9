"""What the automatic landmarks get wrong, and what that does to the unit: the accuracy of the specimen path where
the truth is known (:func:`lumbar.geometry.specimen_accuracy.visible_human_accuracy`: the Visible Human meshes given
as a user gives them, leave one out) and the calibrated unit on the automatic geometry beside the same unit on the
reference landmarks (:func:`landmark_error_effect`): range of motion at 10 N*m and the judged internal loads.

Both units carry the same characteristic set (laws on elongation, pre-elongations in mm: the documented transfer
to another geometry of the same specimen); their ROM is about each geometry's own project axes (the specimen's
frame comes from its anatomy, the reference's from the model), so a difference includes the frames' few-degree
disagreement.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from .calibration.influence import internal_loads

EFFECT_COLUMNS = ("quantity", "unit", "reference_landmarks", "automatic_landmarks", "difference", "relative_difference")
_ROWS = (("ROM flexion, 10 N*m", "deg", ("rom", "flexion")),
         ("ROM extension, 10 N*m", "deg", ("rom", "extension")),
         ("ROM lateral bending (right), 10 N*m", "deg", ("rom", "lateral_bending_right")),
         ("ROM axial rotation (left), 10 N*m", "deg", ("rom", "axial_rotation_left")),
         ("facet force, extension 7.5 N*m (larger joint)", "N", ("facet_extension_7_5_n",)),
         ("facet force, axial rotation 7.5 N*m (loaded joint)", "N", ("facet_axial_rotation_7_5_n",)),
         ("ITL moment, flexion 10 N*m", "N*m", ("itl_flexion_moment_nm",)),
         ("ISL moment, flexion 10 N*m", "N*m", ("isl_flexion_moment_nm",)),
         ("SSL tension, flexion 10 N*m", "N", ("ssl_flexion_tension_n",)))


def _get(d, path):
    for k in path:
        d = d[k]
    return float(d)


def landmark_error_effect(reference_geometry, specimen_geometry, charset, level="L4-L5") -> pd.DataFrame:
    """The unit of ``level`` with ``charset`` on the reference and on the automatic (specimen) geometry:
    :data:`EFFECT_COLUMNS`, one row per quantity (ROM at 10 N*m, facet forces at 7.5 N*m, flexion roles at 10 N*m),
    plus the largest flexion ligament of each and whether every curve converged (rows with text values)."""
    ref = internal_loads(reference_geometry, charset, level)
    auto = internal_loads(specimen_geometry, charset, level)
    rows = []
    for q, unit, path in _ROWS:
        a, b = _get(ref, path), _get(auto, path)
        rows.append({"quantity": q, "unit": unit, "reference_landmarks": a, "automatic_landmarks": b,
                     "difference": b - a, "relative_difference": (b - a) / a if abs(a) > 1e-9 else np.nan})
    rows.append({"quantity": "largest ligament moment, flexion 10 N*m", "unit": "",
                 "reference_landmarks": ref["largest_flexion_ligament"],
                 "automatic_landmarks": auto["largest_flexion_ligament"], "difference": np.nan,
                 "relative_difference": np.nan})
    rows.append({"quantity": "every curve converged", "unit": "", "reference_landmarks": ref["converged"],
                 "automatic_landmarks": auto["converged"], "difference": np.nan, "relative_difference": np.nan})
    return pd.DataFrame(rows).reindex(columns=list(EFFECT_COLUMNS))
