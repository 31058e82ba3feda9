"""The leave-one-row-out finding of the calibration in words (the calibration stage's role row_influence) and the
posterior's share of draws meeting the judged limits, for the posterior section (:mod:`.posterior`; the first page
links there); imports no report module."""
from __future__ import annotations

import numpy as np
import pandas as pd

#: the judged internal loads' limits that the sentences test: the in-vitro mean + 1 SD of the extension facet force
#: (data/load_sharing: Jaumard et al. 2011, 51.5 + 39.0 N) and the SSL's share of the flexion load (Hindle et al. 1990)
FACET_EXT_MAX_N, SSL_MIN_N = 90.5, 5.0


def _sensitivity(t: pd.DataFrame) -> pd.Series:
    """Rows of a sensitivity refit (facet stiffness held, disc-only rows at another spread): neither the MAP nor a
    left-out row."""
    m = pd.Series(False, index=t.index)
    for c in ("facet_stiffness_held", "disc_row_spread"):
        if c in t.columns:
            m |= t[c].notna()
    return m


def influence_sentence(t: pd.DataFrame, fmt) -> str:
    """The leave-one-row-out finding in words, read from the calibration's row_influence table: the row whose removal moves the MAP
    closest to its priors (the smallest largest shift) and what its removal does to the facets and the ITL. ``fmt``: the
    report's number formatter (value, significant digits)."""
    full = t[(t["left_out"].fillna("") == "") & ~_sensitivity(t)]
    # every left-out refit that produced a set (a diagnostic refit that stopped at its evaluation budget is still a set
    # near its optimum: it is named as such, not dropped)
    loo = t[(t["left_out"].fillna("") != "") & np.isfinite(pd.to_numeric(t["rom_flexion_deg"], errors="coerce"))]
    if full.empty or loo.empty:
        return ""
    f = full.iloc[0]

    def top_shift(s):
        first = str(s).split(";")[0].split()
        try:
            return abs(float(first[-2])) if len(first) >= 2 else np.inf
        except ValueError:
            return np.inf
    r = loo.loc[loo["largest_shifts"].map(top_shift).idxmin()]
    if not top_shift(r["largest_shifts"]) < top_shift(f["largest_shifts"]):
        return ""          # no row whose removal brings the MAP nearer its priors
    stopped = "" if bool(r["converged"]) else (" (a diagnostic refit that stopped at its evaluation budget near its "
                                               "optimum)")
    return (f"Without the {r['left_out'].replace('_', ' ')} row{stopped} the MAP stays within "
            f"{fmt(top_shift(r['largest_shifts']), 2)} prior spreads of every prior (with it: "
            f"{f['largest_shifts'].split(';')[0]}): the facet stiffness is {r['facet_stiffness_n_per_m']:.2g} N/m "
            f"instead of {f['facet_stiffness_n_per_m']:.2g}, the extension facet force at 7.5 N*m "
            f"{fmt(r['facet_extension_7_5_n'])} N instead of {fmt(f['facet_extension_7_5_n'])} N, and the largest "
            f"ligament moment in flexion is the {r['largest_flexion_ligament']}'s instead of the "
            f"{f['largest_flexion_ligament']}'s; but the unit then predicts {fmt(r['left_out_predicted_deg'])} deg "
            f"for the left-out row (measured {fmt(r['left_out_measured_deg'])} deg, "
            f"{fmt(100 * r['left_out_rel_error'])} %). This row is the one the model's structure meets only with "
            "internal loads outside their sourced ranges; it stays in the fit.")


def profile_sentence(t: pd.DataFrame, fmt, facet_ext_max_n=FACET_EXT_MAX_N, ssl_min_n=SSL_MIN_N, rom_band=0.25,
                     measured_ar_deg=None) -> str:
    """The facet-stiffness profile in words (the rows of the calibration's row_influence table with
    ``facet_stiffness_held``): the stiffest held value at which the judged internal loads are in their ranges (extension
    facet force at most ``facet_ext_max_n``, the ITL not the largest flexion ligament, the SSL at least ``ssl_min_n``)
    and the axial rotation it then predicts, beside the MAP's. ``facet_ext_max_n``: the in-vitro mean + 1 SD of
    data/load_sharing (Jaumard et al. 2011: 51.5 + 39.0 N). Empty without profile rows."""
    if "facet_stiffness_held" not in t.columns:
        return ""
    # every held refit that produced a set (one that stopped at its evaluation budget included: its loads are those of
    # a set near its optimum, and Table P2 marks it)
    prof = t[t["facet_stiffness_held"].notna() & np.isfinite(pd.to_numeric(t["rom_flexion_deg"], errors="coerce"))
             ].sort_values("facet_stiffness_held")
    full = t[(t["left_out"].fillna("") == "") & ~_sensitivity(t)]
    if prof.empty or full.empty:
        return ""
    f = full.iloc[0]
    ok = prof[(prof["facet_extension_7_5_n"] <= facet_ext_max_n) & (prof["largest_flexion_ligament"] != "ITL")
              & (prof["ssl_flexion_tension_n"] >= ssl_min_n)]
    ar = measured_ar_deg
    if ar is None:
        rows = t[t["left_out"].fillna("") == "axial_rotation"]
        ar = float(rows.iloc[0]["left_out_measured_deg"]) if len(rows) else np.nan

    def err(v):
        return f"{fmt(100 * (v - ar) / ar, 2)} %" if np.isfinite(ar) else "-"
    if ok.empty:
        return (f"Holding the facet stiffness at {', '.join(f'{v:.2g}' for v in prof['facet_stiffness_held'])} N/m "
                "(every other parameter refitted) does not bring the judged internal loads into their ranges either "
                "(Table P2).")
    r = ok.iloc[-1]
    return (f"Held at {fmt(r['facet_stiffness_held'], 2)} N/m with every other parameter refitted, the facet stiffness "
            f"gives an extension facet force of {fmt(r['facet_extension_7_5_n'])} N, the "
            f"{r['largest_flexion_ligament']} as the largest flexion ligament and an SSL tension of "
            f"{fmt(r['ssl_flexion_tension_n'])} N, all in their ranges, with an axial rotation of "
            f"{fmt(r['rom_axial_rotation_deg'])} deg ({err(r['rom_axial_rotation_deg'])} from Yamamoto's); the MAP "
            f"({fmt(f['facet_stiffness_n_per_m'], 3)} N/m) gains {fmt(r['rom_axial_rotation_deg'] - f['rom_axial_rotation_deg'], 2)} "
            f"deg of it ({err(f['rom_axial_rotation_deg'])}) at the cost of those loads."
            + (f" What the held fit pays instead is the disc: its axial-rotation law is "
               f"{fmt(r['disc_axial_rotation_scale'], 2)} x the disc-only fit (the MAP's "
               f"{fmt(f['disc_axial_rotation_scale'], 2)} x), further from the disc-only rows than their assumed "
               f"{fmt(100 * rom_band, 2)} % spread allows; the axial rotation is shared between the disc and the facets, "
               "and the disc-only curve decides the share (Table P2)."
               if np.isfinite(r.get("disc_axial_rotation_scale", np.nan))
               and np.isfinite(f.get("disc_axial_rotation_scale", np.nan)) else " (Table P2)."))


def spread_sentence(t: pd.DataFrame, fmt, facet_ext_max_n=FACET_EXT_MAX_N, ssl_min_n=SSL_MIN_N) -> str:
    """The disc-spread sensitivity in words (rows with ``disc_row_spread``): what the judged internal loads become when
    the disc-only rows, from another study's specimens than the intact rows, are given a wider spread as data. Empty
    without such rows."""
    if "disc_row_spread" not in t.columns:
        return ""
    rows = t[t["disc_row_spread"].notna() & np.isfinite(pd.to_numeric(t["rom_flexion_deg"], errors="coerce"))
             ].sort_values("disc_row_spread")
    if rows.empty:
        return ""
    parts = [f"{fmt(100 * r['disc_row_spread'], 2)} %: disc axial-rotation law {fmt(r['disc_axial_rotation_scale'], 2)} x, "
             f"facet stiffness {r['facet_stiffness_n_per_m']:.2g} N/m, extension facet force "
             f"{fmt(r['facet_extension_7_5_n'])} N, SSL {fmt(r['ssl_flexion_tension_n'])} N"
             for _, r in rows.iterrows()]
    ok = rows[(rows["facet_extension_7_5_n"] <= facet_ext_max_n) & (rows["ssl_flexion_tension_n"] >= ssl_min_n)
              & (rows["largest_flexion_ligament"] != "ITL")]
    verdict = ("every judged internal load is then in its range from a spread of "
               f"{fmt(100 * ok['disc_row_spread'].min(), 2)} % on" if len(ok) else
               "no spread tried brings every judged internal load into its range")
    return ("How much the disc of the specimens behind the disc-only curve (Heuer et al. 2007) may differ from the disc "
            "behind the intact rows (Yamamoto et al. 1989) is not published; the fit assumes the spread of a measured "
            "row. Refitted with the disc-only rows at a wider spread: " + "; ".join(parts) + f"; {verdict} (Table P2).")



def posterior_judged_sentence(draws: pd.DataFrame, fmt, facet_ext_max_n=FACET_EXT_MAX_N,
                              ssl_min_n=SSL_MIN_N) -> str:
    """How probable the judged limits of the extension facet force (at 7.5 N*m, the larger joint) and the SSL tension
    (flexion, 10 N*m) are under the calibration's posterior: the share of the posterior draws (role
    load_sharing.band_draws) that meet each and both. Empty without draws."""
    if draws is None or draws.empty:
        return ""

    def values(direction, moment, quantity):
        g = draws[(draws["direction"] == direction) & np.isclose(draws["moment_nm"].astype(float), moment)
                  & (draws["quantity"] == quantity)]
        return g.set_index("draw")["value"].astype(float)

    fac, ssl = values("extension", 7.5, "facet_max_contact_n"), values("flexion", 10.0, "SSL_tension_n")
    both = pd.concat([fac.rename("f"), ssl.rename("s")], axis=1).dropna()
    if both.empty:
        return ""
    pf, ps = float((both["f"] <= facet_ext_max_n).mean()), float((both["s"] >= ssl_min_n).mean())
    pb = float(((both["f"] <= facet_ext_max_n) & (both["s"] >= ssl_min_n)).mean())
    return (f"Of {len(both)} posterior draws, {fmt(100 * pf, 2)} % keep the extension facet force at 7.5 N*m at or "
            f"below {fmt(facet_ext_max_n)} N (the in-vitro mean + 1 SD), {fmt(100 * ps, 2)} % give the SSL at least "
            f"{fmt(ssl_min_n)} N at 10 N*m flexion, {fmt(100 * pb, 2)} % both: the data behind the calibration "
            + ("make meeting both improbable." if pb < 0.1 else "do not decide them."))
