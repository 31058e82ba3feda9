"""Forward simulation of the stepwise-reduction experiment (paper 1, Sect. 3.1.2, Table 4, Fig. 6).

160 scenarios = 8 reduction stages (``lumbar.experiments.fsu.STAGES``) x 5 pure moments x 4 directions, solved
for one characteristic set in one batch, compared with a reference ROM table (mean, min, max).

Reference ROM tables (schema ``lumbar.inputs.tables.STEPWISE_ROM``, documented in ``data/experiments/README.md``):
one row per (stage, direction, moment_nm) with ``rom_mean_deg``, ``rom_min_deg``, ``rom_max_deg``,
``n_specimens``, ``kind``, ``source``. The measured table of Heuer et al. (2007) is not available to
the project: the workflow uses a surrogate from virtual specimens
(``lumbar.experiments.virtual_experiment.stepwise_reduction_table``) whose disc-only stage (``wo_all``) is replaced by
the rows derived from the paper's published Eq. 3 fit (``data/experiments/``); a user may supply the
real table in the same schema (config ``stepwise_reduction.measured_table``), which is then used as is.

Outlier rule (project decision): a simulated ROM is an outlier when it lies outside
``[rom_min_deg, rom_max_deg]`` of its reference row. Rows without a range (the derived disc-only rows,
kind ``derived_from_published_fit``) use ``mean +- tolerance_deg`` (default 0.5 deg). A scenario
without equilibrium (``converged = False``) always counts as an outlier.

Extra physical effects (hook for the discrepancy workflow): the one registry is ``lumbar.experiments.effects.EFFECTS``.
Its solver effects (``lumbar.experiments.effects.SOLVER_EFFECTS``) are solved with ``lumbar.experiments.effects.FsuVariants``; any
other effect needs a params form ``(fsu, value) -> dict`` of per-scenario solver parameters
(``lumbar.mechanics.solve.solve(params=...)``, may modify the specimen-private model in place), added with
``lumbar.experiments.effects.register_effect`` (re-exported here with ``effect_params``).
"""
from __future__ import annotations

import logging

import numpy as np
import pandas as pd

from ..mechanics import so3
from .effects import SOLVER_EFFECTS, FsuVariants, check_effect, effect_params
from .effects import register_effect as register_effect  # re-export: the documented extension hook
from .fsu import DIRECTIONS, MAIN_DIRECTIONS, STAGES, moment_loads
from ..inputs.io import TableError, read_table
from ..mechanics.solve import continue_rest_states, solve, stable_rest_states
from ..inputs.tables import STEPWISE_ROM, versus_paper

log = logging.getLogger(__name__)

MOMENTS_NM = (1.0, 2.5, 5.0, 7.5, 10.0)
REL_TOLERANCE = 0.25     # acceptance of a published value without a range (equal to lumbar.experiments.validation's)
# ------------------------------------------------------------------ simulation
def scenario_grid(stages=STAGES, directions=MAIN_DIRECTIONS, moments_nm=MOMENTS_NM) -> pd.DataFrame:
    """All (stage, direction, moment_nm) combinations in table order."""
    rows = [(s, d, float(M)) for s in stages for d in directions for M in moments_nm]
    return pd.DataFrame(rows, columns=["stage", "direction", "moment_nm"])


class StageSolver:
    """Solves ROM scenarios of one FSU repeatedly (calibration: same scenarios, changing parameters).

    Keeps the last converged states as warm starts; scenarios that fail from a warm start are
    re-solved from the reference configuration before they are reported as not converged.
    """

    def __init__(self, fsu, scenarios: pd.DataFrame, params=None, max_iter=50, tol=1e-9, load_steps=1,
                 retry_load_steps=(4,)):
        self.fsu, self.params = fsu, dict(params or {})
        self.scen = scenarios.reset_index(drop=True)
        for d in self.scen["direction"]:
            if d not in DIRECTIONS:
                raise ValueError(f"unknown direction {d!r}; expected one of {sorted(DIRECTIONS)}")
        self.stages = list(dict.fromkeys(self.scen["stage"]))
        self.si = np.array([self.stages.index(s) for s in self.scen["stage"]], int)
        self.fm_s, self.cm_s = fsu.masks(self.stages)
        m = fsu.model
        self.loads = moment_loads(list(self.scen["direction"]), list(self.scen["moment_nm"]), m.nb)
        self.axis = np.array([DIRECTIONS[d][0] for d in self.scen["direction"]])
        self.sign = np.array([DIRECTIONS[d][1] for d in self.scen["direction"]])
        self.kw = dict(max_iter=max_iter, tol_force=tol, tol_moment=tol, load_steps=load_steps)
        self.retry = tuple(retry_load_steps)
        self._warm0 = self._warm = None
        self.n_solves = 0

    def _solve(self, loads, fm, cm, warm):
        m = self.fsu.model
        B = loads.shape[0]
        p = self.params
        if warm is not None:
            res = solve(m, loads, x0=warm[0], R0=warm[1], fmask=fm, cmask=cm, params=p,
                        retry_load_steps=(), **self.kw)
            bad = np.flatnonzero(~res.converged)
            if bad.size:
                idx = bad
                sub = {k: (np.asarray(v)[idx] if np.ndim(v) and np.shape(v)[0] == B else v) for k, v in p.items()}
                cold = solve(m, loads[idx], fmask=fm[idx], cmask=cm[idx], params=sub,
                             retry_load_steps=self.retry, **self.kw)
                res.x[idx], res.R[idx], res.converged[idx] = cold.x, cold.R, cold.converged
                res.residual_force[idx], res.residual_moment[idx] = cold.residual_force, cold.residual_moment
        else:
            res = solve(m, loads, fmask=fm, cmask=cm, params=p, retry_load_steps=self.retry, **self.kw)
        self.n_solves += B
        return res

    def run(self):
        """(rom_deg (n,), converged (n,), loaded SolveResult); rom is NaN where not converged."""
        m = self.fsu.model
        zero = np.zeros((len(self.stages), m.nb, 6))
        r0 = self._solve(zero, self.fm_s, self.cm_s, self._warm0)
        if not r0.converged.all():      # a rest state not reached from the reference: continued from the stage before
            r0 = continue_rest_states(m, r0, self.fm_s, self.cm_s, self.params, max_iter=self.kw["max_iter"],
                                      tol_force=self.kw["tol_force"], tol_moment=self.kw["tol_moment"])
        #: per stage: its 0 N*m state, from which the ROM is measured, is stable (solve.stable_rest_states)
        self.rest_stable = stable_rest_states(m, r0.x, r0.R, self.fm_s, self.cm_s, self.params)
        si = self.si
        if self._warm is None:
            warm = (r0.x[si], r0.R[si])
        else:
            warm = self._warm
        res = self._solve(self.loads, self.fm_s[si], self.cm_s[si], warm)
        rot = so3.log(res.R[:, 0] @ np.swapaxes(r0.R[si, 0], -1, -2))
        rom = np.degrees(rot[np.arange(len(si)), self.axis] * self.sign)
        conv = res.converged & r0.converged[si]
        if r0.converged.all():
            self._warm0 = (r0.x.copy(), r0.R.copy())
        if conv.all():
            self._warm = (res.x.copy(), res.R.copy())
        self.last = res
        return np.where(conv, rom, np.nan), conv, res


def simulate_stepwise_reduction(fsu, stages=STAGES, directions=MAIN_DIRECTIONS, moments_nm=MOMENTS_NM,
                                effects=None, max_iter=50, tol=1e-7, load_steps=1) -> pd.DataFrame:
    """ROM of every (stage, direction, moment) scenario: stage, direction, moment_nm, rom_deg, converged,
    residual_force_n, residual_moment_nm (max residual of the loaded solve) and rest_state_stable (the stage's 0 N*m
    state, from which the ROM is measured, is stable: :func:`lumbar.mechanics.solve.stable_rest_states`); the effects
    path omits the last three.

    ``effects`` {name: value} of the registry ``lumbar.experiments.effects.EFFECTS``: when every name is a solver effect
    (``lumbar.experiments.effects.SOLVER_EFFECTS``, the discrepancy candidates; values within their bounds) the scenarios
    are solved as one ``lumbar.experiments.effects.FsuVariants`` batch (no residual columns, ``load_steps`` unused);
    otherwise every name needs a params form (``lumbar.experiments.effects.register_effect``)."""
    scen = scenario_grid(stages, directions, moments_nm)
    if effects and all(k in SOLVER_EFFECTS for k in effects):
        values = {}
        for k, val in effects.items():
            check_effect(k, val)
            values[k] = np.array([float(val)])
        rom, conv, _, _ = FsuVariants(fsu).simulate(scen, values, max_iter=max_iter, tol=tol)
        out = scen.copy()
        out["rom_deg"] = rom[0]
        out["converged"] = conv[0]
        if not out["converged"].all():
            log.info("stepwise reduction: %d of %d scenario(s) did not converge (rom_deg NaN, converged=False)",
                     int((~out["converged"]).sum()), len(out))
        return out
    ss = StageSolver(fsu, scen, params=effect_params(fsu, effects), max_iter=max_iter, tol=tol,
                     load_steps=load_steps)
    rom, conv, res = ss.run()
    out = scen.copy()
    out["rom_deg"] = rom
    out["converged"] = conv
    out["residual_force_n"] = res.residual_force      # of the loaded solve (the 0 N*m state has its own)
    out["residual_moment_nm"] = res.residual_moment
    # the stage's 0 N*m state is stable; False: a saddle, so the ROM from it includes a snap (docs/validity.md)
    out["rest_state_stable"] = ss.rest_stable[ss.si]
    if not conv.all():
        log.info("stepwise reduction: %d of %d scenario(s) did not converge (rom_deg NaN, converged=False)",
                 int((~conv).sum()), len(conv))
    return out


# ------------------------------------------------------------------ reference tables
def read_experiment_table(path) -> pd.DataFrame:
    """Read and validate a stepwise-reduction ROM table (errors name file, row and column)."""
    df = read_table(path, STEPWISE_ROM)
    for i, r in enumerate(df.itertuples(index=False)):
        lo, hi, mean = r.rom_min_deg, r.rom_max_deg, r.rom_mean_deg
        if np.isnan(lo) != np.isnan(hi):
            raise TableError(path, "only one of rom_min_deg / rom_max_deg is given", row=i + 1,
                             column="rom_min_deg" if np.isnan(lo) else "rom_max_deg",
                             expected="both empty or both numbers")
        if not np.isnan(lo) and not (lo <= mean <= hi):
            raise TableError(path, f"rom_mean_deg {mean:g} is not within [rom_min_deg {lo:g}, rom_max_deg {hi:g}]",
                             row=i + 1, column="rom_mean_deg", expected="rom_min_deg <= rom_mean_deg <= rom_max_deg")
    key = df[["stage", "direction", "moment_nm"]].apply(tuple, axis=1)
    dup = key.duplicated()
    if dup.any():
        i = int(np.flatnonzero(dup.to_numpy())[0])
        raise TableError(path, f"duplicate scenario {key.iloc[i]}", row=i + 1, column="stage",
                         expected="one row per (stage, direction, moment_nm)")
    return df


def reference_table(experiment: pd.DataFrame, derived: pd.DataFrame | None = None,
                    real: pd.DataFrame | None = None) -> pd.DataFrame:
    """The table the model is calibrated on and compared with.

    A measured table (no ``surrogate`` rows) is returned as is. For a surrogate table, the disc-only
    rows (``wo_all``) are replaced by the rows derived from the published Eq. 3 fit when ``derived``
    is given, and the rows of the same scenarios by the ``real`` rows (e.g. the intact ROM at 10 N*m of
    Yamamoto et al. 1989), so that every scenario with a published value is compared with it.
    """
    exp = experiment.copy()
    for d in (derived, real):
        if d is None or not len(d) or not (experiment["kind"] == "surrogate").all():
            continue
        d = d.copy()
        keys = set(map(tuple, d[["stage", "direction", "moment_nm"]].to_numpy().tolist()))
        keep = [tuple(k) not in keys for k in exp[["stage", "direction", "moment_nm"]].to_numpy().tolist()]
        exp = pd.concat([exp[keep], d[[c for c in exp.columns if c in d.columns]]], ignore_index=True)
    order = {s: i for i, s in enumerate(STAGES)}
    dord = {d: i for i, d in enumerate(MAIN_DIRECTIONS)}
    exp = exp.assign(_s=exp["stage"].map(order), _d=exp["direction"].map(dord))
    return exp.sort_values(["_s", "_d", "moment_nm"]).drop(columns=["_s", "_d"]).reset_index(drop=True)


def unreferenced_scenarios(sim: pd.DataFrame, ref: pd.DataFrame) -> list[str]:
    """The simulated scenarios (stage, direction, moment) that ``ref`` has no row for, as "stage direction M N*m"."""
    keys = ["stage", "direction", "moment_nm"]
    have = set(map(tuple, ref[keys].astype({"moment_nm": float}).to_numpy().tolist()))
    return [f"{a} {b} {float(c):g} N*m" for a, b, c in sim[keys].drop_duplicates().to_numpy().tolist()
            if (a, b, float(c)) not in have]


def assess(sim: pd.DataFrame, ref: pd.DataFrame, set_name: str, tolerance_deg: float = 0.5) -> pd.DataFrame:
    """Table 4 rows for one set: simulated ROM beside the reference, outlier flag, data kind.

    Reference rows without a range use mean +- ``tolerance_deg``; not-converged scenarios are outliers.
    """
    if not np.isfinite(tolerance_deg) or tolerance_deg < 0:
        raise ValueError(f"tolerance_deg must be finite and >= 0, got {tolerance_deg}")
    keys = ["stage", "direction", "moment_nm"]
    df = sim[keys + ["rom_deg", "converged"]].merge(
        ref[keys + ["rom_mean_deg", "rom_min_deg", "rom_max_deg", "kind"]], on=keys, how="inner")
    if len(df) == 0 and len(sim):
        raise ValueError(
            f"set {set_name}: the reference ROM table shares no scenario (stage, direction, moment_nm) with the "
            f"simulation: simulated moments {sorted(set(sim['moment_nm'].astype(float)))} N*m, stages "
            f"{sorted(set(sim['stage']))}; reference moments {sorted(set(ref['moment_nm'].astype(float)))} N*m, stages "
            f"{sorted(set(ref['stage']))}. Set stepwise_reduction.moments_nm to the table's moments (or check "
            "stepwise_reduction.measured_table)")
    if len(df) < len(sim):
        # a surrogate leaves out the rows its virtual specimens cannot reach (a model limit, logged where the
        # surrogate is made); a measured table's missing scenarios are named once by the caller
        # (:func:`unreferenced_scenarios`)
        log.info("set %s: %d simulated scenario(s) have no reference row and are not assessed", set_name,
                 len(sim) - len(df))
    no_range = df["rom_min_deg"].isna()
    # rows without a range: the derived (published-fit) and surrogate rows use mean +- tolerance_deg; a
    # published population value without a range (e.g. Yamamoto et al. 1989) uses mean +- 25 %, the rule of
    # lumbar.experiments.validation (REL_TOLERANCE), so Table 4 and the real-data scoreboard judge such a row alike
    relative = no_range & ~df["kind"].isin(["derived_from_published_fit", "surrogate"])
    half = np.where(relative, REL_TOLERANCE * df["rom_mean_deg"].to_numpy(float), tolerance_deg)
    lo = np.where(no_range, df["rom_mean_deg"] - half, df["rom_min_deg"])
    hi = np.where(no_range, df["rom_mean_deg"] + half, df["rom_max_deg"])
    rom = df["rom_deg"].to_numpy(float)
    inside = (rom >= lo) & (rom <= hi)
    out = pd.DataFrame({
        "set": set_name, "stage": df["stage"], "direction": df["direction"], "moment_nm": df["moment_nm"],
        "rom_sim_deg": rom, "rom_mean_deg": df["rom_mean_deg"], "rom_min_deg": df["rom_min_deg"],
        "rom_max_deg": df["rom_max_deg"],
        "outlier": ~(df["converged"].to_numpy(bool) & inside),
        "converged": df["converged"].astype(bool),
        "data_kind": df["kind"],
        "range_rule": np.where(relative, f"mean+-{REL_TOLERANCE * 100:g}%",
                               np.where(no_range, f"mean+-{tolerance_deg:g}deg", "min-max")),
    })
    return out


def outlier_counts(synopsis: pd.DataFrame) -> pd.DataFrame:
    """Outliers per set: all rows, and (``n_outliers_real`` / ``n_scenarios_real``) only the rows whose
    reference is real (a measured or published-fit value, kind != surrogate). The surrogate rows are a
    method check (round trip on virtual specimens of this model), never a reproduction of the paper."""
    g = synopsis.groupby("set", sort=False)
    real = synopsis["data_kind"] != "surrogate"
    out = pd.DataFrame({"n_scenarios": g.size(), "n_outliers": g["outlier"].sum().astype(int),
                        "n_not_converged": g["converged"].apply(lambda c: int((~c.astype(bool)).sum())),
                        "data_kinds": g["data_kind"].apply(lambda k: "+".join(sorted(set(k))))})
    out["n_scenarios_real"] = real.groupby(synopsis["set"], sort=False).sum().astype(int)
    out["n_outliers_real"] = (synopsis["outlier"].astype(bool) & real).groupby(synopsis["set"], sort=False).sum().astype(int)
    out["surrogate_comparison"] = np.where(out["data_kinds"].astype(str).str.contains("surrogate"),
                                           "method check (round trip on virtual specimens)",
                                           "none: every reference row is measured or published")
    return out.reset_index()


PAPER_N_SCENARIOS = 160      # paper 1, Table 4: 8 stages x 4 directions x 5 moments
PAPER_OUTLIER_KEYS = {"calibrated": "outliers_rom_this_paper_model", "chazal1985": "outliers_rom_chazal1985",
                      "shirazi_adl1986": "outliers_rom_shirazi_adl1986",
                      "white_panjabi1990": "outliers_rom_white_panjabi1990",
                      "nolte1990": "outliers_rom_nolte1990", "rupp2015": "outliers_rom_rupp2015"}


def compare_with_paper(counts: pd.DataFrame, published_csv=None) -> pd.DataFrame:
    """Our outlier counts beside the paper's (Sect. 3.1.2; 160 scenarios), in the columns of
    :data:`lumbar.inputs.tables.VS_PAPER_COLUMNS`; empty paper columns if the file is absent."""
    return versus_paper(counts, published_csv, PAPER_OUTLIER_KEYS, paper_n_scenarios=PAPER_N_SCENARIOS)


def with_bands(synopsis: pd.DataFrame, bands: pd.DataFrame, set_name="calibrated") -> pd.DataFrame:
    """The Table 4 synopsis with the 90 % posterior band of ``set_name``'s simulated ROM (rom_band_low,
    rom_band_high; NaN for the other sets and where no band was computed); ``outlier`` stays on the MAP value."""
    out = synopsis.copy()
    out["rom_band_low"], out["rom_band_high"] = np.nan, np.nan
    if bands is None or not len(bands):
        return out
    key = ["stage", "direction", "moment_nm"]
    b = bands[key + ["low90", "high90"]].copy()
    b["moment_nm"] = b["moment_nm"].astype(float)
    m = out[key].assign(moment_nm=out["moment_nm"].astype(float)).merge(b, on=key, how="left")
    sel = (out["set"] == set_name).to_numpy()
    out.loc[sel, "rom_band_low"] = m.loc[sel, "low90"].to_numpy()
    out.loc[sel, "rom_band_high"] = m.loc[sel, "high90"].to_numpy()
    return out
