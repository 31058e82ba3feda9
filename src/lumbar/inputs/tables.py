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
in_vivo_idp           data/in_vivo/wilke_idp_l4l5.csv                   IN_VIVO_IDP
neutral_angle         data/experiments/heuer2007_va_artefact_*.csv      NEUTRAL_ANGLE (discovery)
in_vivo               results/tables/in_vivo_validation.csv             IN_VIVO (discovery)
====================  ================================================  =====================================

:data:`MEASURED` says which of them the discrepancy discovery reads and by which columns it recognises each;
:data:`VS_PAPER_COLUMNS` is the one column vocabulary of the outlier counts beside the paper's
(``table4_vs_paper.csv``, ``table5_vs_paper.csv``; :func:`versus_paper`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .io import Column, TableSchema, read_table

__all__ = ["LANDMARKS", "MUSCLE_GROUPS", "ANTHROPOMETRY", "IN_VIVO_IDP", "DISC", "FACET", "LIGAMENTS_SOFTPLUS",
           "LIGAMENT_PRESTRAIN", "LIGAMENTS_RUPP2015", "RUPP2015_SHAPE_CHECK", "STEPWISE_ROM", "IDP_INVITRO",
           "CABLES", "NEUTRAL_ANGLE", "IN_VIVO", "TABLE_KINDS", "schema_of", "read_kind", "DATA_FILES", "MEASURED",
           "MeasuredKind", "VS_PAPER_COLUMNS", "OUTLIER_COUNT_NAMES", "versus_paper"]

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
                                  # (results/calibration/characteristics)
                                  "calibrated_on_surrogate", "calibrated_on_measured"})
#: reduction stages of the stepwise-reduction experiment (Heuer et al. 2007), in removal order
STAGES = ("intact", "wo_ssl", "wo_isl", "wo_fl", "wo_cl", "wo_va", "wo_pll", "wo_all")
#: the four loading directions of the stepwise-reduction tables
MAIN_DIRECTIONS = ("flexion", "extension", "lateral_bending", "axial_rotation")
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
    "rom_min_deg": Column("float", min=0.0, nullable=True, finite=False, description="[deg], empty = no range"),
    "rom_max_deg": Column("float", min=0.0, nullable=True, finite=False, description="[deg], empty = no range"),
    "n_specimens": Column("int", min=1, description="specimens behind the row"),
    "kind": Column("str", allowed=ROM_DATA_KINDS),
    "source": Column("str"),
    "note": Column("str", required=False, nullable=True),
})
IDP_INVITRO = TableSchema("idp_table", {
    "muscle_setup": Column("str", allowed=frozenset(MUSCLE_SETUPS)),
    "load_case": Column("str", allowed=frozenset(LOAD_CASES)),
    "idp_mean_mpa": Column("float"),
    "idp_sd_mpa": Column("float", min=0.0, description="MPa, standard deviation over specimens"),
    "n_specimens": Column("int", min=0),
    "kind": Column("str"),
    "source": Column("str"),
})
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
})
IN_VIVO = TableSchema("in_vivo", {
    "activity": Column("str"),
    "idp_sim_mpa": Column("float", nullable=True, min=0.0, max=100.0,
                          description="simulated IDP [MPa]; empty only where converged is False"),
    "idp_in_vivo_mpa": Column("float", min=0.0, max=100.0, description="in-vivo IDP [MPa]"),
    "converged": Column("str", allowed=frozenset({"True", "False", "true", "false"})),
})
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
    "data/in_vivo/wilke_idp_l4l5.csv": "in_vivo_idp",
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
