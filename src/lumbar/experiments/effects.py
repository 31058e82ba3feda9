"""Candidate physical effects for the discrepancy workflow.

Each effect is a one-parameter extension of a model that **vanishes at parameter 0** (the model is then
unchanged, bit for bit) and acts on some of the project's experiments:

* ``stepwise_rom``  L4-L5 range of motion of the stepwise-reduction experiment (re-solved, batched);
* ``neutral_angle`` L4-L5 sagittal angle at 0 N*m per reduction stage (the vertebral-arch artefact);
* ``idp_invitro``   L4-L5 IDP of the L2-S1 wire-cable experiment (from the solved internal loads);
* ``in_vivo``       L4-L5 IDP of the muscle-driven model against in-vivo values (from segment loads);
* ``multilevel_rom`` range of motion of the levels the calibration did not fit (the real-data case of the same name).

Two families:

* ``kind = "solver"``: enters the equilibrium (lumbar.mechanics.model params ``k_tension``, ``disc_phi_offset``,
  ``fibre_l0_scale``, or extra fibres/cables whose per-scenario fibre-mask weight is the parameter, so
  the solver's exact Jacobian covers them). :class:`FsuVariants` solves many parameter values of many
  effects as one batch.
* ``kind = "idp"``: acts on the IDP computed from the disc loads (no re-solve):
  ``idp_delta(name, value, idp_pa, f_axial_n, m_sagittal_nm, idp_per_newton)``.

This module is the one effect registry of the package (``EFFECTS``). An effect may also carry a
``params`` form, ``params(fsu, value) -> dict`` of per-scenario solver parameters
(``lumbar.mechanics.solve.solve(params=...)``; it may modify the specimen-private model in place), used by
``lumbar.experiments.stepwise_reduction.simulate_stepwise_reduction`` when an effect outside ``SOLVER_EFFECTS`` is
asked for; add such extra effects with :func:`register_effect` and turn a {name: value} dict into solver
params with :func:`effect_params`.

``lumbosacral_disc_height`` is a level-specific candidate: the L5-S1 disc's height relative to the L4-L5 disc the
transferred laws were calibrated on, ``delta = h(L5-S1) / h(L4-L5) - 1``, turned into the disc's laws as a disc of
the same material and cross-section: its strains are the L4-L5 disc's at ``1 + delta`` times the angle or displacement,
so every law takes its argument divided by ``1 + delta`` (Eq. 3: ``T(phi) -> T(phi / (1 + delta))``, i.e. p2 times
``(1 + delta)**3`` and p3 divided by ``1 + delta``; axial ``F(c) -> F(c / (1 + delta))``; shear stiffness divided by
``1 + delta``): the disc alone rotates ``1 + delta`` times as far under the same moment. It acts only on a unit of level
:data:`LUMBOSACRAL_LEVEL` (anywhere else it is the identity) and is solved on a copy of the unit's model with the
scaled disc (:meth:`FsuVariants.disc_model`), so the numpy reference and the compiled kernel both see it without a
change of the kernel. Its sourced range (:func:`sourced_range`) is read from
``data/anatomy/lumbosacral_disc_height_original_text.csv`` (radiographic/MRI morphometry, independent of the ROM rows
it is judged on).

``disc_tension`` is registered for completeness (paper 1, Sect. 4.3 hypothesis) but no scenario of the
available experiments loads the L4-L5 disc in tension (the effect changes no ROM by more than 1e-8 deg
and no IDP by more than 0.1 N of disc force), so it is not identifiable there and is not benchmarked.
"""
from __future__ import annotations

import copy
import functools
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import pandas as pd

from ..mechanics import so3
from ..inputs import resources
from ..inputs.characteristics import default_data_dir, load_characteristic_set
from ..mechanics.elements.ligament import rupp_shape, slack_length
from .fsu import DIRECTIONS, STAGES, moment_loads
from ..mechanics.idp import K_FLEXION_PA_PER_NM
from ..mechanics.solve import solve

EXPERIMENTS = ("stepwise_rom", "neutral_angle", "idp_invitro", "in_vivo", "multilevel_rom")
# stages after the vertebral arches were sawn off where the neutral-angle offset acts; at w/o ALL the disc
# alone is shift invariant (the ROM about the stage's own 0 N*m state cannot change), and its flexion law
# (Eq. 3 with p3 < 0) has an unstable neutral, so the offset is not applied there
VA_STAGES = ("wo_va", "wo_pll")
ARCH_STAGES = STAGES[STAGES.index("wo_va"):]         # stages without the vertebral arches (ITL, spinous processes)
PRELOAD_CABLE_LENGTH_M = 1000.0                      # far fixed point: the preload keeps its direction
PASSIVE_CABLE_LENGTH_M = 1.0
# effects with a form inside the L4-L5 equilibrium (FsuVariants); axial_preload also has an IDP form
SOLVER_EFFECTS = ("ligament_prestrain", "va_neutral_offset", "itl", "passive_muscle", "disc_tension",
                  "axial_preload", "lumbosacral_disc_height")
#: the level whose disc the level-specific candidate lumbosacral_disc_height changes
LUMBOSACRAL_LEVEL = "L5-S1"
#: the sourced morphometry of the lumbosacral disc (package data, relative to the data folder)
LUMBOSACRAL_DISC_TABLE = "anatomy/lumbosacral_disc_height_original_text.csv"


@dataclass(frozen=True)
class Effect:
    name: str
    parameter: str
    unit: str                     # SI unit of the parameter
    bounds: tuple                 # (lo, hi) of the fit, SI
    magnitudes: tuple             # benchmark magnitudes (SI), plausible sizes
    experiments: tuple            # experiments it acts on (benchmarked there)
    kind: str                     # "solver" | "idp" | "params" (registered: a params form only)
    description: str
    basis: str                    # where the papers point at it
    params: Callable | None = None  # (fsu, value) -> dict of solver params (may edit fsu.model); None: none
    sourced: Callable | None = None  # () -> (lo, hi, source text): the magnitude range a source measured; None: none


def _disc_tension_params(fsu, value):
    """Disc axial tensile stiffness k_tension [N/m] (the paper's disc transmits no traction)."""
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"effect disc_tension: k_tension must be finite and >= 0 N/m, got {value!r}")
    return {"k_tension": v}


def lumbosacral_disc_height_range(path=None) -> tuple:
    """(lo, hi, source) of ``delta = h(L5-S1) / h(L4-L5) - 1`` from the sourced middle disc heights: the ratio of the
    two levels' mean middle heights of each source (rows ``disc_height_middle`` at L4-L5 and L5-S1 of
    :data:`LUMBOSACRAL_DISC_TABLE`), lo/hi the smallest and largest over the sources (the spread between the
    populations' means; a range of the mean of a group of specimens, as the judged rows are means)."""
    p = Path(path) if path is not None else resources.data_dir() / LUMBOSACRAL_DISC_TABLE
    if not p.is_file():
        raise ValueError(f"lumbosacral disc table not found: {p}; expected columns quantity, level, value, unit, "
                         f"kind, source")
    t = pd.read_csv(p)
    need = {"quantity", "level", "value", "unit", "kind", "source"}
    if need - set(t.columns):
        raise ValueError(f"{p}: column(s) {sorted(need - set(t.columns))} missing; expected {sorted(need)}")
    t = t[t["quantity"] == "disc_height_middle"]
    if (t["unit"] != "mm").any():
        raise ValueError(f"{p}, column 'unit': {sorted(set(t['unit']) - {'mm'})} not understood; expected mm")
    ratios, sources = [], []
    for src, g in t.groupby("source", sort=False):
        by = dict(zip(g["level"], g["value"].astype(float)))
        if "L4-L5" in by and LUMBOSACRAL_LEVEL in by:
            ratios.append(by[LUMBOSACRAL_LEVEL] / by["L4-L5"])
            sources.append(src)
    if not ratios:
        raise ValueError(f"{p}: no source gives disc_height_middle at both L4-L5 and {LUMBOSACRAL_LEVEL}")
    return float(min(ratios) - 1.0), float(max(ratios) - 1.0), f"{LUMBOSACRAL_DISC_TABLE} ({len(ratios)} sources)"


def sourced_range(name):
    """(lo, hi, source) of an effect's sourced magnitude range, or None when no source measured one."""
    e = check_effect(name)
    return e.sourced() if e.sourced is not None else None


EFFECTS: dict[str, Effect] = {e.name: e for e in [
    Effect("ligament_prestrain", "delta_prestrain", "1 (strain)", (-0.06, 0.06), (0.02, 0.04),
           ("stepwise_rom", "neutral_angle"), "solver",
           "extra prestrain of every ligament fibre: slack length l0 -> l0 / (1 + delta)",
           "paper 1 Sect. 2.2.4: prestrains taken from the literature, not measured on the specimens"),
    Effect("va_neutral_offset", "lordosis_offset", "rad", (-0.07, 0.07), (0.0269, 0.0524),
           ("stepwise_rom", "neutral_angle"), "solver",
           "disc neutral angle shifted into lordosis (extension) from the w/o VA stage on "
           "(disc_phi_offset_y = -offset for wo_va, wo_pll; w/o ALL is shift invariant)",
           "paper 1 Sect. 4.2: sawing off the vertebral arches increased the lordotic angle at 0 N*m "
           "from 0.66 to 2.2 deg (Heuer et al. 2007, Table 1)"),
    Effect("itl", "itl_force_scale", "1", (0.0, 1.0), (0.1, 0.25),
           ("stepwise_rom", "neutral_angle"), "solver",
           "intertransverse ligaments (left, right) with the Rupp et al. (2015) ITL law times a force scale; "
           "removed with the vertebral arches",
           "paper 1 Sect. 4.2: the ITL influence was not measured; Sect. 4.3: non-validated ITL"),
    Effect("passive_muscle", "passive_tension", "N", (0.0, 100.0), (10.0, 25.0),
           ("stepwise_rom", "neutral_angle"), "solver",
           "passive posterior muscle tissue: a constant-force cable from the L4 spinous process (SSL "
           "insertion) towards the L5 one, removed with the vertebral arches",
           "paper 2 Sect. 3.2.2/4: passive muscle stiffness changes spinal loading; paper 1 Sect. 2.1.1: "
           "specimens were prepared free of muscle"),
    Effect("axial_preload", "preload", "N", (0.0, 1000.0), (150.0, 300.0),
           ("idp_invitro", "in_vivo"), "idp",
           "axial compressive preload carried by the disc (follower-load-like): IDP += idp_per_newton * P",
           "paper 2 Sect. 4: in-vivo compression from body weight and muscles; in-vitro tests without preload"),
    Effect("idp_moment_term", "k_moment", "Pa/(N*m)", (0.0, 0.2e6), (K_FLEXION_PA_PER_NM, 2 * K_FLEXION_PA_PER_NM),
           ("idp_invitro", "in_vivo"), "idp",
           "IDP += k * |M_sagittal| (the disc's bending moment raises the nucleus pressure)",
           "paper 2 Sect. 2.4: IDP formula with +0.036 MPa/(N*m) flexion, +0.018 extension moment term; "
           "paper 1 Eq. IDP = 1.68 F/CSA has none"),
    Effect("disc_load_share", "share_slope", "1/(N*m)", (-0.25, 0.25), (0.06, 0.12),
           ("idp_invitro", "in_vivo"), "idp",
           "posture-dependent share of the axial load on the nucleus: IDP *= 1 + s * M_sagittal "
           "(flexion + loads the nucleus, extension + unloads it to the facets)",
           "paper 2 Sect. 2.4: disc share 0.85 and nucleus factor 0.66 taken constant for every posture"),
    Effect("disc_tension", "k_tension", "N/m", (0.0, 2.0e6), (5.0e5, 1.0e6),
           (), "solver",
           "disc tensile (traction) stiffness k_tension (the published disc transmits no traction)",
           "paper 1 Sect. 4.3: outliers with the cranial multifidus attributed partly to the disc's "
           "inability to transmit traction", params=_disc_tension_params),
    Effect("lumbosacral_disc_height", "delta_height", "1 (relative height)", (-0.5, 1.5), (0.045, 0.09),
           ("multilevel_rom",), "solver",
           "the L5-S1 disc's height relative to the L4-L5 disc whose laws are transferred, delta = h(L5-S1)/h(L4-L5) "
           "- 1: the L5-S1 disc's laws per unit height (every law's angle or displacement divided by 1+delta: the "
           "disc alone rotates 1+delta times as far under the same moment); no effect at another level",
           "validation: the calibrated set is carried to the other levels unchanged; the lumbosacral disc's "
           "morphometry differs from L4-L5's (data/anatomy/lumbosacral_disc_height_original_text.csv)",
           sourced=lumbosacral_disc_height_range),
]}


def register_effect(name: str, fn: Callable) -> None:
    """Add an extra physical effect: ``fn(fsu, value) -> dict`` of solver params (may edit fsu.model).

    A known effect keeps its description and solver form and gets ``fn`` as its params form; a new name
    becomes an effect of kind ``"params"`` that acts on no benchmarked experiment."""
    if name in EFFECTS:
        EFFECTS[name] = replace(EFFECTS[name], params=fn)
    else:
        EFFECTS[name] = Effect(name, "value", "", (-np.inf, np.inf), (), (), "params",
                               (fn.__doc__ or "").strip(), "registered with lumbar.experiments.effects.register_effect",
                               params=fn)


def effect_params(fsu, effects: Mapping | None) -> dict:
    """Solver ``params`` for a dict {effect name: value} (effects with a params form); unknown names
    raise ValueError."""
    params: dict = {}
    known = sorted(n for n, e in EFFECTS.items() if e.params is not None)
    for name, value in (effects or {}).items():
        if name not in known:
            raise ValueError(f"unknown effect {name!r}; known effects: {known}")
        if value is None:
            continue
        params.update(EFFECTS[name].params(fsu, value))
    return params


def effect_names(experiment=None, kind=None):
    """Effects acting on ``experiment`` (all with None), optionally of one ``kind``."""
    return [n for n, e in EFFECTS.items() if (experiment is None or experiment in e.experiments)
            and (kind is None or e.kind == kind)]


def check_effect(name, value=None):
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
    if value is not None:
        lo, hi = EFFECTS[name].bounds
        v = float(value)
        if not np.isfinite(v) or v < lo or v > hi:
            raise ValueError(f"effect {name}: {EFFECTS[name].parameter} = {value!r} {EFFECTS[name].unit} "
                             f"is outside its bounds [{lo:g}, {hi:g}]")
    return EFFECTS[name]


# ------------------------------------------------------------------ IDP-from-loads effects
def idp_delta(name, value, idp_pa, m_sagittal_nm, idp_per_newton):
    """IDP [Pa] with the IDP effect ``name`` at ``value`` (arrays broadcast; value 0 -> idp unchanged)."""
    idp = np.asarray(idp_pa, float)
    v = np.asarray(value, float)
    M = np.asarray(m_sagittal_nm, float)
    if name == "axial_preload":
        return idp + v * idp_per_newton
    if name == "idp_moment_term":
        return idp + v * np.abs(M)
    if name == "disc_load_share":
        return idp * (1.0 + v * M)
    raise ValueError(f"effect {name!r} is not an IDP effect; IDP effects: {effect_names(kind='idp')}")


# ------------------------------------------------------------------ solver effects on the L4-L5 unit

def rupp2015_itl_law():
    """The intertransverse ligament law of the rupp2015 set (the ITL effect's law), read once per version of the
    data folder's tables: a discovery benchmark builds a unit per virtual specimen (hundreds per job), and reading
    the set's tables each time cost about 30 ms a unit."""
    d = Path(default_data_dir())
    stamp = tuple((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in sorted(d.glob("*.csv")))
    return _rupp2015_itl_law(str(d), stamp)


@functools.lru_cache(maxsize=4)
def _rupp2015_itl_law(data_dir: str, stamp: tuple):
    return load_characteristic_set("rupp2015", data_dir=data_dir).ligaments["ITL"]


class FsuVariants:
    """An L4-L5 unit augmented with the extra elements of the solver effects (at weight 0).

    ``simulate(scen, values)`` solves every row of ``values`` (a model variant: one value per effect)
    for every scenario of ``scen`` (stage, direction, moment_nm) in one batch: (G*S) 0 N*m states and
    (G*n) loaded states warm-started from them. Returns ROM (G, n) [deg] relative to each variant's
    0 N*m state, converged (G, n), and the 0 N*m rotation vectors (G, S, 3) [rad].
    """

    def __init__(self, fsu, itl_law=None):

        self.fsu = fsu
        m = copy.deepcopy(fsu.model)
        m.__dict__.pop("_group_cache", None)
        self.nf_base = m.nf
        lev = fsu.level
        up, lo = 0, -1
        extra = {}
        if itl_law is None:
            itl_law = rupp2015_itl_law()
        itl = [lg for lg in lev.ligaments if lg.kind == "ITL"]
        shape = rupp_shape(itl_law.l_a_m, itl_law.l_b_m, itl_law.f_a_n, itl_law.f_b_n, itl_law.n_strands)
        g_itl = [m.add_fibre_group(lg.name + "_effect", "ITL", lev.name, up, lo, lg.upper, lg.lower,
                                   lg.extra_length, "rupp", shape, prestrain=itl_law.prestrain,
                                   scale=itl_law.n_strands / lg.n_fibres) for lg in itl]
        extra["itl"] = g_itl
        c = np.asarray(lev.disc_centre, float)
        nrm = np.asarray(lev.disc_normal, float) / np.linalg.norm(lev.disc_normal)
        extra["axial_preload"] = [m.add_fibre_group("preload_effect", "preload", lev.name, up, lo, c[None],
                                                    (c - PRELOAD_CABLE_LENGTH_M * nrm)[None], 0.0, "cable",
                                                    (1.0,))]
        ssl = [lg for lg in lev.ligaments if lg.kind == "SSL"]
        src = ssl[0] if ssl else [lg for lg in lev.ligaments if lg.kind == "ISL"][0]
        a, b = np.asarray(src.upper, float).mean(0), np.asarray(src.lower, float).mean(0)
        u = (b - a) / np.linalg.norm(b - a)
        extra["passive_muscle"] = [m.add_fibre_group("passive_muscle_effect", "passive_muscle", lev.name, up, lo,
                                                     a[None], (a + PASSIVE_CABLE_LENGTH_M * u)[None], 0.0,
                                                     "cable", (1.0,))]
        m.finalize()
        self.model = m
        self.extra_cols = {k: np.flatnonzero(np.isin(m.f_group, g)) for k, g in extra.items()}
        self.is_lig = np.zeros(m.nf, bool)
        self.is_lig[: self.nf_base] = m.f_law[: self.nf_base] != 2
        self.is_lig[self.extra_cols["itl"]] = True
        self.acts_disc_height = lev.name == LUMBOSACRAL_LEVEL
        self._disc_models: dict = {}

    def disc_model(self, delta):
        """The unit's model with its discs' laws as those of a disc of relative height ``1 + delta`` and the same
        material (effect lumbosacral_disc_height): every law takes its argument divided by ``1 + delta`` (Eq. 3
        T(phi) -> T(phi / (1 + delta)): p1 kept, p2 x (1 + delta)**3, p3 / (1 + delta); axial F(c) -> F(c / (1 +
        delta)): k_linear / (1 + delta), k_quadratic / (1 + delta)**2; k_shear / (1 + delta)). The unit's own model
        at ``delta`` 0 and at any level but LUMBOSACRAL_LEVEL (the same object: bit-identical results)."""
        d = float(delta)
        check_effect("lumbosacral_disc_height", d)
        if d == 0.0 or not self.acts_disc_height:
            return self.model
        if d not in self._disc_models:
            m = copy.deepcopy(self.model)
            for k in ("_group_cache", "_kernel_model_data", "_kernel_defaults"):
                m.__dict__.pop(k, None)
            a = 1.0 + d
            for spec in m.discs:
                spec.k_linear /= a
                spec.k_shear /= a
                spec.k_quadratic /= a * a
                spec.torque = {k: (p1, p2 * a ** 3, p3 / a) for k, (p1, p2, p3) in spec.torque.items()}
            if len(self._disc_models) >= 64:                # a discovery grid's values, bounded
                self._disc_models.pop(next(iter(self._disc_models)))
            self._disc_models[d] = m
        return self._disc_models[d]

    def _by_disc_model(self, values: dict, fn):
        """``fn(model, values)`` per distinct value of lumbosacral_disc_height (one model per value, see
        :meth:`disc_model`), its per-variant outputs (arrays with G rows) put back in the order of ``values``."""
        values = dict(values)
        dh = values.pop("lumbosacral_disc_height", None)
        if dh is None:
            return fn(self.model, values)
        dh = np.asarray(dh, float).reshape(-1)
        for u in np.unique(dh):
            check_effect("lumbosacral_disc_height", u)
        G = len(dh)
        values = {k: np.asarray(v, float).reshape(G) for k, v in values.items()} or \
            {"ligament_prestrain": np.zeros(G)}         # keeps G variants (a zero prestrain is no change)
        if not self.acts_disc_height or not dh.any():
            return fn(self.model, values)
        out = None
        for u in np.unique(dh):
            idx = np.flatnonzero(dh == u)
            res = fn(self.disc_model(u), {k: v[idx] for k, v in values.items()})
            if out is None:
                out = [np.empty((G,) + r.shape[1:], r.dtype) if isinstance(r, np.ndarray) and r.shape[:1] == (len(idx),)
                       else r for r in res]
            for o, r in zip(out, res):
                if isinstance(o, np.ndarray):
                    o[idx] = r
        return tuple(out)

    def masks_params(self, stages, values: dict):
        """fmask (G*S, nf), cmask (G*S, nc), params for variants ``values`` {effect: (G,)} x stages."""
        stages = list(stages)
        G = len(next(iter(values.values()))) if values else 1
        for k in values:
            check_effect(k)
            if k not in SOLVER_EFFECTS:
                raise ValueError(f"effect {k!r} does not act on the solver")
        if "lumbosacral_disc_height" in values and np.any(values["lumbosacral_disc_height"]) and self.acts_disc_height:
            raise ValueError("effect lumbosacral_disc_height changes the model, not the masks: solve it with "
                             "FsuVariants.simulate or neutral_lordosis (one model per value, FsuVariants.disc_model)")
        fb, cb = self.fsu.masks(stages)
        S, m = len(stages), self.model
        fm = np.zeros((G, S, m.nf))
        fm[:, :, : self.nf_base] = fb
        cm = np.broadcast_to(cb, (G, S, m.nc)).copy()
        after_va = np.array([s in ARCH_STAGES for s in stages])
        offset_on = np.array([s in VA_STAGES for s in stages])
        v = {k: np.asarray(values.get(k, np.zeros(G)), float).reshape(G) for k in
             ("ligament_prestrain", "va_neutral_offset", "itl", "passive_muscle", "disc_tension", "axial_preload")}
        for k in ("itl", "passive_muscle"):
            fm[:, :, self.extra_cols[k]] = (v[k][:, None] * ~after_va)[..., None]
        fm[:, :, self.extra_cols["axial_preload"]] = v["axial_preload"][:, None, None]
        params = {}
        if (v["ligament_prestrain"] != 0).any():
            sc = np.ones((G, S, m.nf))
            sc[:, :, self.is_lig] = slack_length(1.0, v["ligament_prestrain"])[:, None, None]
            params["fibre_l0_scale"] = sc.reshape(G * S, m.nf)
        if (v["va_neutral_offset"] != 0).any():
            off = np.zeros((G, S, 3))
            off[:, :, 1] = -v["va_neutral_offset"][:, None] * offset_on
            params["disc_phi_offset"] = off.reshape(G * S, 3)
        if (v["disc_tension"] != 0).any():
            params["k_tension"] = np.repeat(v["disc_tension"], S)
        return fm.reshape(G * S, m.nf), cm.reshape(G * S, m.nc), params, G

    def _start(self, params, B):
        """Start states: the disc's shifted neutral angle, so Newton finds the root next to it (the
        disc-only flexion law of Eq. 3 with p3 < 0 has a second zero-torque root far away)."""
        x0, R0 = self.model.reference_state(B)
        off = params.get("disc_phi_offset")
        if off is not None:
            R0[:, 0] = so3.exp(np.asarray(off, float))
        return x0, R0

    def simulate(self, scen: pd.DataFrame, values: dict, max_iter=50, tol=1e-7, retry_load_steps=(4, 16)):
        """``retry_load_steps``: load continuation for scenarios that fail at first (the solver's default; the
        virtual-specimen banks of the discrepancy null pass fewer, a failing specimen scenario is a NaN there)."""
        scen = scen.reset_index(drop=True)
        return self._by_disc_model(values, lambda m, v: self._simulate(m, scen, v, max_iter, tol, retry_load_steps))

    def _simulate(self, m, scen, values, max_iter, tol, retry_load_steps):
        stages = list(dict.fromkeys(scen["stage"]))
        fm, cm, params, G = self.masks_params(stages, values)
        S, n = len(stages), len(scen)
        kw = dict(max_iter=max_iter, tol_force=tol, tol_moment=tol, retry_load_steps=tuple(retry_load_steps))
        r0 = solve(m, np.zeros((G * S, m.nb, 6)), *self._start(params, G * S), fmask=fm, cmask=cm,
                   params=params, **kw)
        si = np.array([stages.index(s) for s in scen["stage"]])
        gi = (np.arange(G)[:, None] * S + si[None, :]).ravel()          # (G*n,) index into the G*S states
        loads = np.tile(moment_loads(list(scen["direction"]), list(scen["moment_nm"]), m.nb), (G, 1, 1))
        p1 = {k: np.asarray(val)[gi] for k, val in params.items()}
        res = solve(m, loads, x0=r0.x[gi], R0=r0.R[gi], fmask=fm[gi], cmask=cm[gi], params=p1, **kw)
        rot = so3.log(res.R[:, 0] @ np.swapaxes(r0.R[gi, 0], -1, -2))
        axis = np.array([DIRECTIONS[d][0] for d in scen["direction"]])
        sign = np.array([DIRECTIONS[d][1] for d in scen["direction"]])
        rom = np.degrees(rot.reshape(G, n, 3)[:, np.arange(n), axis] * sign)
        conv = (res.converged & r0.converged[gi]).reshape(G, n)
        phi0 = so3.log(r0.R[:, 0]).reshape(G, S, 3)
        return np.where(conv, rom, np.nan), conv, phi0, stages

    def neutral_lordosis(self, stages, values: dict, max_iter=50, tol=1e-7):
        """Lordotic angle change [deg] at 0 N*m per stage (G, S): -(sagittal rotation) from the reference."""
        return self._by_disc_model(values, lambda m, v: self._neutral_lordosis(m, stages, v, max_iter, tol))

    def _neutral_lordosis(self, m, stages, values, max_iter, tol):
        fm, cm, params, G = self.masks_params(stages, values)
        r0 = solve(m, np.zeros((fm.shape[0], m.nb, 6)), *self._start(params, fm.shape[0]),
                   fmask=fm, cmask=cm, params=params, max_iter=max_iter, tol_force=tol, tol_moment=tol)
        phi = so3.log(r0.R[:, 0]).reshape(G, len(stages), 3)
        return -np.degrees(phi[..., 1]), r0.converged.reshape(G, len(stages))

