"""Physical admissibility of a characteristic set on a geometry: does the unit reach its range of motion for the
reasons real segments have?

A set that matches the range of motion at 10 N*m with clamped facets, a ligament switched off or a snap-through in
its curve is a fit, not a model. :func:`assess` simulates a unit (moment-rotation curves in 0.25 N*m steps as a
continuation, the unloaded state, a follower load of 0-1000 N) and :func:`criteria_table` returns one row per
criterion with its value, limit, unit and ``passed``:

- unloaded (0 N*m, no external load): contact force of each facet joint <= ``REST_FACET_MAX_N``; every ligament
  kind's tension <= the largest pre-tension that can be sourced for it (:func:`pretension_limits`: the paper's own law
  at its prestrain, paper 1 Table 3 and Sect. 2.2.4, and the Remus et al. 2021 model of this geometry);
- no snap-through: the rotation changes by less than ``load_sharing.JUMP_DEG`` between moments 0.25 N*m apart, 0-10
  N*m, every direction; the compliance (deg per N*m) does not rise between 2.5 and 10 N*m by more than
  ``COMPLIANCE_RISE_MAX`` (a stiffening curve, as every in-vitro curve);
- neutral zone (a PROXY: the model has no hysteresis): the rotations at +1 and -1 N*m of a plane add up to at least
  ``NZ_FRACTION`` of the neutral zone Yamamoto et al. (1989) measured at that level;
- every ligament functional in flexion (10 N*m): ISL, SSL, FL and CL in tension (>= ``FUNCTIONAL_MIN_N``); the ISL
  and SSL together carry at least ``ISL_SSL_MIN_SHARE`` of the moment and at most the 134 N Hindle et al. (1990)
  measured near the end of flexion, the ISL more than the SSL (Hindle: the ISL 75 % of it); the capsular ligaments
  more of the moment than the flavum (Adams, Hutton & Stott 1980: 39 % vs 13 % at full flexion, an ordering);
- facets: contact force non-decreasing with the moment in extension and (contralateral facet) axial rotation; under a
  pure axial (follower) load the facets carry at most ``COMPRESSION_FACET_MAX_SHARE`` (Adams & Hutton 1980: about 16 %
  in erect standing);
- every ligament's force scale within [``SCALE_MIN``, ``SCALE_MAX``] x the law it was calibrated from, unless its
  tension stays within ``REMUS_FACTOR`` of the Remus et al. (2021) model of the same fibres (the sourced prior for this
  geometry: then the source law is the one far from it); no fitted parameter at a bound without its flag and reason
  (given the calibration's parameter table).

Sourced values are read from ``data/load_sharing/load_sharing_literature.csv`` and
``data/experiments/yamamoto1989_levels_original_text.csv``; the thresholds are project decisions, documented here and
in docs/validity.md. This module never imports snakemake.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from ..geometry.visible_human import read_uw_materials, uw_force
from ..inputs import resources
from ..inputs.characteristics import load_characteristic_set
from .fsu import FSU, build_fsu, softplus_fibre_params
from .load_sharing import JUMP_DEG, axial_compression_curve, moment_rotation_curves
from ..mechanics.elements.ligament import softplus_force

log = logging.getLogger(__name__)

REST_FACET_MAX_N = 20.0
#: the moment step [N*m] of the snap-through criterion (a rotation change of load_sharing.JUMP_DEG or more)
JUMP_STEP_NM = 0.25
#: a ligament within this tension [N] of its pre-tension limit passes (a sourced limit of 0 N = a slack ligament)
REST_TENSION_TOL_N = 0.5
COMPLIANCE_RISE_MAX = 0.10
NZ_FRACTION = 0.75
FUNCTIONAL_MIN_N = 1.0
FUNCTIONAL_KINDS = ("ISL", "SSL", "FL", "CL")
ISL_SSL_MIN_SHARE = 0.10
COMPRESSION_FACET_MAX_SHARE = 0.25
COMPRESSION_N = 1000.0
SCALE_MIN, SCALE_MAX = 0.1, 10.0
#: below this contact force [N] a facet is "not in contact" for the monotonicity check
CONTACT_ON_N = 0.5
#: facet contact may fall by this much [N] between steps before "non-decreasing" fails (contact-point switching)
CONTACT_TOL_N = 0.5
NZ_PLANES = {"flexion_extension": ("flexion", "extension"),
             "lateral_bending_right_left": ("lateral_bending_right", "lateral_bending_left"),
             "axial_rotation_right_left": ("axial_rotation_right", "axial_rotation_left")}


def literature_path() -> Path:
    return resources.data_dir() / "load_sharing" / "load_sharing_literature.csv"


def yamamoto_path() -> Path:
    return resources.data_dir() / "experiments" / "yamamoto1989_levels_original_text.csv"


def _read_with_columns(p: Path, need: set) -> pd.DataFrame:
    """The CSV ``p``; a missing column of ``need`` is an error naming the file and the columns."""
    df = pd.read_csv(p)
    if not need <= set(df.columns):
        raise ValueError(f"{p}: columns {sorted(need - set(df.columns))} missing; expected {sorted(need)}")
    return df


def read_literature(path=None) -> pd.DataFrame:
    return _read_with_columns(Path(path) if path is not None else literature_path(),
                              {"quantity", "value", "unit", "kind", "source"})


def literature_value(lit: pd.DataFrame, quantity: str, load: str | None = None) -> tuple[float, str]:
    sel = lit[lit["quantity"] == quantity]
    if load is not None:
        sel = sel[sel["load"] == load]
    if len(sel) != 1:
        raise ValueError(f"{literature_path()}: expected one row for quantity {quantity!r}"
                         f"{'' if load is None else f' load {load!r}'}, found {len(sel)}")
    r = sel.iloc[0]
    return float(r["value"]), str(r["source"])


def read_yamamoto(path=None) -> pd.DataFrame:
    """ROM (10 N*m, one side) and neutral zones of every lumbar level (Yamamoto et al. 1989)."""
    return _read_with_columns(Path(path) if path is not None else yamamoto_path(),
                              {"level", "quantity", "direction", "value_deg", "source"})


#: the one-sided directions of the Yamamoto table -> the experiment tables' directions
YAMAMOTO_DIRECTIONS = {"flexion": "flexion", "extension": "extension", "lateral_bending_one_side": "lateral_bending",
                       "axial_rotation_one_side": "axial_rotation"}


def yamamoto_level_targets(level: str, path=None) -> pd.DataFrame:
    """The intact ROM at 10 N*m of one level in the experiment-table schema (the form of
    ``data/experiments/yamamoto1989_intact_rom_original_text.csv``, which holds L4-L5): the calibration's real targets
    when a specimen is calibrated on another unit. Each row is a row of :func:`read_yamamoto` (the values as printed),
    renamed; a level without the four ROM rows is an error naming the file."""
    src = Path(path) if path is not None else yamamoto_path()
    y = read_yamamoto(src)
    sel = y[(y["level"] == level) & (y["quantity"] == "rom") & y["direction"].isin(list(YAMAMOTO_DIRECTIONS))]
    if len(sel) != len(YAMAMOTO_DIRECTIONS):
        raise ValueError(f"{src}: level {level!r} has {len(sel)} of the {len(YAMAMOTO_DIRECTIONS)} ROM rows "
                         f"{list(YAMAMOTO_DIRECTIONS)}; expected one per direction")
    return pd.DataFrame({
        "stage": "intact", "direction": sel["direction"].map(YAMAMOTO_DIRECTIONS).to_numpy(),
        "moment_nm": sel["moment_nm"].astype(float).to_numpy(), "rom_mean_deg": sel["value_deg"].to_numpy(float),
        "rom_min_deg": np.nan, "rom_max_deg": np.nan, "n_specimens": sel["n_specimens"].to_numpy(),
        "kind": sel["kind"].to_numpy(), "source": sel["source"].to_numpy(),
        "note": [f"{level} intact ROM at a pure moment of 10 N*m, one side (row {lv} {d} of {src.name}); no range "
                 f"published: rom_min_deg/rom_max_deg empty" for lv, d in zip(sel["level"], sel["direction"])]})


def neutral_zones(level: str, path=None) -> dict:
    y = read_yamamoto(path)
    sel = y[(y["level"] == level) & (y["quantity"] == "neutral_zone")]
    return {r.direction: (float(r.value_deg), str(r.source)) for r in sel.itertuples(index=False)}


# ------------------------------------------------------------------ pre-tension limits
def _fibre_lengths(level_geom, kind):
    out = []
    for lig in level_geom.ligaments:
        if lig.kind == kind:
            L = np.linalg.norm(np.asarray(lig.upper) - np.asarray(lig.lower), axis=1) + np.asarray(lig.extra_length)
            out.append((lig.name, L))
    return out


def pretension_limits(published, prior, geometry, level="L4-L5", geometry_path=None) -> pd.DataFrame:
    """Largest sourced pre-tension [N] of every ligament kind of ``prior`` at ``level``.

    Sources: (1) the paper's own law at its own prestrain on its own fibre (``published``: paper 1 Table 3 with the
    Sect. 2.2.4 prestrains; for a kind Table 3 lacks, e.g. the ITL, the ``prior`` law at its prestrain) -
    derived_from_published_fit; (2) the Remus et al. (2021) model of this geometry (its UW ligament materials, a
    negative reference strain = a pre-stretched fibre), summed over the level's fibres - third_party, when the
    geometry folder has the material files. The limit is the larger of the two."""
    if published is None:
        published = load_characteristic_set("calibrated")
    lev = geometry.levels[level]
    uw = None
    if geometry_path is not None:
        try:
            uw = read_uw_materials(geometry_path, level)
        except Exception as exc:  # noqa: BLE001 - reported, the paper's value still applies
            log.info("no Remus ligament materials for %s (%s): pre-tension limits from the paper only", level, exc)
    rows = []
    for kind, law in prior.ligaments.items():
        pub = published.ligaments.get(kind) if published is not None else None
        if pub is not None and hasattr(pub, "a"):
            F_paper = float(softplus_force(pub.prestrain_pct, pub.a, pub.b, pub.c, pub.d, 0.0)[0])
            paper_src = "paper 1 Table 3 law at its Sect. 2.2.4 prestrain"
        else:
            # the paper gives no calibrated law for this kind (the ITL: "non-validated characteristic"): its
            # pre-tension is sourced only by the model that calibrated this kind on these very fibres (Remus et al.)
            F_paper = np.nan
            paper_src = f"none: paper 1 Table 3 has no {kind} law"
        F_remus = np.nan
        if uw is not None:
            F_remus = 0.0
            for name, L in _fibre_lengths(lev, kind):
                if name in uw:
                    F_remus += float(uw_force(L, L, uw[name]).sum())
        limit = float(np.nanmax([F_paper, F_remus])) if np.isfinite([F_paper, F_remus]).any() else 0.0
        rows.append({"ligament": kind, "paper_pretension_n": F_paper, "remus2021_pretension_n": F_remus,
                     "limit_n": limit,
                     "limit_source": "paper" if (np.isfinite(F_paper) and not F_remus > F_paper) else "Remus et al. 2021",
                     "paper_source": paper_src,
                     "remus_source": "Remus et al. 2021 UW materials of this geometry (data/geometry/visible_human_lss/"
                                     "ligaments/*_UWMat.lig)" if uw is not None else ""})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ simulation
def assess(fsu: FSU, follower_fsu: FSU | None = None, follower_group: int | None = None, moments_nm=None,
           stages=("intact",)):
    """Moment-rotation curves (0-10 N*m, 0.25 N*m steps, continuation) and, with a unit carrying a follower cable,
    the axial compression curve (0-1000 N): (curves, compression or None)."""
    curves = moment_rotation_curves(fsu, moments_nm=moments_nm, stages=stages)
    comp = None
    if follower_fsu is not None:
        comp = axial_compression_curve(follower_fsu, follower_group,
                                       forces_n=np.arange(0.0, COMPRESSION_N + 1e-9, 50.0))
    return curves, comp


# ------------------------------------------------------------------ criteria
def _row(criterion, value, limit, unit, passed, source, note="", direction="", level=""):
    return {"level": level, "criterion": criterion, "direction": direction, "value": value, "limit": limit,
            "unit": unit, "passed": bool(passed), "source": source, "note": note}


def compliance_rise(curve: pd.DataFrame, start_nm=2.5, end_nm=10.0) -> float:
    """Largest relative rise of the tangent compliance (deg per N*m) between ``start_nm`` and ``end_nm`` over its
    value at ``start_nm`` (central differences on the curve's moment grid; 0 or negative for a stiffening curve)."""
    c = curve.sort_values("moment_nm")
    M = c["moment_nm"].to_numpy(float)
    th = c["rotation_deg"].to_numpy(float)
    if len(M) < 3 or not np.all(np.isfinite(th)):
        return float("nan")
    comp = np.gradient(th, M)
    ref = float(np.interp(start_nm, M, comp))
    sel = (M >= start_nm - 1e-9) & (M <= end_nm + 1e-9)
    if ref <= 0:
        return float("inf")
    return float(comp[sel].max() / ref - 1.0)


#: the source of the criteria whose limit is the project's own
_PROJECT = "project threshold (docs/load_sharing.md)"


def criteria_table(curves: pd.DataFrame, compression: pd.DataFrame | None, limits: pd.DataFrame, level: str,
                   nz: dict, literature: pd.DataFrame, scales: dict | None = None,
                   fit_parameters: pd.DataFrame | None = None, stage="intact",
                   remus: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per admissibility criterion (module docstring) from :func:`assess`'s outputs (``remus``: the table of
    :func:`remus_comparison`, the sourced reason a force scale may leave 0.1-10 x its source law), in this order: the
    unloaded state, snap-through and curve shape, the neutral-zone proxy, the ligaments in flexion at 10 N*m, the facets
    loading with the moment, axial compression, the force scales and bounds of the fit."""
    cv = curves[curves["stage"] == stage]
    rows = [*_unloaded_rows(cv, limits, level), *_curve_shape_rows(cv, level), *_neutral_zone_rows(cv, nz, level),
            *_flexion_rows(cv, literature, level), *_facet_loading_rows(cv, level),
            *_compression_rows(compression, literature, level),
            *_fit_rows(scales, remus, fit_parameters, level)]
    return pd.DataFrame(rows, columns=["level", "criterion", "direction", "value", "limit", "unit", "passed", "source",
                                       "note"])


def _unloaded_rows(cv: pd.DataFrame, limits: pd.DataFrame, level: str) -> list:
    """The unloaded state: facet contact and ligament tension at 0 N*m."""
    rows = []
    rest = cv[cv["moment_nm"] == 0.0].iloc[0]
    for side in ("left", "right"):
        col = f"facet_{side}_contact_n"
        if col in rest:
            v = float(rest[col])
            rows.append(_row("unloaded facet contact", v, REST_FACET_MAX_N, "N", v <= REST_FACET_MAX_N, _PROJECT,
                             f"{side} facet joint at 0 N*m, no preload", side, level))
    for r in limits.itertuples(index=False):
        col = f"{r.ligament}_tension_n"
        if col in rest:
            v = float(rest[col])
            rows.append(_row("unloaded ligament tension", v, float(r.limit_n), "N", v <= r.limit_n + REST_TENSION_TOL_N,
                             f"largest sourced pre-tension ({r.limit_source})",
                             f"{r.ligament}: paper {r.paper_pretension_n:.3g} N, Remus et al. 2021 "
                             f"{r.remus2021_pretension_n:.3g} N", r.ligament, level))
    return rows


def _curve_shape_rows(cv: pd.DataFrame, level: str) -> list:
    """Per direction: no snap-through (the rotation change per 0.25 N*m) and the compliance rise 2.5-10 N*m."""
    rows = []
    for d, g in cv.groupby("direction", sort=False):
        g = g.sort_values("moment_nm")
        th = g["rotation_deg"].to_numpy(float)
        dM = np.diff(g["moment_nm"].to_numpy(float))
        # rotation change per JUMP_STEP_NM: a coarser grid's steps are scaled down to the criterion's step
        jump = float(np.nanmax(np.abs(np.diff(th)) * np.minimum(1.0, JUMP_STEP_NM / dM))) if len(th) > 1 else 0.0
        conv = bool(g["converged"].all())
        rows.append(_row("no snap-through: largest rotation change per 0.25 N*m", jump, JUMP_DEG, "deg",
                         conv and jump < JUMP_DEG, _PROJECT, "" if conv else "a step did not converge", d, level))
        rise = compliance_rise(g)
        rows.append(_row("compliance rise 2.5-10 N*m", rise, COMPLIANCE_RISE_MAX, "1", rise <= COMPLIANCE_RISE_MAX,
                         _PROJECT, "relative to the tangent compliance at 2.5 N*m; <= 0: stiffening", d, level))
    return rows


def _neutral_zone_rows(cv: pd.DataFrame, nz: dict, level: str) -> list:
    """The neutral-zone proxy per plane: the rotation at +1 plus -1 N*m against a fraction of the measured zone."""
    rows = []
    for plane, (dpos, dneg) in NZ_PLANES.items():
        if plane not in nz:
            continue
        ref, src = nz[plane]
        # the rotation at 1 N*m of each side, interpolated on its curve (a grid without 1.0 exactly still counts)
        at1 = {}
        for d in (dpos, dneg):
            g = cv[cv["direction"] == d].sort_values("moment_nm")
            if len(g) and g["moment_nm"].min() <= 1.0 <= g["moment_nm"].max():
                at1[d] = float(np.interp(1.0, g["moment_nm"].to_numpy(float), g["rotation_deg"].to_numpy(float)))
        if dpos not in at1 or dneg not in at1:
            continue
        v = float(at1[dpos] + at1[dneg])
        rows.append(_row("neutral-zone proxy: rotation at +1 plus -1 N*m", v, NZ_FRACTION * ref, "deg",
                         v >= NZ_FRACTION * ref, src,
                         f"{NZ_FRACTION:g} x the measured neutral zone {ref:g} deg; a proxy (no hysteresis in the "
                         "model)", plane, level))
    return rows


def _flexion_rows(cv: pd.DataFrame, literature: pd.DataFrame, level: str) -> list:
    """The ligaments in flexion at the largest moment (10 N*m): in tension, the ISL+SSL share and force, the ISL
    above the SSL, the CL moment above the FL moment."""
    rows = []
    f10 = cv[(cv["direction"] == "flexion") & np.isclose(cv["moment_nm"], cv["moment_nm"].max())]
    if not len(f10):
        return rows
    f10 = f10.iloc[0]
    Mapp = float(f10["moment_nm"])
    for k in FUNCTIONAL_KINDS:
        col = f"{k}_tension_n"
        if col in f10:
            v = float(f10[col])
            rows.append(_row("ligament in tension at 10 N*m flexion", v, FUNCTIONAL_MIN_N, "N",
                             v >= FUNCTIONAL_MIN_N, _PROJECT, "", k, level))

    def moment(k):
        col = f"{k}_moment_y_nm"
        return -float(f10[col]) if col in f10 else 0.0      # resisting flexion = negative y moment
    isl_ssl = moment("ISL") + moment("SSL")
    v_share = isl_ssl / Mapp
    hindle_f, hsrc = literature_value(literature, "isl_ssl_force_end_of_flexion")
    rows.append(_row("ISL+SSL share of the flexion moment at 10 N*m", v_share, ISL_SSL_MIN_SHARE, "1",
                     v_share >= ISL_SSL_MIN_SHARE, hsrc,
                     "Hindle et al. 1990: the ISL and SSL resist a real part of flexion (about 7 N*m near its end)",
                     "flexion", level))
    force = float(f10.get("ISL_tension_n", 0.0) + f10.get("SSL_tension_n", 0.0))
    rows.append(_row("ISL+SSL tension at 10 N*m flexion at most the end-of-flexion maximum", force, hindle_f, "N",
                     force <= hindle_f, hsrc, "", "flexion", level))
    if "ISL_tension_n" in f10 and "SSL_tension_n" in f10:
        isl, ssl = float(f10["ISL_tension_n"]), float(f10["SSL_tension_n"])
        frac, fsrc = literature_value(literature, "isl_fraction_of_isl_ssl_force")
        rows.append(_row("ISL carries more than the SSL at 10 N*m flexion", isl / max(isl + ssl, 1e-12), 0.5,
                         "1", isl > ssl, fsrc, f"measured: the ISL {frac:g} % of the ISL+SSL force", "flexion",
                         level))
    if "CL_moment_y_nm" in f10 and "FL_moment_y_nm" in f10:
        cl, fl = moment("CL"), moment("FL")
        c_sh, csrc = literature_value(literature, "capsular_ligament_share_of_flexion_resistance")
        f_sh, _ = literature_value(literature, "ligamentum_flavum_share_of_flexion_resistance")
        rows.append(_row("CL moment above FL moment at 10 N*m flexion", cl - fl, 0.0, "N*m", cl > fl, csrc,
                         f"ordering of the full-flexion shares CL {c_sh:g} % > FL {f_sh:g} % (not a tolerance at "
                         "10 N*m)", "flexion", level))
    return rows


def _facet_loading_rows(cv: pd.DataFrame, level: str) -> list:
    """The facets load with the moment in extension (both) and in axial rotation (the contralateral one)."""
    rows = []
    for d, side in (("extension", None), ("axial_rotation_left", "right"), ("axial_rotation_right", "left")):
        g = cv[cv["direction"] == d].sort_values("moment_nm")
        if not len(g):
            continue
        cols = [c for c in g.columns if c.startswith("facet_") and c.endswith("_contact_n")]
        if side is not None:
            cols = [f"facet_{side}_contact_n"]
        if not all(c in g for c in cols):
            continue
        F = g[cols].sum(axis=1).to_numpy(float)
        on = F > CONTACT_ON_N
        # a drop counts where the facets were in contact before or after the step: one that opens within a step
        # (in contact, then not) is a drop too
        drop = float(np.max(np.maximum(0.0, -np.diff(F))[on[:-1] | on[1:]], initial=0.0))
        rows.append(_row("facet contact non-decreasing with the moment", drop, CONTACT_TOL_N, "N",
                         drop <= CONTACT_TOL_N and F[-1] > F[0], _PROJECT,
                         f"{'both facets' if side is None else side + ' (contralateral) facet'}: {F[0]:.3g} -> "
                         f"{F[-1]:.3g} N from 0 to {g['moment_nm'].max():g} N*m; value = largest drop", d, level))
    return rows


def _compression_rows(compression: pd.DataFrame | None, literature: pd.DataFrame, level: str) -> list:
    """The facet share of a pure axial (follower) load at its largest force."""
    if compression is None or not len(compression):
        return []
    last = compression.sort_values("force_n").iloc[-1]
    share = float(last["facet_share"])
    ref, src = literature_value(literature, "facet_share_of_compression", "erect standing posture")
    return [_row("facet share of a pure axial (follower) load", share, COMPRESSION_FACET_MAX_SHARE, "1",
                 bool(last["converged"]) and share <= COMPRESSION_FACET_MAX_SHARE, src,
                 f"at {last['force_n']:g} N; measured about {ref:g} % in erect standing", "compression", level)]


def _fit_rows(scales: dict | None, remus: pd.DataFrame | None, fit_parameters: pd.DataFrame | None,
              level: str) -> list:
    """The fit: every ligament force scale within 0.1-10 x its source law (or, outside, near the Remus et al. 2021
    model of the same fibres), and no fitted parameter at a bound without a documented reason."""
    rows = []
    for k, s in (scales or {}).items():
        inside = SCALE_MIN * (1 - 1e-9) <= s <= SCALE_MAX * (1 + 1e-9)
        note, src = "", _PROJECT
        if not inside and remus is not None and k in set(remus["ligament"]):
            r = remus[(remus["ligament"] == k) & (remus["remus2021_n"] > 1.0)]
            if len(r):
                top = r.loc[r["remus2021_n"].idxmax()]
                inside = bool(1.0 / REMUS_FACTOR <= top["ratio"] <= REMUS_FACTOR)
                note = (f"outside 0.1-10 x its source law; {top['model_n']:.3g} N vs {top['remus2021_n']:.3g} N of the "
                        f"Remus et al. (2021) model of these fibres at {top['state']} (factor {REMUS_FACTOR:g} "
                        "allowed): the source law, not the calibrated one, is far from this geometry")
                src = "Remus et al. 2021 (data/geometry/visible_human_lss/ligaments/*_UWMat.lig)"
        rows.append(_row("ligament force scale within 0.1-10 x its source law", s, SCALE_MAX if s > 1 else SCALE_MIN,
                         "1", inside, src, note, k, level))
    if fit_parameters is not None and len(fit_parameters) and "at_bound" in fit_parameters:
        fp = fit_parameters
        bad = fp[fp["at_bound"].astype(bool) & (fp.get("bound_reason", pd.Series("", index=fp.index))
                                                .fillna("").astype(str) == "")]
        rows.append(_row("fitted parameters at a bound without a documented reason", float(len(bad)), 0.0, "count",
                         len(bad) == 0, _PROJECT, "; ".join(bad["parameter"].astype(str)), "", level))
    return rows


def force_scales(charset, prior) -> dict:
    """Force scale of every softplus ligament of ``charset`` relative to ``prior`` (a / a_prior)."""
    out = {}
    for k, law in charset.ligaments.items():
        p = prior.ligaments.get(k)
        if p is not None and hasattr(law, "a") and hasattr(p, "a") and p.a != 0:
            out[k] = float(law.a / p.a)
    return out


def evaluate(geometry, charset, prior, published, level="L4-L5", geometry_path=None, fit_parameters=None,
             moments_nm=None, facet_stiffness_n_per_m=None, disc_shear_stiffness_n_per_m=None
             ) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The one admissibility check of a characteristic set on a geometry level: (criteria table, curves, compression)."""
    if published is None:
        published = load_characteristic_set("calibrated")
    fsu = build_fsu(geometry, charset, level, facet_stiffness_n_per_m=facet_stiffness_n_per_m,
                    disc_shear_stiffness_n_per_m=disc_shear_stiffness_n_per_m, follower=True)
    curves, comp = assess(fsu, fsu, fsu.follower_group, moments_nm=moments_nm)
    limits = pretension_limits(published, prior, geometry, level, geometry_path)
    remus = remus_comparison(fsu, geometry_path) if geometry_path is not None else None
    table = criteria_table(curves, comp, limits, level, {k: v for k, v in neutral_zones(level).items()},
                           read_literature(), force_scales(charset, prior), fit_parameters, remus=remus)
    return table, curves, comp


#: states of the comparison with the Remus et al. (2021) model: rest and 10 N*m in four directions
REMUS_STATES = (("rest", None, 0.0), ("flexion 10 N*m", "flexion", 10.0), ("extension 10 N*m", "extension", 10.0),
                ("lateral bending 10 N*m", "lateral_bending_right", 10.0),
                ("axial rotation 10 N*m", "axial_rotation_left", 10.0))
#: a force scale outside [SCALE_MIN, SCALE_MAX] passes when the ligament's tension stays within this factor of the
#: Remus et al. (2021) model of the same fibres (a sourced prior for this geometry) where that model loads it most
REMUS_FACTOR = 5.0


def remus_comparison(fsu: FSU, geometry_path, max_iter=80) -> pd.DataFrame:
    """Tension of every ligament kind of a unit against the Remus et al. (2021) model's law on the same fibres at the
    same deformation (rest and 10 N*m flexion, extension, lateral bending, axial rotation): ligament, state,
    model_n, remus2021_n, ratio. A comparison with the model calibrated on exactly these fibres, never a target."""
    from ..mechanics.solve import solve_sequence  # noqa: PLC0415 - the comparison's own continuation
    from .fsu import moment_loads  # noqa: PLC0415
    m, lev = fsu.model, fsu.level
    uw = read_uw_materials(geometry_path, lev.name)
    dirs = [d for _, d, _ in REMUS_STATES if d]
    fm, cm = fsu.masks(["intact"] * len(dirs))
    path = np.stack([moment_loads(dirs, [M] * len(dirs), m.nb) for M in np.linspace(0.0, 10.0, 11)])
    steps = solve_sequence(m, path, fmask=fm, cmask=cm, max_iter=max_iter)
    states = {"rest": (steps[0].x[:1], steps[0].R[:1], bool(steps[0].converged[0]))}
    for i, (label, d, _) in enumerate(REMUS_STATES[1:]):
        states[label] = (steps[-1].x[[i]], steps[-1].R[[i]], bool(steps[-1].converged[i]))
    rows = []
    for label, (x, R, conv) in states.items():
        length, _, T = m.fibre_state(x, R, fm[:1])[:3]
        for g, (name, kind, lv) in enumerate(m.fibre_groups):
            if lv != lev.name or kind not in LIGAMENT_KINDS_REMUS or name not in uw:
                continue
            sel = m.f_group == g
            row = {"ligament": kind, "state": label, "converged": conv}
            rows.append({**row, "model_n": float(T[0, sel].sum()),
                         "remus2021_n": float(uw_force(length[0, sel], m.f_lref[sel], uw[name]).sum())})
    df = pd.DataFrame(rows).groupby(["ligament", "state"], sort=False, as_index=False).agg(
        model_n=("model_n", "sum"), remus2021_n=("remus2021_n", "sum"), converged=("converged", "all"))
    with np.errstate(divide="ignore", invalid="ignore"):
        df["ratio"] = np.where(df["remus2021_n"] > 1e-9, df["model_n"] / df["remus2021_n"], np.nan)
    return df


LIGAMENT_KINDS_REMUS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL")


def fibre_tension_remus(geometry_path, level_geom, level, kind, lengths: dict) -> float:
    """Total tension [N] of a ligament kind under the Remus et al. (2021) law at given fibre lengths
    ({ligament name: (n,) lengths [m]}); a comparison, never a target."""
    uw = read_uw_materials(geometry_path, level)
    total = 0.0
    for name, L0 in _fibre_lengths(level_geom, kind):
        if name in uw and name in lengths:
            total += float(uw_force(lengths[name], L0, uw[name]).sum())
    return total


__all__ = ["assess", "criteria_table", "evaluate", "pretension_limits", "force_scales", "neutral_zones",
           "read_literature", "read_yamamoto", "yamamoto_level_targets", "compliance_rise", "softplus_fibre_params"]
