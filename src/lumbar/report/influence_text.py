"""The leave-one-row-out finding of the calibration in words (the calibration stage's role row_influence), shared by the
first page (:mod:`.sections`) and the posterior section (:mod:`.posterior`); imports no report module."""
from __future__ import annotations

import numpy as np
import pandas as pd


def influence_sentence(t: pd.DataFrame, fmt) -> str:
    """The leave-one-row-out finding in words, read from the calibration's row_influence table: the row whose removal moves the MAP
    closest to its priors (the smallest largest shift) and what its removal does to the facets and the ITL. ``fmt``: the
    report's number formatter (value, significant digits)."""
    full = t[t["left_out"].fillna("") == ""]
    loo = t[(t["left_out"].fillna("") != "") & t["converged"].astype(bool)]
    if full.empty or loo.empty:
        return ""
    f = full.iloc[0]

    def top_shift(s):
        first = str(s).split(";")[0].split()
        return abs(float(first[-2])) if len(first) >= 2 else np.inf
    r = loo.loc[loo["largest_shifts"].map(top_shift).idxmin()]
    return (f"Without the {r['left_out'].replace('_', ' ')} row the MAP stays within "
            f"{fmt(top_shift(r['largest_shifts']), 2)} prior spreads of every prior (with it: "
            f"{f['largest_shifts'].split(';')[0]}): the facet stiffness is {fmt(r['facet_stiffness_n_per_m'], 3)} N/m "
            f"instead of {fmt(f['facet_stiffness_n_per_m'], 3)}, the extension facet force at 7.5 N*m "
            f"{fmt(r['facet_extension_7_5_n'])} N instead of {fmt(f['facet_extension_7_5_n'])} N, and the largest "
            f"ligament moment in flexion is the {r['largest_flexion_ligament']}'s instead of the "
            f"{f['largest_flexion_ligament']}'s; but the unit then predicts {fmt(r['left_out_predicted_deg'])} deg "
            f"for the left-out row (measured {fmt(r['left_out_measured_deg'])} deg, "
            f"{fmt(100 * r['left_out_rel_error'])} %). This row is the one the model's structure meets only with "
            "internal loads outside their sourced ranges; it stays in the fit.")
