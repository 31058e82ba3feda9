"""The one registry of table schemas: every table kind the library reads (and the column vocabulary of the
tables it compares), with the vocabularies their columns allow, and ``read_kind`` to read one validated.

Every kind of table under ``data/`` (and every user table the config can point to) has a
:class:`lumbar.inputs.io.TableSchema` here; reading goes through :func:`lumbar.inputs.io.read_table`, whose
:class:`lumbar.inputs.io.TableError` names the file, the 1-based data row and the column, and states the expected
form. The stage modules import their schemas and vocabularies from this module (it imports nothing from
``lumbar`` but :mod:`lumbar.inputs.io`):

====================  ================================================  =====================================
kind                  files                                             schema
====================  ================================================  =====================================
disc, facet, ...      data/characteristics/*.csv                        DISC, FACET, LIGAMENTS_SOFTPLUS, ...
stepwise_rom          data/experiments/heuer2007_*.csv, measured        STEPWISE_ROM
idp_invitro           l2s1.measured_table (Wilke et al. 1996 layout)    IDP_INVITRO
cables                data/cables/wilke1996_cables.csv                  CABLES
landmarks             data/landmarks/myo_sim_landmarks.csv              LANDMARKS
muscle_groups         data/muscles/muscle_groups.csv                    MUSCLE_GROUPS
anthropometry         data/anthropometry/upper_body_segments.csv        ANTHROPOMETRY
in_vivo_idp           data/in_vivo/wilke_idp_l4l5.csv, wilke1999_*.csv  IN_VIVO_IDP
neutral_angle         data/experiments/heuer2007_va_artefact_*.csv      NEUTRAL_ANGLE (discovery)
in_vivo               stage manifest role muscle_model.validation       IN_VIVO (discovery)
====================  ================================================  =====================================

:data:`MEASURED` says which of them the discrepancy discovery reads and by which columns it recognises each;
:data:`VS_PAPER_COLUMNS` is the one column vocabulary of the outlier counts beside the paper's
(``table4_vs_paper.csv``, ``table5_vs_paper.csv``; :func:`versus_paper`).
"""
from __future__ import annotations

import functools
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from . import resources
from .io import Column, TableError, TableSchema, UniqueKey, read_table

__all__ = ["LANDMARKS", "MUSCLE_GROUPS", "ANTHROPOMETRY", "IN_VIVO_IDP", "DISC", "FACET", "LIGAMENTS_SOFTPLUS",
           "LIGAMENT_PRESTRAIN", "LIGAMENTS_RUPP2015", "RUPP2015_SHAPE_CHECK", "STEPWISE_ROM", "IDP_INVITRO",
           "CABLES", "NEUTRAL_ANGLE", "IN_VIVO", "TABLE_KINDS", "schema_of", "read_kind", "DATA_FILES", "MEASURED",
           "MeasuredKind", "VS_PAPER_COLUMNS", "OUTLIER_COUNT_NAMES", "versus_paper", "PLAUSIBILITY_FACTOR",
           "UNIT_CONFUSIONS", "PLAUSIBILITY_SOURCES", "SourcedRange", "sourced_ranges", "PlausibleRange",
           "plausible_ranges", "check_measured", "LABEL_TABLE"]

log = logging.getLogger(__name__)

# ------------------------------------------------------------------ vocabularies of the columns
#: the characteristic sets (paper 1, Appendix 1, and the calibrated set of Table 3); the first five have
#: softplus (Eq. 7) ligament laws
CHARACTERISTIC_SETS = ("calibrated", "chazal1985", "shirazi_adl1986", "white_panjabi1990", "nolte1990", "rupp2015")
SOFTPLUS_SETS = CHARACTERISTIC_SETS[:5]
LIGAMENT_KINDS = ("ALL", "PLL", "FL", "CL", "ISL", "SSL", "ITL")
#: data kinds of the characteristic tables
CHARACTERISTIC_KINDS = frozenset({"original_text", "original_figure", "third_party", "derived_from_published_fit",
                                  "surrogate",
                                  # written by lumbar.experiments.calibration.write_characteristics
                                  # (role calibration.characteristics of the stage manifests)
                                  "calibrated_on_surrogate", "calibrated_on_measured"})
#: reduction stages of the stepwise-reduction experiment (Heuer et al. 2007), in removal order
STAGES = ("intact", "wo_ssl", "wo_isl", "wo_fl", "wo_cl", "wo_va", "wo_pll", "wo_all")
#: the four loading directions of the stepwise-reduction tables
MAIN_DIRECTIONS = ("flexion", "extension", "lateral_bending", "axial_rotation")
#: the out-of-library causes of the discovery benchmark (config key discovery.benchmark.out_of_library;
#: lumbar.discovery.power_study.OUT_OF_LIBRARY describes them) and the experiment each acts on: which benchmark job
#: needs which model and specimen files (the workflow's rule files import it)
OUT_OF_LIBRARY_EXPERIMENT = {"disc_scale": "stepwise_rom", "ligament_removed": "stepwise_rom",
                             "rom_scale_per_direction": "stepwise_rom", "idp_scale": "idp_invitro"}
#: the fixture specimens of the in-vitro IDP benchmark are simulated in this many parts (files
#: fixture_specimens_idp_<k>.csv, rule discovery_fixture_specimens_idp), so that both cores make them
IDP_FIXTURE_PARTS = 4
#: the muscle parameters of the sensitivity study (paper 2, Sect. 2.5), in the order of its tables and figures
#: (lumbar.muscles.muscle_model.PARAMETERS; rule muscle_sensitivity_table names one figure per parameter)
MUSCLE_SENSITIVITY_PARAMETERS = ("ssl_um", "k_n_per_cm2", "in_situ_sl_um", "spt_n_per_cm2", "pennation_deg")
#: data kinds of a reference ROM table
ROM_DATA_KINDS = frozenset({"measured", "original_text", "original_figure", "third_party",
                            "derived_from_published_fit", "surrogate"})
#: the L2-S1 model (Wilke et al. 1996): free vertebrae, cable muscle pairs, muscle set-ups and load cases
L2S1_FREE = ("L2", "L3", "L4", "L5")
L2S1_MUSCLES = ("multifidus_caudal", "iliocostalis_longissimus", "psoas_vertebral_bodies",
                "psoas_transverse_processes", "multifidus_cranial")
MUSCLE_SETUPS = ("none",) + L2S1_MUSCLES + ("all",)
LOAD_CASES = ("neutral", "flexion", "extension", "axial_rotation_left", "axial_rotation_right",
              "lateral_bending_left", "lateral_bending_right")

#: provenance kinds of data rows (README "Data provenance"), plus the geometry-derived and summary kinds
PROVENANCE = frozenset({"original_text", "original_figure", "third_party", "third_party_summary",
                        "derived_from_published_fit", "derived_from_geometry", "surrogate", "measured"})
_VERTEBRAE = frozenset({"L1", "L2", "L3", "L4", "L5", "S1"})
_LEVELS = frozenset({"L1-L2", "L2-L3", "L3-L4", "L4-L5", "L5-S1"})
_TEXT_OPT = Column("str", required=False, nullable=True)

LANDMARKS = TableSchema("landmarks", {
    "level": Column("str", allowed=_LEVELS),
    "structure": Column("str", allowed=frozenset({"ALL", "PLL", "FL", "CL_L", "CL_R", "ISL", "SSL", "ITL_L",
                                                  "ITL_R", "facet_superior", "facet_inferior"})),
    "side": Column("str", allowed=frozenset({"left", "right", "medial"})),
    "point_index": Column("int", min=0),
    # a lumbar vertebra lies well within 1 m of the origin in the project frame; millimetres would not
    "x_m": Column("float", min=-1.0, max=1.0, description="metres, project frame: x anterior"),
    "y_m": Column("float", min=-1.0, max=1.0, description="metres, project frame: y left"),
    "z_m": Column("float", min=-1.0, max=2.5, description="metres, project frame: z superior"),
    "body": Column("str", allowed=_VERTEBRAE),
    "vertex_index": Column("int", min=-1, nullable=True, description="mesh vertex the point came from; -1 = none"),
    "rule": Column("str"),
    "source": Column("str"),
    "kind": Column("str", allowed=PROVENANCE),
})

MUSCLE_GROUPS = TableSchema("muscle_groups", {
    "prefix": Column("str"),
    "group": Column("str", allowed=frozenset({"MF", "IL", "LT", "QL", "Ps", "EO", "IO", "RA"})),
    "in_situ_sl_um": Column("float", min=1.0, max=5.0, description="in-situ sarcomere length [um]"),
    "in_situ_sl_kind": Column("str", allowed=PROVENANCE),
    "in_situ_sl_source": Column("str"),
    "pennation_deg": Column("float", min=0.0, max=89.0, description="pennation angle [deg]"),
    "fibre_ratio": Column("float", min=0.001, max=1.0, description="fibre length / musculotendon length [-]"),
    "architecture_kind": Column("str", allowed=PROVENANCE),
    "architecture_source": Column("str"),
    "note": _TEXT_OPT,
})

ANTHROPOMETRY = TableSchema("anthropometry", {
    "segment": Column("str"),
    "body": Column("str", allowed=frozenset({"L1", "L2", "L3", "L4", "L5"})),
    "mass_fraction": Column("float", min=0.0, max=1.0, nullable=True,
                            description="fraction of body mass [-]; empty when mass_kg_fixed is given"),
    "mass_kg_fixed": Column("float", min=0.0, max=100.0, nullable=True,
                            description="segment mass [kg]; empty when mass_fraction is given"),
    "com_rule": Column("str"),
    "mass_kind": Column("str", allowed=PROVENANCE),
    "mass_source": Column("str"),
    "com_kind": Column("str", allowed=PROVENANCE),
    "note": _TEXT_OPT,
})

IN_VIVO_IDP = TableSchema("in_vivo_idp", {
    "activity": Column("str"),
    "idp_mpa": Column("float", min=0.0, max=5.0, description="intradiscal pressure [MPa]"),
    "posture_detail": Column("str", nullable=True),
    "source": Column("str"),
    "kind": Column("str", allowed=PROVENANCE),
    "note": _TEXT_OPT,
})

# ------------------------------------------------------------------ characteristic sets (data/characteristics)
_COMMON = {
    "value": Column("float"),
    "unit": Column("str"),
    "kind": Column("str", allowed=CHARACTERISTIC_KINDS),
    "source": Column("str"),
    "note": Column("str", required=False, nullable=True),
}
DISC = TableSchema("disc", {"parameter": Column("str"), "direction": Column("str"), **_COMMON})
FACET = TableSchema("facet", {"parameter": Column("str"), "side": Column("str"), **_COMMON})
LIGAMENTS_SOFTPLUS = TableSchema("ligaments_softplus", {
    "set": Column("str", allowed=frozenset(SOFTPLUS_SETS)),
    "ligament": Column("str", allowed=frozenset(LIGAMENT_KINDS)),
    "variant": Column("str", allowed=frozenset({"primary", "alternative"})),
    # a, b, c, d of Eq. 7; optional law_length [mm] (the law takes elongation in percent of this length instead of
    # each fibre's own strain) and prestrain [%] (this set's own prestrain, else ligament_prestrain.csv)
    "parameter": Column("str", allowed=frozenset({"a", "b", "c", "d", "law_length", "prestrain"})),
    **_COMMON})
LIGAMENT_PRESTRAIN = TableSchema("ligament_prestrain", {
    "ligament": Column("str", allowed=frozenset(LIGAMENT_KINDS)),
    "prestrain": Column("float", min=-100.0),
    **{k: v for k, v in _COMMON.items() if k != "value"}})
LIGAMENTS_RUPP2015 = TableSchema("ligaments_rupp2015", {
    "ligament": Column("str", allowed=frozenset(LIGAMENT_KINDS)),
    "parameter": Column("str", allowed=frozenset({"l_a", "l_b", "f_a", "f_b", "prestrain", "n_strands"})),
    "value_as_printed": Column("str"),
    **_COMMON})
RUPP2015_SHAPE_CHECK = TableSchema("rupp2015_shape_check", {
    "ligament": Column("str", allowed=frozenset(LIGAMENT_KINDS)),
    "fibre": Column("str"),
    "l0": Column("float", min=0.0), "dU_nll": Column("float", min=0.0), "nu": Column("float", min=0.0),
    "K_nl": Column("float", min=0.0), "K_l": Column("float", min=0.0),
    **{k: v for k, v in _COMMON.items() if k not in ("value", "unit")}})

# ------------------------------------------------------------------ experiments
#: columns of a reference ROM table (stepwise reduction)
STEPWISE_ROM_COLUMNS = ("stage", "direction", "moment_nm", "rom_mean_deg", "rom_min_deg", "rom_max_deg",
                        "n_specimens", "kind", "source")
STEPWISE_ROM = TableSchema("stepwise_reduction_rom", {
    "stage": Column("str", allowed=frozenset(STAGES)),
    "direction": Column("str", allowed=frozenset(MAIN_DIRECTIONS)),
    "moment_nm": Column("float", min=0.0, max=50.0, description="pure moment [N*m]"),
    "rom_mean_deg": Column("float", min=0.0, description="mean range of motion [deg]"),
    "rom_min_deg": Column("float", min=0.0, nullable=True, description="[deg], empty = no range"),
    "rom_max_deg": Column("float", min=0.0, nullable=True, description="[deg], empty = no range"),
    "n_specimens": Column("int", min=1, description="specimens behind the row"),
    "kind": Column("str", allowed=ROM_DATA_KINDS),
    "source": Column("str"),
    "note": Column("str", required=False, nullable=True),
}, unique=UniqueKey(("stage", "direction", "moment_nm"), "scenario", "stage", "one row per (stage, direction, moment_nm)"))
IDP_INVITRO = TableSchema("idp_table", {
    "muscle_setup": Column("str", allowed=frozenset(MUSCLE_SETUPS)),
    "load_case": Column("str", allowed=frozenset(LOAD_CASES)),
    "idp_mean_mpa": Column("float", min=0.0, description="MPa, mean over specimens; a pressure, >= 0"),
    "idp_sd_mpa": Column("float", min=0.0, description="MPa, standard deviation over specimens"),
    "n_specimens": Column("int", min=0),
    "kind": Column("str"),
    "source": Column("str"),
}, unique=UniqueKey(("muscle_setup", "load_case"), "(muscle_setup, load_case)", "load_case", "each scenario once"))
CABLES = TableSchema("wilke1996_cables", {
    "muscle_setup": Column("str", allowed=frozenset(L2S1_MUSCLES)),
    "label": Column("str"),
    "vertebra": Column("str", allowed=frozenset(L2S1_FREE)),
    "attachment_fascicles": Column("str"),
    "direction_fascicles": Column("str"),
    "attachment_rule": Column("str", allowed=frozenset({"mean_site_on_vertebra"})),
    "direction_rule": Column("str", allowed=frozenset({"mean_unit_from_vertebra_site_to_next_site",
                                                       "mean_unit_from_caudal_site_to_cranial_site"})),
    "tension_per_side": Column("float", min=0.0),
    "unit": Column("str", allowed=frozenset({"N"})),
    "kind": Column("str", allowed=frozenset({"derived_from_geometry"})),
    "source": Column("str"),
    "note": Column("str", required=False, nullable=True),
})
NEUTRAL_ANGLE = TableSchema("neutral_angle", {
    "stage": Column("str", allowed=frozenset(STAGES), description="reduction stage; the first row is the reference"),
    "lordosis_deg": Column("float", min=-90.0, max=90.0, description="lordotic angle at 0 N*m [deg]"),
    "lordosis_sd_deg": Column("float", required=False, nullable=True, min=0.0, max=90.0,
                              description="SD of the lordotic angle [deg], > 0; empty = discovery.neutral_sd_deg"),
}, unique=UniqueKey(("stage",), "stage", "stage", "one row per stage"))
IN_VIVO = TableSchema("in_vivo", {
    "activity": Column("str"),
    # no upper bound here: lumbar.inputs.tables.check_measured refuses implausible pressures naming the unit
    "idp_sim_mpa": Column("float", nullable=True, min=0.0,
                          description="simulated IDP [MPa]; empty only where converged is False"),
    "idp_in_vivo_mpa": Column("float", min=0.0, description="in-vivo IDP [MPa]"),
    "converged": Column("str", allowed=frozenset({"True", "False", "true", "false"})),
}, unique=UniqueKey(("activity",), "activity", "activity", "one row per activity"))
#: columns of the muscle model's segment-load table that the discovery reads
SEGMENT_LOAD_COLUMNS = ("level", "activity", "compressive_n", "shear_n", "moment_nm", "converged")


@dataclass(frozen=True)
class MeasuredKind:
    """A table kind the discrepancy discovery reads: its schema, the columns it uses (in that order) and the
    first ``signature`` of them, whose presence identifies the kind."""

    schema: TableSchema
    columns: tuple[str, ...]
    signature: int


#: the experiments of the discrepancy discovery, in detection order
MEASURED = {
    "stepwise_rom": MeasuredKind(STEPWISE_ROM, STEPWISE_ROM_COLUMNS[:7], 3),
    "idp_invitro": MeasuredKind(IDP_INVITRO, ("muscle_setup", "load_case", "idp_mean_mpa", "idp_sd_mpa",
                                              "n_specimens"), 3),
    "in_vivo": MeasuredKind(IN_VIVO, ("activity", "idp_sim_mpa", "idp_in_vivo_mpa", "converged"), 3),
    "neutral_angle": MeasuredKind(NEUTRAL_ANGLE, ("stage", "lordosis_deg"), 2),
}

# ------------------------------------------------------------------ physiological plausibility of measured tables
#: How far beyond the sourced values (:func:`sourced_ranges`) a measured value may lie [-]. Wider than the spread
#: of the sourced values themselves (ROM at 10 N*m 2.2-13.4 deg, a factor 6; in-vivo IDP 0.5-1.8 MPa, a factor
#: 3.6), so no specimen, stage or load case of a real experiment is refused; narrow enough that a value cannot be
#: plausible in two of the units it is confused with (factor^2 = 25 < 57.3 deg per rad < 1000 kPa per MPa).
PLAUSIBILITY_FACTOR = 5.0
#: unit confusions the checks recognise: the table's unit -> {unit the values may be in: factor converting a
#: value in that unit into the table's unit} (definitions of the units, not data)
UNIT_CONFUSIONS = {"deg": {"radians": 180.0 / np.pi},
                   "MPa": {"kPa": 1e-3, "Pa": 1e-6, "bar": 0.1, "psi": 6.894757e-3}}
#: the sourced tables the ranges are read from (relative to the data directory; every row carries its source)
PLAUSIBILITY_SOURCES = {
    "rom_deg_at_10nm": ("experiments/yamamoto1989_intact_rom_original_text.csv",
                        "experiments/heuer2007_disc_only_derived_from_published_fit.csv"),
    "idp_mpa": ("in_vivo/wilke_idp_l4l5.csv",),
    "lordosis_change_deg": ("experiments/heuer2007_va_artefact_original_text.csv",),
}


@dataclass(frozen=True)
class SourcedRange:
    """The smallest and largest sourced value of a quantity, the files they come from, and (for ROM) the largest
    number of specimens behind a sourced row."""

    low: float
    high: float
    files: tuple[str, ...]
    n_max: int | None = None

    def cite(self, unit) -> str:
        return f"sourced {self.low:g}-{self.high:g} {unit} in data/{', data/'.join(self.files)}"


@functools.cache
def sourced_ranges() -> dict[str, SourcedRange]:
    """The sourced values the plausibility ranges are derived from, read (validated) from the data tables of
    :data:`PLAUSIBILITY_SOURCES`:

    * ``rom_deg_at_10nm``: L4-L5 ROM at 10 N*m, intact (Yamamoto et al. 1989, original text) and disc only
      (derived from the published Eq. 3 fit to Heuer et al. 2007): smallest and largest mean;
    * ``idp_mpa``: in-vivo L4-L5 IDP of Wilke et al. (1999, 2001): smallest and largest value;
    * ``lordosis_change_deg``: the published L4-L5 lordotic angles at 0 N*m (paper 1, Sect. 4.2): smallest and
      largest magnitude."""
    d = resources.data_dir()
    files = PLAUSIBILITY_SOURCES
    rom = pd.concat([read_kind(d / f, "stepwise_rom") for f in files["rom_deg_at_10nm"]], ignore_index=True)
    at10 = rom[rom["moment_nm"] == 10.0]
    idp = pd.concat([read_kind(d / f, "in_vivo_idp") for f in files["idp_mpa"]], ignore_index=True)
    lord = pd.concat([read_kind(d / f, "neutral_angle") for f in files["lordosis_change_deg"]], ignore_index=True)
    return {"rom_deg_at_10nm": SourcedRange(float(at10["rom_mean_deg"].min()), float(at10["rom_mean_deg"].max()),
                                            files["rom_deg_at_10nm"], int(rom["n_specimens"].max())),
            "idp_mpa": SourcedRange(float(idp["idp_mpa"].min()), float(idp["idp_mpa"].max()), files["idp_mpa"]),
            "lordosis_change_deg": SourcedRange(float(lord["lordosis_deg"].abs().min()),
                                                float(lord["lordosis_deg"].abs().max()), files["lordosis_change_deg"])}


@dataclass(frozen=True)
class PlausibleRange:
    """Per-row bounds of one measured column (NaN = no bound on that side) and, optionally, the value the column's
    largest magnitude must reach (a table-wide scale check), with the derivation of both."""

    column: str
    unit: str
    lo: np.ndarray
    hi: np.ndarray
    table_min: float | None
    derivation: str


def plausible_ranges(kind: str, df: pd.DataFrame) -> list[PlausibleRange]:
    """The plausibility ranges of the value columns of a measured table of ``kind`` (:data:`MEASURED`), per row.

    From :func:`sourced_ranges` and :data:`PLAUSIBILITY_FACTOR` F:

    * ROM at a moment M [N*m] (mean, and the upper end of min/max): from ``lo10 * min(M, 10) / 10 / F`` to
      ``hi10 * max(M, 10) / 10 * F`` with lo10, hi10 the smallest and largest sourced ROM at 10 N*m. The lower end
      takes the ROM at M < 10 N*m to be about M / 10 of the ROM at 10 N*m or more, as in a segment that stiffens
      with the load (the sourced disc-only curves: 17-37 % at 1 N*m; the least, lateral bending at 7.5 N*m, 0.96 x
      M / 10; ``tests/test_discover_inputs.py`` checks them against half of it), and above 10 N*m at most linear;
    * IDP (in vitro, in vivo, simulated): from 0 (a pressure) to ``high * F`` per row; the table's largest value
      must reach ``low / F`` (the smallest sourced pressure);
    * neutral angle: no per-row bound beyond the schema's; the table's largest magnitude must reach ``low / F``."""
    src = sourced_ranges()
    F = PLAUSIBILITY_FACTOR
    n = len(df)
    nan = np.full(n, np.nan)
    if kind == "stepwise_rom":
        r = src["rom_deg_at_10nm"]
        M = df["moment_nm"].to_numpy(float)
        lo = r.low * np.minimum(M, 10.0) / 10.0 / F
        hi = r.high * np.maximum(M, 10.0) / 10.0 * F
        why = (f"ROM at M N*m from {r.low:g} deg x min(M, 10) / 10 / {F:g} to {r.high:g} deg x max(M, 10) / 10 x "
               f"{F:g}; {r.cite('deg')} at 10 N*m")
        return [PlausibleRange("rom_mean_deg", "deg", lo, hi, None, why),
                PlausibleRange("rom_max_deg", "deg", nan, hi, None, why),
                PlausibleRange("rom_min_deg", "deg", nan, hi, None, why)]
    if kind in ("idp_invitro", "in_vivo"):
        r = src["idp_mpa"]
        why = f"an IDP from 0 to {r.high:g} MPa x {F:g}, the table reaching {r.low:g} MPa / {F:g}; {r.cite('MPa')}"
        cols = ["idp_mean_mpa", "idp_sd_mpa"] if kind == "idp_invitro" else ["idp_in_vivo_mpa", "idp_sim_mpa"]
        return [PlausibleRange(c, "MPa", np.zeros(n) if c != "idp_sd_mpa" else nan, np.full(n, r.high * F),
                               r.low / F if c != "idp_sd_mpa" else None, why) for c in cols]
    if kind == "neutral_angle":
        r = src["lordosis_change_deg"]
        return [PlausibleRange("lordosis_deg", "deg", nan, nan, r.low / F,
                               f"the table's largest magnitude at least {r.low:g} deg / {F:g}; {r.cite('deg')}")]
    raise KeyError(f"no plausibility ranges for table kind {kind!r}; expected one of {sorted(MEASURED)}")


def _unit_hint(v, lo, hi, table_min, unit) -> str:
    """The unit the finite values ``v`` look like: the first confusion that puts every one of them within its
    bounds (and the largest magnitude above ``table_min``), as a phrase; "" when none does."""
    ok = np.isfinite(v)
    for name, f in UNIT_CONFUSIONS.get(unit, {}).items():
        w = v[ok] * f
        inside = ~((w < lo[ok]) | (w > hi[ok]))
        if ok.any() and inside.all() and (table_min is None or np.abs(w).max() >= table_min):
            return (f"the column's values look like {name}, not {unit}: x {f:.6g} puts every one of them in the "
                    f"plausible range")
    return ""


def check_measured(kind: str, df: pd.DataFrame, path) -> list[str]:
    """Refuse a measured table whose values lie outside the physiological ranges of :func:`plausible_ranges`, or
    whose spread contradicts its own mean and specimen count; name the unit the values look like where one fits.

    Raises :class:`lumbar.inputs.io.TableError` (file, 1-based data row, column, expected form) for a value above
    its range, and for a column mostly below it when a unit confusion explains that; returns warnings for what is
    unusual but possible (a few values below the range, e.g. a small noisy ROM at a small moment; more specimens
    than F x the largest sourced study; a table whose largest value stays below the sourced range with no unit
    that explains it), each naming file, row and column."""
    warnings_: list[str] = []
    for rng in plausible_ranges(kind, df):
        if rng.column not in df:
            continue
        v = df[rng.column].to_numpy(float)
        lo = np.where(np.isfinite(rng.lo), rng.lo, -np.inf)
        hi = np.where(np.isfinite(rng.hi), rng.hi, np.inf)
        fin = np.isfinite(v)
        above, below = fin & (v > hi), fin & (v < lo)
        small = rng.table_min is not None and fin.any() and np.nanmax(np.abs(v)) < rng.table_min
        if not (above.any() or below.any() or small):
            continue
        hint = _unit_hint(v, lo, hi, rng.table_min, rng.unit)
        # refused: a value above the range, or most of the column below it with a unit that explains it; a few
        # values below it (a small ROM at a small moment, measured with noise) are possible: flagged
        refuse = above if above.any() else below if (hint and below.sum() >= 0.5 * fin.sum()) else None
        for i in (np.flatnonzero(below) if refuse is None else []):
            at = f" at {df['moment_nm'].iat[i]:g} N*m" if "moment_nm" in df else ""
            warnings_.append(f"{path}, row {i + 1}, column '{rng.column}': {v[i]:g} {rng.unit}{at} is below the "
                             f"plausible range [{lo[i]:.3g}, {hi[i]:.3g}] {rng.unit} ({rng.derivation}); read as given")
        if refuse is not None:
            i = int(np.flatnonzero(refuse)[0])
            at = f" at {df['moment_nm'].iat[i]:g} N*m" if "moment_nm" in df else ""
            where = (f"[{lo[i]:.3g}, {hi[i]:.3g}] {rng.unit}" if np.isfinite(lo[i]) else
                     f"at most {hi[i]:.3g} {rng.unit}")
            raise TableError(path, f"got {v[i]:g} {rng.unit}{at}, outside the plausible range {where}"
                             + (f"; {hint}" if hint else ""), row=i + 1,
                             column=rng.column, expected=f"a value within the plausible range ({rng.derivation})")
        if not small:
            continue
        i = int(np.nanargmax(np.abs(v)))
        text = (f"the largest value of the column is {v[i]:g} {rng.unit}, below {rng.table_min:.3g} {rng.unit}, "
                f"the smallest plausible largest value")
        if hint:
            raise TableError(path, f"{text}; {hint}", row=i + 1, column=rng.column,
                             expected=f"values in {rng.unit} ({rng.derivation})")
        warnings_.append(f"{path}, column '{rng.column}': {text} ({rng.derivation}); check the unit")
    _check_spread(kind, df, path)
    n_max = sourced_ranges()["rom_deg_at_10nm"].n_max
    if "n_specimens" in df and n_max:
        big = np.flatnonzero(df["n_specimens"].to_numpy(float) > PLAUSIBILITY_FACTOR * n_max)
        if len(big):
            warnings_.append(f"{path}, row {big[0] + 1}, column 'n_specimens': {df['n_specimens'].iat[big[0]]:g} "
                             f"specimens, more than {PLAUSIBILITY_FACTOR:g} x the largest sourced in-vitro study "
                             f"({n_max}, {', '.join(PLAUSIBILITY_SOURCES['rom_deg_at_10nm'])}); the uncertainty of "
                             f"the mean shrinks with it: check the count")
    return warnings_


def _check_spread(kind, df, path):
    """A row's spread must be possible for its specimens: one specimen has no range and no SD; the SD of n values
    >= 0 with mean m is at most m * sqrt(n); a row without specimens has no mean."""
    if kind == "stepwise_rom":
        n, lo, hi = (df[c].to_numpy(float) for c in ("n_specimens", "rom_min_deg", "rom_max_deg"))
        bad = np.flatnonzero((n == 1) & np.isfinite(lo) & (hi > lo))
        if len(bad):
            i = int(bad[0])
            raise TableError(path, f"a range {lo[i]:g}-{hi[i]:g} deg from one specimen", row=i + 1,
                             column="n_specimens", expected="n_specimens >= 2 for a range (or rom_min_deg = "
                                                            "rom_max_deg, or both empty)")
    if kind == "idp_invitro":
        n, m, sd = (df[c].to_numpy(float) for c in ("n_specimens", "idp_mean_mpa", "idp_sd_mpa"))
        for i in range(len(df)):
            if n[i] == 0:
                raise TableError(path, "no specimen behind the mean", row=i + 1, column="n_specimens",
                                 expected="n_specimens >= 1 (leave a row without specimens out)")
            if n[i] == 1 and sd[i] > 0:
                raise TableError(path, f"an SD of {sd[i]:g} MPa from one specimen", row=i + 1, column="idp_sd_mpa",
                                 expected="0 or n_specimens >= 2")
            if sd[i] > m[i] * np.sqrt(n[i]) * (1 + 1e-9) + 1e-12:
                hint = [k for k, f in UNIT_CONFUSIONS["MPa"].items() if sd[i] * f <= m[i] * np.sqrt(n[i])]
                raise TableError(path, f"SD {sd[i]:g} MPa is larger than {n[i]:g} pressures >= 0 with mean "
                                       f"{m[i]:g} MPa can have (at most mean x sqrt(n) = {m[i] * np.sqrt(n[i]):.3g})"
                                 + (f"; the SD looks like it is in {hint[0]}, not MPa" if hint else ""),
                                 row=i + 1, column="idp_sd_mpa", expected="the SD over the specimens in MPa")

#: a user's multi-label CT volume (lumbar.geometry.specimen_io.label_volume_to_meshes): which voxel value is which
#: vertebra; ``label`` names the level (a token L1..L5, S1 or sacrum, e.g. "L4", "vertebrae_L4", "sacrum")
LABEL_TABLE = TableSchema("label_table", {
    "label": Column("str", description="a vertebra: L1..L5, S1 or sacrum (e.g. 'L4' or 'vertebrae_L4')"),
    "value": Column("int", min=1, description="the voxel value of that vertebra in the label volume"),
}, unique=UniqueKey(("label",), "label", "label", "one row per vertebra"))

# ------------------------------------------------------------------ registry
#: kind -> schema
TABLE_KINDS = {
    "disc": DISC,
    "facet": FACET,
    "ligaments_softplus": LIGAMENTS_SOFTPLUS,
    "ligament_prestrain": LIGAMENT_PRESTRAIN,
    "ligaments_rupp2015": LIGAMENTS_RUPP2015,
    "rupp2015_shape_check": RUPP2015_SHAPE_CHECK,
    "stepwise_rom": STEPWISE_ROM,
    "idp_invitro": IDP_INVITRO,
    "cables": CABLES,
    "landmarks": LANDMARKS,
    "muscle_groups": MUSCLE_GROUPS,
    "anthropometry": ANTHROPOMETRY,
    "in_vivo_idp": IN_VIVO_IDP,
    "neutral_angle": NEUTRAL_ANGLE,
    "in_vivo": IN_VIVO,
    "label_table": LABEL_TABLE,
}

#: the repository's data tables (relative to the repository root) and their kinds
DATA_FILES = {
    "data/characteristics/disc.csv": "disc",
    "data/characteristics/facet.csv": "facet",
    "data/characteristics/ligaments_softplus.csv": "ligaments_softplus",
    "data/characteristics/ligament_prestrain.csv": "ligament_prestrain",
    "data/characteristics/ligaments_rupp2015.csv": "ligaments_rupp2015",
    "data/characteristics/rupp2015_shape_check.csv": "rupp2015_shape_check",
    "data/experiments/heuer2007_disc_only_derived_from_published_fit.csv": "stepwise_rom",
    "data/cables/wilke1996_cables.csv": "cables",
    "data/landmarks/myo_sim_landmarks.csv": "landmarks",
    "data/muscles/muscle_groups.csv": "muscle_groups",
    "data/anthropometry/upper_body_segments.csv": "anthropometry",
    "data/paper2/paper2_upper_body_third_party.csv": "anthropometry",
    "data/in_vivo/wilke_idp_l4l5.csv": "in_vivo_idp",
    "data/in_vivo/wilke1999_idp_lying_original_text.csv": "in_vivo_idp",
}


def schema_of(kind: str) -> TableSchema:
    if kind not in TABLE_KINDS:
        raise KeyError(f"unknown table kind {kind!r}; expected one of {sorted(TABLE_KINDS)}")
    return TABLE_KINDS[kind]


def read_kind(path, kind: str) -> pd.DataFrame:
    """Read ``path`` validated against the schema of ``kind`` (raises :class:`lumbar.inputs.io.TableError`)."""
    return read_table(Path(path), schema_of(kind))


# ------------------------------------------------------------------ outlier counts beside the paper's
#: the one column vocabulary of ``table4_vs_paper.csv`` and ``table5_vs_paper.csv``: our outlier counts
#: (``n_outliers`` of ``n_scenarios``; ``*_real``: among the rows with a real reference), the paper's
#: (``paper_n_outliers`` of ``paper_n_scenarios``, empty when unknown), its source and the difference
VS_PAPER_COLUMNS = ("set", "n_scenarios", "n_outliers", "data_kind", "n_scenarios_real", "n_outliers_real",
                    "paper_n_outliers", "paper_n_scenarios", "paper_source", "difference")
#: the outlier-count tables' own names (table4/table5_outlier_counts.csv, kept) -> this vocabulary
OUTLIER_COUNT_NAMES = {"outliers": "n_outliers", "scenarios": "n_scenarios", "data_kinds": "data_kind"}


def versus_paper(counts: pd.DataFrame, published_csv, keys: dict, paper_n_scenarios=None) -> pd.DataFrame:
    """Outlier counts beside the paper's, in :data:`VS_PAPER_COLUMNS`.

    ``counts``: one row per characteristic set with ``set``, ``n_scenarios``, ``n_outliers`` and optionally
    ``data_kind``, ``n_scenarios_real``, ``n_outliers_real`` (or their :data:`OUTLIER_COUNT_NAMES`); ``keys``: set -> ``quantity`` of its count in
    ``published_csv`` (columns quantity, value, source); ``paper_n_scenarios``: the paper's number of scenarios
    (None: not known). The paper's columns stay empty when the file is absent (logged)."""
    counts = counts.rename(columns=OUTLIER_COUNT_NAMES)
    out = pd.DataFrame({c: counts[c] if c in counts.columns else np.nan for c in VS_PAPER_COLUMNS[:6]})
    out["data_kind"] = counts["data_kind"] if "data_kind" in counts.columns else ""
    out["paper_n_outliers"] = np.nan
    out["paper_n_scenarios"] = np.nan if paper_n_scenarios is None else paper_n_scenarios
    out["paper_source"] = ""
    if published_csv is not None and Path(published_csv).is_file():
        pub = pd.read_csv(published_csv).set_index("quantity")
        for i, s in out["set"].items():
            k = keys.get(s)
            if k in pub.index:
                out.at[i, "paper_n_outliers"] = float(pub.at[k, "value"])
                out.at[i, "paper_source"] = str(pub.at[k, "source"])
    else:
        log.warning("published model results %s not found: paper_n_outliers left empty", published_csv)
    out["difference"] = out["n_outliers"] - out["paper_n_outliers"]
    return out[list(VS_PAPER_COLUMNS)]
