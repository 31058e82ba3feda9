"""Schemas of the hand-curated input tables, one per table kind, and ``read_kind`` to read one validated.

Every kind of table under ``data/`` (and every user table the config can point to) has a
:class:`lumbar.io.TableSchema`; reading goes through :func:`lumbar.io.read_table`, whose
:class:`lumbar.io.TableError` names the file, the 1-based data row and the column, and states the expected
form. Schemas of kinds that belong to one stage live in that stage's module and are registered here
(imported lazily, so this module stays light):

==================  ==================================================  =======================================
kind                files                                               schema
==================  ==================================================  =======================================
disc, facet, ...    data/characteristics/*.csv                          lumbar.characteristics.*_SCHEMA
stepwise_rom        data/experiments/heuer2007_*.csv, measured tables   lumbar.stepwise_reduction.EXPERIMENT_SCHEMA
idp_invitro         l2s1.measured_table (Wilke et al. 1996 layout)      lumbar.l2s1.IDP_TABLE_SCHEMA
cables              data/cables/wilke1996_cables.csv                    lumbar.l2s1.CABLE_SCHEMA
landmarks           data/landmarks/myo_sim_landmarks.csv                LANDMARKS (here)
muscle_groups       data/muscles/muscle_groups.csv                      MUSCLE_GROUPS (here)
anthropometry       data/anthropometry/upper_body_segments.csv          ANTHROPOMETRY (here)
in_vivo_idp         data/in_vivo/wilke_idp_l4l5.csv                     IN_VIVO_IDP (here)
==================  ==================================================  =======================================
"""
from __future__ import annotations

import importlib
from pathlib import Path

import pandas as pd

from .io import Column, TableSchema, read_table

__all__ = ["LANDMARKS", "MUSCLE_GROUPS", "ANTHROPOMETRY", "IN_VIVO_IDP", "TABLE_KINDS", "schema_of",
           "read_kind", "DATA_FILES"]

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

# kind -> (module, attribute) of its schema
TABLE_KINDS = {
    "disc": ("lumbar.characteristics", "DISC_SCHEMA"),
    "facet": ("lumbar.characteristics", "FACET_SCHEMA"),
    "ligaments_softplus": ("lumbar.characteristics", "SOFTPLUS_SCHEMA"),
    "ligament_prestrain": ("lumbar.characteristics", "PRESTRAIN_SCHEMA"),
    "ligaments_rupp2015": ("lumbar.characteristics", "RUPP_SCHEMA"),
    "rupp2015_shape_check": ("lumbar.characteristics", "SHAPE_CHECK_SCHEMA"),
    "stepwise_rom": ("lumbar.stepwise_reduction", "EXPERIMENT_SCHEMA"),
    "idp_invitro": ("lumbar.l2s1", "IDP_TABLE_SCHEMA"),
    "cables": ("lumbar.l2s1", "CABLE_SCHEMA"),
    "landmarks": ("lumbar.tables", "LANDMARKS"),
    "muscle_groups": ("lumbar.tables", "MUSCLE_GROUPS"),
    "anthropometry": ("lumbar.tables", "ANTHROPOMETRY"),
    "in_vivo_idp": ("lumbar.tables", "IN_VIVO_IDP"),
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
    module, attr = TABLE_KINDS[kind]
    return getattr(importlib.import_module(module), attr)


def read_kind(path, kind: str) -> pd.DataFrame:
    """Read ``path`` validated against the schema of ``kind`` (raises :class:`lumbar.io.TableError`)."""
    return read_table(Path(path), schema_of(kind))
