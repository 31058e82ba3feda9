"""Discovery problems: measured data, their uncertainty and a batched forward model per experiment
(stepwise-reduction ROM, neutral angle, in-vitro IDP, in-vivo IDP)."""
from __future__ import annotations

import functools
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from ..experiments import effects as fx
from ..inputs.characteristics import resolve_characteristic_set
from ..experiments.fsu import MAIN_DIRECTIONS, STAGES, build_fsu, unit_options, unit_stiffness
from ..geometry.configured import load_configured
from ..mechanics.idp import DISC_AREA_M2, idp_per_newton
from ..experiments.l2s1 import LEVELS, derive_cables, run_set
from ..experiments.stepwise_reduction import scenario_grid
from ..inputs.tables import SEGMENT_LOAD_COLUMNS
from .detect import DiscoveryInputError, benchmark_settings, discovery_settings
from .specimens import D2, bank_for, d2

log = logging.getLogger(__name__)




# ------------------------------------------------------------------ problems (measured data + batched forward model)
@dataclass
class Problem:
    experiment: str
    keys: pd.DataFrame                       # scenario labels
    y: np.ndarray                            # measured (physical unit)
    sigma: np.ndarray                        # uncertainty of the measured value
    unit: str
    forward: Callable                        # forward({effect: (G,)}) -> (G, n) predictions (one batch)
    candidates: list
    row_key: str
    col_keys: list
    folds: np.ndarray                        # CV fold per scenario
    meta: dict = field(default_factory=dict)

    @property
    def n(self):
        return len(self.y)


def _rom_sigma(df, s):
    n = df["n_specimens"].to_numpy(int)
    lo, hi = df["rom_min_deg"].to_numpy(float), df["rom_max_deg"].to_numpy(float)
    d2 = np.array([D2.get(int(k), 3.078 if k > 10 else np.nan) for k in n])
    sd = (hi - lo) / d2
    sig = np.where(np.isfinite(sd) & (n > 1), sd / np.sqrt(np.maximum(n, 1)), s["no_range_sd_deg"])
    return np.maximum(sig, s["sigma_floor_deg"])


@functools.lru_cache(maxsize=4)
def _fsu_variants(geometry, level, set_name, data_dir, facet_k, k_shear, calibrated_dir=None):
    geo = load_configured(dict(geometry), levels=[level])
    cs = resolve_charset(set_name, data_dir, calibrated_dir)
    return fx.FsuVariants(build_fsu(geo, cs, level, facet_stiffness_n_per_m=facet_k,
                                    disc_shear_stiffness_n_per_m=k_shear))


def fsu_variants_from_config(config):
    g, f = config.get("geometry", {}), config.get("fsu", {})
    s = discovery_settings(config)
    return _fsu_variants(tuple(sorted({"kind": "default", **g}.items())), f.get("level", "L4-L5"), s["characteristic_set"],
                         (config.get("characteristics") or {}).get("data_dir"), *unit_options(f).values(),
                         (config.get("characteristics") or {}).get("calibrated_dir"))


def resolve_charset(name, data_dir, calibrated_dir):
    """The one resolver (lumbar.inputs.characteristics.resolve_characteristic_set): "calibrated" from the workflow's
    calibration output when it exists, else the published tables (logged: then the comparison is with paper 1's
    Table 3 set, not with a calibrated unit)."""
    if name == "calibrated" and not (calibrated_dir is not None and (Path(calibrated_dir) / "disc.csv").is_file()):
        log.warning("discovery: characteristic set 'calibrated' has no calibration output (characteristics."
                    "calibrated_dir = %s): comparing with the published Table 3 set of %s", calibrated_dir, data_dir)
    return resolve_characteristic_set(name, data_dir=data_dir, calibrated_dir=calibrated_dir)


def nominal_model_label(config) -> str:
    """Which nominal model a discovery compares with: the characteristic set and the folder it is read from
    (scenarios.csv column ``nominal_model``)."""
    c = (config or {}).get("characteristics") or {}
    name = discovery_settings(config)["characteristic_set"]
    cs = resolve_charset(name, c.get("data_dir"), c.get("calibrated_dir"))
    f = (config or {}).get("fsu") or {}
    k_f, k_s = unit_stiffness(cs, f)
    return (f"set {name} from {Path(cs.source).parent} (facet stiffness {k_f:.4g} N/m, disc shear stiffness "
            f"{k_s:.4g} N/m)")


def _grouped_folds(labels, k):
    cats = list(dict.fromkeys(labels))
    idx = {c: i % max(1, min(k, len(cats))) for i, c in enumerate(cats)}
    return np.array([idx[c] for c in labels])


def _candidates(s, experiment):
    names = fx.effect_names(experiment)
    if s.get("effects"):
        names = [n for n in s["effects"] if n in names]
    return names


def rom_problem(df, config, solver_kw=None, bank=None) -> Problem:
    s = discovery_settings(config)
    fv = fsu_variants_from_config(config)
    keys = df[["stage", "direction", "moment_nm"]].reset_index(drop=True)
    kw = solver_kw or {}

    def forward(values):
        rom, conv, _, _ = fv.simulate(keys, values, **kw)
        return np.where(conv, rom, np.nan)

    cells = [f"{a}/{b}" for a, b in zip(keys["stage"], keys["direction"])]
    d0 = df.reset_index(drop=True)
    has_range = (np.isfinite(d0["rom_max_deg"].to_numpy(float) - d0["rom_min_deg"].to_numpy(float))
                 & (d0["n_specimens"].to_numpy(int) > 1))
    moments = sorted(set(map(float, keys["moment_nm"])) | set(map(float, benchmark_settings(config)["moments_nm"])))
    design = scenario_grid(STAGES, MAIN_DIRECTIONS, moments).reset_index(drop=True)

    def design_forward(values):
        rom, conv, _, _ = fv.simulate(design, values, **kw)
        return np.where(conv, rom, np.nan)

    n = d0["n_specimens"].to_numpy(int)
    with np.errstate(invalid="ignore"):
        spec_sd = np.where(has_range, (d0["rom_max_deg"].to_numpy(float) - d0["rom_min_deg"].to_numpy(float))
                           / d2(np.maximum(n, 2)), np.nan)
    model_sd = model_band_sd(keys, s.get("model_bands"))
    sigma = np.hypot(_rom_sigma(d0, s), np.nan_to_num(model_sd))
    return Problem("stepwise_rom", keys, d0["rom_mean_deg"].to_numpy(float), sigma,
                   "deg", forward, _candidates(s, "stepwise_rom"), "stage", ["direction", "moment_nm"],
                   _grouped_folds(cells, s["cv_folds"]),
                   meta={"quantity": "range of motion at the row's moment [deg]",
                         "nominal_model": nominal_model_label(config),
                         "n_per_row": n, "has_range": has_range, "spec_sd": spec_sd,
                         "sigma_floor": float(s["sigma_floor_deg"]), "groups": keys["direction"].to_numpy(str),
                         "model_sd": model_sd,
                         "bank": _bank("stepwise_rom", keys, config, s, bank),
                         "design_keys": design, "design_forward": design_forward})


def model_band_sd(keys: pd.DataFrame, path) -> np.ndarray:
    """The nominal model's own posterior spread [deg] at each scenario of ``keys`` (stage, direction, moment_nm), from
    the calibration's band table (role stepwise_reduction.bands of the stage manifests; setting
    ``discovery.model_bands``, set by the workflow for the calibrated set): the width of the row's 90 % band over
    2 x 1.645, i.e. the band the report shows (the posterior draws' where the linearisation failed its check), the
    linearised ``sd`` for a table without band ends. Part of a row's spread, added in quadrature to the
    measurement's. Zeros without a table (a set without a posterior); NaN-free."""
    from ..experiments.posterior import Z90  # noqa: PLC0415 - one definition of the 90 % quantile

    if not path:
        return np.zeros(len(keys))
    b = pd.read_csv(path)
    if b.empty:
        return np.zeros(len(keys))
    k = keys.assign(moment_nm=keys["moment_nm"].astype(float))
    if {"low90", "high90"} <= set(b.columns):
        b = b.assign(sd=(b["high90"].astype(float) - b["low90"].astype(float)) / (2.0 * Z90))
    b = b.assign(moment_nm=b["moment_nm"].astype(float))[["stage", "direction", "moment_nm", "sd"]]
    sd = k.merge(b, on=["stage", "direction", "moment_nm"], how="left")["sd"].to_numpy(float)
    return np.nan_to_num(sd)


def _bank(experiment, keys, config, s, bank=None):
    """The null bank of the problem: ``bank`` (a :class:`lumbar.discovery.specimens.SpecimenBank` covering the
    table's scenarios) when given, else ``discovery.null_specimens`` virtual specimens; None when that is 0."""
    if bank is not None:
        a = bank.align(keys)
        if a is None:
            raise ValueError(f"the given specimen bank does not cover every scenario of the {experiment} table")
        return a
    K = int(s["null_specimens"])
    return bank_for(experiment, keys, config, K) if K > 0 else None


#: what a neutral-angle row compares (scenarios.csv column ``quantity``)
NEUTRAL_QUANTITY = ("change of the lordotic angle at 0 N*m from reference_stage to stage [deg]. The nominal model has "
                    "no vertebral-arch artefact: its change comes only from the structures the step removes that "
                    "carry load at rest (facet contact, prestrained ligaments) and is 0 where none does; the "
                    "measured change includes the artefact")


def neutral_problem(df, config) -> Problem:
    s = discovery_settings(config)
    fv = fsu_variants_from_config(config)
    stages = list(df["stage"])
    y = df["lordosis_deg"].to_numpy(float)
    sd = df["lordosis_sd_deg"].to_numpy(float) if "lordosis_sd_deg" in df else np.full(len(df), np.nan)
    sd = np.where(np.isfinite(sd), sd, s["neutral_sd_deg"])
    # the first stage is the reference: changes relative to it are compared (the model has no absolute
    # lordosis of the specimens); sigma of a difference of two independent values
    ref_sd = sd[0]

    def forward(values):
        lord, conv = fv.neutral_lordosis(stages, values)
        d = lord[:, 1:] - lord[:, :1]
        return np.where(conv[:, 1:] & conv[:, :1], d, np.nan)

    keys = pd.DataFrame({"stage": stages[1:], "reference_stage": stages[0]})
    dstages = [stages[0]] + [x for x in STAGES if x != stages[0]]

    def design_forward(values):
        lord, conv = fv.neutral_lordosis(dstages, values)
        d = lord[:, 1:] - lord[:, :1]
        return np.where(conv[:, 1:] & conv[:, :1], d, np.nan)

    return Problem("neutral_angle", keys, y[1:] - y[0], np.hypot(sd[1:], ref_sd), "deg", forward,
                   _candidates(s, "neutral_angle"), "reference_stage", ["stage"], np.arange(len(stages) - 1),
                   meta={"quantity": NEUTRAL_QUANTITY, "nominal_model": nominal_model_label(config),
                         "design_keys": pd.DataFrame({"stage": dstages[1:], "reference_stage": stages[0]}),
                         "design_forward": design_forward})


_IDP_MODEL_CACHE: dict = {}


def idp_model_table(config):
    """Internal loads + IDP of the nominal L2-S1 model (49 scenarios): the configured file, else solved once per
    process and configuration (cached: the nominal solve dominates an IDP discovery's time)."""
    s = discovery_settings(config)
    p = s.get("idp_model_table")
    if p and Path(p).is_file():
        return pd.read_csv(p)
    key = json.dumps({k: (config or {}).get(k) for k in ("geometry", "characteristics", "fsu", "l2s1")}
                     | {"set": s["characteristic_set"]}, sort_keys=True, default=str)
    if key not in _IDP_MODEL_CACHE:
        _IDP_MODEL_CACHE[key] = solve_idp_model(config)
    return _IDP_MODEL_CACHE[key].copy()


def solve_idp_model(config):
    s = discovery_settings(config)
    g, l2 = config.get("geometry", {}), config.get("l2s1", {})
    geo = load_configured({"kind": "default", **g}, levels=list(LEVELS))
    data_dir = (config.get("characteristics") or {}).get("data_dir")
    cs = resolve_charset(s["characteristic_set"], data_dir, (config.get("characteristics") or {}).get("calibrated_dir"))
    sim, _ = run_set(geo, cs, derive_cables(l2.get("cables")), idp_formula=l2.get("idp_formula", "paper1"),
                     **unit_options(config),
                     moment_nm=l2.get("moment_nm", 3.75))
    sim["idp_per_newton_pa"] = idp_per_newton(l2.get("idp_formula", "paper1"), geo.levels["L4-L5"].disc_csa,
                                               l2.get("disc_area_m2", DISC_AREA_M2))
    return sim


def idp_problem(df, config, model=None, bank=None) -> Problem:
    s = discovery_settings(config)
    model = idp_model_table(config) if model is None else model
    d = df.reset_index(drop=True).merge(model, on=["muscle_setup", "load_case"], how="left", validate="one_to_one")
    miss = d["idp_mpa"].isna() & ~d["disc_axial_force_n"].isna()
    base = d["idp_mpa"].to_numpy(float) * 1e6
    M = d["disc_moment_sagittal_nm"].to_numpy(float)
    per_n = float(np.nanmedian(d["idp_per_newton_pa"])) if "idp_per_newton_pa" in d else float(
        np.nanmedian(base / d["disc_axial_force_n"].to_numpy(float)))
    if miss.any():
        log.warning("%d scenario(s) without model equilibrium", int(miss.sum()))

    def forward(values):
        return idp_forward(values, base, M, per_n) / 1e6

    n = d["n_specimens"].to_numpy(float)
    sig = np.maximum(d["idp_sd_mpa"].to_numpy(float) / np.sqrt(np.maximum(n, 1)), s["sigma_floor_mpa"])
    mk = model[np.isfinite(model["idp_mpa"].to_numpy(float))].reset_index(drop=True)
    dbase, dM = mk["idp_mpa"].to_numpy(float) * 1e6, mk["disc_moment_sagittal_nm"].to_numpy(float)

    def design_forward(values):
        return idp_forward(values, dbase, dM, per_n) / 1e6

    keys = d[["muscle_setup", "load_case"]]
    return Problem("idp_invitro", keys, d["idp_mean_mpa"].to_numpy(float), sig, "MPa",
                   forward, _candidates(s, "idp_invitro"), "muscle_setup", ["load_case"],
                   _grouped_folds(list(d["muscle_setup"]), s["cv_folds"]),
                   meta={"idp_per_newton_pa": per_n, "n_per_row": n.astype(int), "has_range": n > 1,
                         "spec_sd": np.where(n > 1, d["idp_sd_mpa"].to_numpy(float), np.nan),
                         "sigma_floor": float(s["sigma_floor_mpa"]), "bank": _bank("idp_invitro", keys, config, s, bank),
                         "design_keys": mk[["muscle_setup", "load_case"]], "design_forward": design_forward})


def idp_forward(values, base, M, per_n):
    G = len(next(iter(values.values()))) if values else 1
    out = np.broadcast_to(base, (G, len(base))).copy()
    for name, v in values.items():
        v = np.asarray(v, float)[:, None]
        # effects act one at a time per variant row (the others are 0 there), so applying them in turn is exact
        out = fx.idp_delta(name, v, out, M[None, :], per_n)
    return out


def read_segment_loads(path, level):
    p = Path(path)
    if not p.is_file():
        raise DiscoveryInputError(f"segment-load table not found: {p} (config discovery.in_vivo_segment_loads); "
                                  f"the in-vivo discovery needs the muscle model's segment loads with columns "
                                  f"{list(SEGMENT_LOAD_COLUMNS)}")
    sl = pd.read_csv(p)
    miss = [c for c in SEGMENT_LOAD_COLUMNS if c not in sl.columns]
    if miss:
        raise DiscoveryInputError(f"{p}: column(s) {miss} missing; expected columns {list(SEGMENT_LOAD_COLUMNS)}")
    sl = sl[sl["level"] == level]
    if sl.empty:
        raise DiscoveryInputError(f"{p}: no rows with level {level!r} (config discovery.in_vivo_level)")
    return sl


def in_vivo_problem(df, config, segment_loads=None) -> Problem:
    s = discovery_settings(config)
    sl = read_segment_loads(s["in_vivo_segment_loads"], s["in_vivo_level"]) if segment_loads is None else \
        segment_loads[segment_loads["level"] == s["in_vivo_level"]]
    conv = df["converged"].astype(str).str.lower().isin(["true", "1"])   # read_measured: bool
    d = df[conv].reset_index(drop=True).merge(sl[["activity", "compressive_n", "moment_nm"]], on="activity", how="left")
    if d["moment_nm"].isna().any():
        a = d["activity"][d["moment_nm"].isna()].iat[0]
        raise DiscoveryInputError(f"segment loads: no {s['in_vivo_level']} row for activity {a!r}; expected one row "
                                  f"per activity of the in-vivo table")
    base = d["idp_sim_mpa"].to_numpy(float) * 1e6
    M = d["moment_nm"].to_numpy(float)
    F = d["compressive_n"].to_numpy(float)
    ok = F > 0
    per_n = float(np.median(base[ok] / F[ok])) if ok.any() else idp_per_newton("paper2")

    def forward(values):
        return idp_forward(values, base, M, per_n) / 1e6

    # design space: every activity of the segment-load table (IDP of activities without a simulated value from
    # the force part, per_n * F: an approximation used only to rank where to measure next)
    sim = dict(zip(d["activity"], base))
    dsl = sl.drop_duplicates("activity").reset_index(drop=True)
    dbase = np.array([sim.get(a, per_n * f) for a, f in zip(dsl["activity"], dsl["compressive_n"].to_numpy(float))])
    dM = dsl["moment_nm"].to_numpy(float)

    def design_forward(values):
        return idp_forward(values, dbase, dM, per_n) / 1e6

    return Problem("in_vivo", d[["activity"]], d["idp_in_vivo_mpa"].to_numpy(float),
                   np.full(len(d), float(s["in_vivo_sd_mpa"])), "MPa", forward, _candidates(s, "in_vivo"),
                   "experiment", ["activity"], np.arange(len(d)),
                   meta={"idp_per_newton_pa": per_n, "design_keys": dsl[["activity"]], "design_forward": design_forward})


def build_problem(experiment, df, config, **kw) -> Problem:
    if experiment == "stepwise_rom":
        return rom_problem(df, config, kw.get("solver_kw"), kw.get("bank"))
    if experiment == "neutral_angle":
        return neutral_problem(df, config)
    if experiment == "idp_invitro":
        return idp_problem(df, config, kw.get("idp_model"), kw.get("bank"))
    if experiment == "in_vivo":
        return in_vivo_problem(df, config, kw.get("segment_loads"))
    raise ValueError(f"unknown experiment {experiment!r}")
