"""Discovery settings and reading a measured table: the experiment is recognised from its columns
(:data:`lumbar.inputs.tables.MEASURED`) and the table validated against its schema before any computation."""
from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs.config import schema_defaults
from ..inputs.io import TableError, read_table
from ..experiments.stepwise_reduction import read_experiment_table
from ..inputs.tables import MEASURED, check_measured

log = logging.getLogger(__name__)

#: discovery settings that are not configuration keys; every other setting and its default is owned by the
#: ``discovery`` section of the configuration schema (:func:`lumbar.inputs.config.schema_defaults`)
INTERNAL_SETTINGS = dict(seed=0, fine_candidates=0,
                         # the metric of the tests with a specimen bank: "specimen_correlation" (residuals decorrelated
                         # by the specimens' correlation) or "independent" rows; LR statistics normalised by the
                         # overdispersion of the null model (always without a bank) or raw (with one)
                         test_metric="specimen_correlation", lr_normalise=False)


class DiscoveryInputError(ValueError):
    """A measured file that cannot be used (message names file, column and the expected form)."""


# ------------------------------------------------------------------ configuration
def default_settings() -> dict:
    """The discovery settings of an empty configuration: the schema's ``discovery`` defaults (without the
    benchmark section) and :data:`INTERNAL_SETTINGS`."""
    s = schema_defaults("discovery")
    s.pop("benchmark", None)
    return s | INTERNAL_SETTINGS


def discovery_settings(config: dict | None) -> dict:
    s = default_settings()
    s.update({k: v for k, v in ((config or {}).get("discovery") or {}).items() if k != "benchmark"})
    s["seed"] = int((config or {}).get("seed", 0))
    return s


def benchmark_settings(config) -> dict:
    """The ``discovery.benchmark`` settings: the schema's defaults updated by ``config``."""
    b = schema_defaults("discovery", "benchmark")
    b.update(((config or {}).get("discovery") or {}).get("benchmark") or {})
    return b


# ------------------------------------------------------------------ reading and schema detection
def detect_experiment(columns, path="<table>") -> str:
    """The experiment of a table with ``columns`` (:data:`lumbar.inputs.tables.MEASURED`, in its order: the first one
    whose signature columns are all present; then every column it uses must be)."""
    cols = set(columns)
    for name, kind in MEASURED.items():
        if set(kind.columns[: kind.signature]) <= cols:
            missing = [c for c in kind.columns if c not in cols]
            if missing:
                raise DiscoveryInputError(
                    f"{path}: looks like a {name} table but column(s) {missing} are missing; "
                    f"expected columns {list(kind.columns)}")
            return name
    forms = "; ".join(f"{k}: {list(v.columns)}" for k, v in MEASURED.items())
    raise DiscoveryInputError(f"{path}: columns {sorted(cols)} match no experiment schema; expected one of {forms}")


def _check_ragged(p):
    """Every data row has as many fields as the header (pandas pads short rows silently)."""
    with open(p, newline="", encoding="utf-8", errors="replace") as f:
        rows = list(csv.reader(f))
    if not rows:
        return
    head = rows[0]
    for i, r in enumerate(rows[1:], 1):
        if r and len(r) != len(head):
            col = head[len(r)] if len(r) < len(head) else None
            where = f"row {i}" + (f", column '{col}'" if col else "")
            raise DiscoveryInputError(f"{p}, {where}: {len(r)} field(s) but the header has {len(head)}; expected one "
                                      f"value per header column {head} (a ragged row)")


def read_measured(path) -> tuple[str, pd.DataFrame]:
    """(experiment, validated table) of a measured/surrogate/fixture file; DiscoveryInputError if unusable.

    Every schema goes through :func:`lumbar.inputs.io.read_table`: a bad cell names the file, the 1-based data row, the
    column and the expected form; ragged rows and repeated scenarios are rejected. Then
    :func:`lumbar.inputs.tables.check_measured` refuses values outside the sourced physiological ranges (naming the
    unit they look like: radians, kPa, ...) and spreads a row's specimens cannot have; what is unusual but possible
    is logged as a warning and kept in ``table.attrs["input_warnings"]`` (and in the discovery's result)."""
    p = Path(path)
    if not p.is_file():
        raise DiscoveryInputError(f"measured file not found: {p}")
    _check_ragged(p)
    try:
        head = pd.read_csv(p, nrows=5)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as e:
        raise DiscoveryInputError(f"{p}: not a readable CSV table ({type(e).__name__}); expected a CSV file with a "
                                  f"header row") from e
    exp = detect_experiment(head.columns, p)
    try:
        if exp == "stepwise_rom":
            df = read_experiment_table(p)
        else:
            df = read_table(p, MEASURED[exp].schema)
    except TableError as e:
        raise DiscoveryInputError(str(e)) from e
    if len(df) == 0:
        raise DiscoveryInputError(f"{p}: no data rows; expected one row per scenario")
    if exp == "neutral_angle" and "lordosis_sd_deg" in df:
        sd = df["lordosis_sd_deg"].to_numpy(float)
        bad = np.flatnonzero(sd == 0)
        if len(bad):
            raise DiscoveryInputError(f"{p}, row {bad[0] + 1}, column 'lordosis_sd_deg': got 0, a zero uncertainty; "
                                      f"expected a finite number > 0 [deg] (or empty for discovery.neutral_sd_deg)")
    if exp == "in_vivo":
        df["converged"] = df["converged"].str.lower() == "true"
        bad = np.flatnonzero(df["converged"].to_numpy(bool) & ~np.isfinite(df["idp_sim_mpa"].to_numpy(float)))
        if len(bad):
            raise DiscoveryInputError(f"{p}, row {bad[0] + 1}, column 'idp_sim_mpa': empty on a converged row; "
                                      f"expected a finite number >= 0 (empty only where converged is False)")
    if exp == "neutral_angle" and len(df) < 2:
        raise DiscoveryInputError(f"{p}: a neutral-angle table needs >= 2 stages (the first is the reference); "
                                  f"got {len(df)}")
    try:
        warns = check_measured(exp, df, p)
    except TableError as e:
        raise DiscoveryInputError(str(e)) from e
    for w in warns:
        log.warning("%s", w)
    df.attrs["input_warnings"] = warns
    return exp, df
