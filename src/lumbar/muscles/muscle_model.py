"""Muscle-driven lumbar spine (paper 2, Sect. 2.1-2.4): L1-L5 free, thorax fused to L1, sacrum/pelvis fixed.

Passive intervertebral behaviour: the project's disc, facet and ligament elements at every level
(:func:`lumbar.experiments.fsu.add_level`), from the passive set named by ``passive_set`` (config
``muscle_model.passive_set``, :func:`passive_characteristics`): ``workflow_calibrated`` = the workflow's own
calibration output (role calibration.characteristics, fitted on the passive models' geometry) applied unchanged at
every level (ligament laws on elongation, the same facet and disc shear stiffness: the adopted "as_calibrated" rule of
:mod:`lumbar.experiments.level_transfer`), ``published_table3`` = paper 1's published Table 3 set as printed
(data/characteristics, set "calibrated" there), or a literature set by name. With ``symmetric_passive`` (default, config
``muscle_model.symmetric_passive``) the geometry is first mirror-averaged about y = 0
(:func:`lumbar.geometry.symmetry.mirror_average`: left/right partner points averaged, midline points
projected to y = 0, disc centres/normals and body centroids on the plane) and the segment COMs are put on
y = 0, so that with the mirrored fascicles the model is exactly bilateral (the myo-sim landmarks are not:
midline ligament insertions snapped to mesh vertices off y = 0, lateral force up to 7 N on a level at rest). Muscles: the 210 MyoTorso fascicles
(:mod:`lumbar.muscles`), Hill-type without tendon compliance. Upper-body weights: de Leva (1996) fractions
for a ``body_mass_kg`` body plus the MyoTorso lumbar slice masses (``data/anthropometry``). Activities
(paper Sect. 2.4): thorax sagittal rotation targets and the 190 N crate held 25 / 55 cm anterior to the
L5-S1 disc, applied to the L1+thorax body. The redundancy solver is :mod:`lumbar.muscles.redundancy`.

One passive model per level (same bodies) gives each level's intervertebral load and its exact
derivative; their sum is the spine. Muscle forces are constant-tension cables per path segment (exact
geometric stiffness from :class:`lumbar.mechanics.model.SpineModel`, tension per scenario through ``fmask``) plus
the rank-one tension-stiffness term ``-dT/dL g g^T`` added here.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs import resources
from ..inputs.tables import MUSCLE_SENSITIVITY_PARAMETERS
from ..mechanics import so3
from ..experiments.fsu import add_level, disc_frame, facet_surfaces
from ..geometry.core import LEVEL_NAMES
from ..mechanics.model import SpineModel
from .nlp import IpoptPostureSolver
from .muscle_set import ABDOMINALS, EXTENSORS, GROUPS, SCENARIOS, MuscleSet, load_muscle_set
from .paths import N_PER_CM2, MusclePaths, baseline_properties

log = logging.getLogger(__name__)

G = 9.81
FREE = ("L1", "L2", "L3", "L4", "L5")
DATA = resources.data_dir()
LENGTH_SCALE = 0.05   # m, moments -> forces in the FSU-load cost
PROP_FIELDS = ("spt_pa", "k_pa", "ssl_um", "in_situ_sl_um", "pennation_rad")
IN_SITU_POSTURES = ("reference", "standing")   # where the fascicles have their in-situ sarcomere length


@dataclass(frozen=True)
class Activity:
    name: str
    thorax_flexion_deg: float
    crate_n: float = 0.0
    crate_anterior_m: float = 0.0
    in_vivo_row: str = ""
    note: str = ""


ACTIVITIES = {
    "extension_19deg": Activity("extension_19deg", -19.0, in_vivo_row="extension_20deg",
                                note="in vivo: about 20 deg extension"),
    "upright_standing": Activity("upright_standing", 0.0, in_vivo_row="relaxed_standing"),
    "crate_close": Activity("crate_close", 0.0, 190.0, 0.25, "crate_close_chest",
                            note="in vivo: 20 kg crate close to the chest (distance not stated)"),
    "crate_far": Activity("crate_far", 0.0, 190.0, 0.55, "crate_far_60cm",
                          note="in vivo: crate about 60 cm in front of the body; model 55 cm as in the paper"),
    "flexion_36deg": Activity("flexion_36deg", 36.0, in_vivo_row="flexion_36deg",
                              note="in vivo trunk flexion includes hip flexion; here all of it is lumbar (pelvis fixed)"),
}


def get_activity(name) -> Activity:
    if isinstance(name, Activity):
        return name
    if name not in ACTIVITIES:
        raise ValueError(f"unknown activity {name!r} (field 'activity'); expected one of {sorted(ACTIVITIES)}")
    return ACTIVITIES[name]


def read_anthropometry(path=None) -> pd.DataFrame:
    path = Path(path) if path is not None else DATA / "anthropometry" / "upper_body_segments.csv"
    from lumbar.inputs.tables import read_kind  # noqa: PLC0415
    read_kind(path, "anthropometry")   # schema: file, row, column and expected form of a bad cell
    df = pd.read_csv(path)
    for i, r in df.iterrows():
        if r["body"] not in FREE:
            raise ValueError(f"{path} row {i + 2}: body {r['body']!r} must be one of {FREE}")
        has_f, has_m = pd.notna(r["mass_fraction"]), pd.notna(r["mass_kg_fixed"])
        if has_f == has_m:
            raise ValueError(f"{path} row {i + 2}: give exactly one of mass_fraction, mass_kg_fixed")
        v = r["mass_fraction"] if has_f else r["mass_kg_fixed"]
        if not v > 0:
            raise ValueError(f"{path} row {i + 2}: segment mass must be > 0, got {v}")
    return df


class PointForces:
    """Opaque container (numpy treats it as a scalar, so it passes through ``lumbar.mechanics.solve`` params)."""

    def __init__(self, items):
        self.items = list(items)

    def __iter__(self):
        return iter(self.items)


#: the passive sets of the muscle model that are not a literature set's own name (config muscle_model.passive_set)
PASSIVE_SETS = {
    "workflow_calibrated": "the workflow's calibrated set (role calibration.characteristics: fitted on the passive "
                           "models' geometry), applied unchanged at every level (laws on elongation)",
    "published_table3": "paper 1's published Table 3 set as printed (data/characteristics, set 'calibrated' there)",
}


def passive_set_names() -> tuple:
    """Every value ``muscle_model.passive_set`` accepts: :data:`PASSIVE_SETS` and the literature sets."""
    from ..inputs.characteristics import CHARACTERISTIC_SETS  # noqa: PLC0415

    return tuple(PASSIVE_SETS) + tuple(n for n in CHARACTERISTIC_SETS if n != "calibrated")


def passive_characteristics(passive_set, data_dir=None, calibrated_dir=None):
    """The characteristic set of the muscle model's passive spine (every level the same, as paper 1's L2-S1 model).

    ``workflow_calibrated``: the tables in ``calibrated_dir`` (the workflow's calibration output, which must exist:
    no silent fall-back to the published values); ``published_table3``: the set "calibrated" of ``data_dir``
    (data/characteristics: paper 1's Table 3 as printed); a literature set name: that set from ``data_dir``.
    """
    from ..inputs.characteristics import default_data_dir, load_characteristic_set  # noqa: PLC0415

    names = passive_set_names()
    if passive_set not in names:
        hint = " ('calibrated' is ambiguous here: say which)" if passive_set == "calibrated" else ""
        raise ValueError(f"muscle_model.passive_set: unknown passive set {passive_set!r}{hint}; expected one of "
                         f"{', '.join(names)}")
    if passive_set == "workflow_calibrated":
        if calibrated_dir is None or not (Path(calibrated_dir) / "disc.csv").is_file():
            raise FileNotFoundError(f"muscle_model.passive_set = workflow_calibrated: no calibration output in "
                                    f"{calibrated_dir} (expected disc.csv, facet.csv and the ligament tables written "
                                    f"by rule calibrate, characteristics.calibrated_dir)")
        return load_characteristic_set("calibrated", data_dir=calibrated_dir)
    d = data_dir if data_dir is not None else default_data_dir()
    return load_characteristic_set("calibrated" if passive_set == "published_table3" else passive_set, data_dir=d)


class LumbarMuscleModel:
    """Bodies, passive levels, muscles and weights; ``evaluate`` is the equilibrium residual + Jacobian."""

    def __init__(self, geometry=None, charset=None, muscle_set: MuscleSet | None = None, body_mass_kg=71.0,
                 anthropometry_csv=None, iap_force_n=0.0, passive_set="published_table3", data_dir=None,
                 calibrated_dir=None, symmetric_passive=True, in_situ_posture="reference"):
        from ..geometry import load_geometry
        from ..geometry.symmetry import mirror_average
        if not body_mass_kg > 0:
            raise ValueError(f"body_mass_kg must be > 0, got {body_mass_kg}")
        if not iap_force_n >= 0:
            raise ValueError(f"iap_force_n must be >= 0, got {iap_force_n}")
        if in_situ_posture not in IN_SITU_POSTURES:
            raise ValueError(f"in_situ_posture must be one of {IN_SITU_POSTURES}, got {in_situ_posture!r}")
        self.geo = geometry if geometry is not None else load_geometry("default")
        self.symmetric_passive = bool(symmetric_passive)
        if self.symmetric_passive:
            # passive elements (and body reference points) mirror-averaged about y = 0: the muscles are
            # already bilateral (load_muscle_set), so the whole model is mirror-symmetric
            self.geo = mirror_average(self.geo)
        self.passive_set = "given" if charset is not None else passive_set
        self.charset = charset if charset is not None else passive_characteristics(passive_set, data_dir,
                                                                                   calibrated_dir)
        self.ms = muscle_set if muscle_set is not None else load_muscle_set()
        self.nb = len(FREE)
        cents = np.array([self.geo.vertebrae[v].centroid for v in FREE])
        self.c = cents
        self.body_index = {v: i for i, v in enumerate(FREE)} | {"S1": -1}

        def bodies(m):
            for v in FREE:
                m.add_body(v, self.geo.vertebrae[v].centroid)
            m.add_body("S1", self.geo.vertebrae["S1"].centroid, fixed=True)

        self.levels = list(LEVEL_NAMES)
        self.level_models = []
        self.facet_sides = []              # per level: the side of each facet surface, in surface order
        for lv in self.levels:
            m = SpineModel()
            bodies(m)
            _, sides = add_level(m, self.geo.levels[lv], self.charset)
            self.level_models.append(m.finalize())
            self.facet_sides.append(list(sides))
        self.paths = MusclePaths(self.ms, self.body_index, cents)
        cab = SpineModel()
        bodies(cab)
        for k in range(self.paths.ns):
            cab.add_fibre_group(f"{self.ms.names[self.paths.seg_m[k]]}_{k}", "muscle", "", int(self.paths.seg_a[k]),
                                int(self.paths.seg_b[k]), self.paths.sa[k], self.paths.sb[k], 0.0, "cable", (1.0,))
        self.cables = cab.finalize()
        self.l_ref = self.paths.reference_lengths(self.nb)
        self.props = baseline_properties(self.ms, self.l_ref)
        # weights: (body, force (3,), reference point (3,))
        self.body_mass_kg = body_mass_kg
        self.segments = self._segments(read_anthropometry(anthropometry_csv))
        self.iap_force_n = iap_force_n
        self.thorax = 0
        self.l5s1_centre = np.asarray(self.geo.levels["L5-S1"].disc_centre, float)
        self.in_situ_posture = in_situ_posture
        if in_situ_posture == "standing":
            self.anchor_in_situ("upright_standing")

    def anchor_in_situ(self, activity="upright_standing", iterations=2):
        """Give every fascicle its in-situ sarcomere length in the solved ``activity`` posture instead of the
        as-segmented reference pose (the paper's model has the multifidus at its in-situ 2.27 um in upright
        standing, Sect. 3.2.2): the path lengths of that solution become ``l_ref``. The solution depends a
        little on ``l_ref`` (active force-length), so this is repeated ``iterations`` times."""
        solver = make_solver(self, {"multistart": False})   # one start: the SQP optimum, IPOPT-certified
        for _ in range(iterations):
            sol = solve_postures(self, solver, [activity])[0]
            if not sol.converged:
                raise RuntimeError(f"in-situ posture {activity!r} did not converge: {sol.message}")
            L, _ = self.paths.lengths(sol.x[None], sol.R[None], gradient=False)
            self.l_ref = L[0].copy()
            self.props = self.props.with_(l_ref_m=L[0].copy())
        return sol

    def _segments(self, df):
        out = []
        for _, r in df.iterrows():
            mass = r["mass_fraction"] * self.body_mass_kg if pd.notna(r["mass_fraction"]) else r["mass_kg_fixed"]
            rule, arg = str(r["com_rule"]).split(":")
            if rule == "mjcf_com":
                com = self.ms.mjcf_bodies[arg][1]
            elif rule == "shoulder_drop":
                com = self.ms.mjcf_bodies["Arm_attachment"][1] - np.array([0, 0, float(arg)])
            else:
                raise ValueError(f"unknown com_rule {r['com_rule']!r} in the anthropometry table")
            com = np.array(com, float)
            if self.symmetric_passive:
                com[1] = 0.0        # MyoTorso COMs are within 0.15 mm of y = 0; exactly on it when symmetric
            out.append((r["segment"], self.body_index[r["body"]], float(mass), com))
        return out

    # ------------------------------------------------------------------ loads
    def point_forces(self, activity):
        """Weights, crate and IAP: a :class:`PointForces` of (body, force (3,), reference point (3,), follower)."""
        f = [(b, np.array([0, 0, -m * G]), com, False) for _, b, m, com in self.segments]
        act = get_activity(activity)
        if act.crate_n:
            z = self.segments[1][3][2]
            p = np.array([self.l5s1_centre[0] + act.crate_anterior_m, 0.0, z])
            f.append((self.thorax, np.array([0, 0, -act.crate_n]), p, False))
        return PointForces(f + list(self.follower_forces()))

    def follower_forces(self):
        """The intra-abdominal pressure force (``iap_force_n``, follower on the thorax, below the diaphragm
        centre anterior to L1) as a :class:`PointForces`; empty when off. Passed to the solver as ``forces``
        beside the per-activity arrays of :meth:`load_arrays`."""
        if not self.iap_force_n:
            return PointForces([])
        p = self.c[0] + np.array([0.06, 0, 0.05])
        return PointForces([(self.thorax, np.array([0, 0, self.iap_force_n]), p, True)])

    def upper_body_weight_n(self):
        return sum(m for _, _, m, _ in self.segments) * G

    # ------------------------------------------------------------------ evaluation
    # ------------------------------------------------------------------ per-scenario inputs
    def load_arrays(self, activities):
        """Point loads of each activity as arrays: forces (B, nf, 3) [N] and points (B, nf, 3) [m] on the
        bodies ``self.load_bodies`` (weights, crate slot with 0 N when there is no crate); the IAP follower
        force is :meth:`follower_forces`."""
        segs = self.segments
        nf = len(segs) + 1
        F = np.zeros((len(activities), nf, 3))
        P = np.zeros((len(activities), nf, 3))
        for i, act in enumerate(activities):
            act = get_activity(act)
            for k, (_, b, mass, com) in enumerate(segs):
                F[i, k, 2] = -mass * G
                P[i, k] = com
            P[i, -1] = [self.l5s1_centre[0] + act.crate_anterior_m, 0.0, segs[1][3][2]]
            F[i, -1, 2] = -act.crate_n
        return F, P

    @property
    def load_bodies(self):
        return [b for _, b, _, _ in self.segments] + [self.thorax]

    def props_stack(self, props_list):
        """(B, 5, nm) per-scenario muscle properties (spt_pa, k_pa, ssl_um, in_situ_sl_um, pennation_rad)."""
        return np.stack([np.stack([np.broadcast_to(getattr(p, f), (self.ms.n,)) for f in PROP_FIELDS])
                         for p in props_list])

    def properties(self, params):
        """Muscle properties of a batch: ``params["prop_stack"]`` (per scenario), else ``params["props"]``, else
        the baseline."""
        st = params.get("prop_stack")
        if st is None:
            return params.get("props", self.props)
        return self.props.with_(**{f: st[:, k] for k, f in enumerate(PROP_FIELDS)})

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None, levels=False,
                 muscles=False):
        """Residual (B, nb, 6) and Jacobian (B, nb, 6, nb, 6).

        ``params``: ``activation`` (B, nm); muscle properties as ``props`` (one MuscleProperties) or
        ``prop_stack`` (B, 5, nm, see :meth:`props_stack`); point loads as ``force_vec``/``force_pt``
        (B, nf, 3, see :meth:`load_arrays`) or ``forces`` (a :class:`PointForces`). With ``levels=True``
        also returns each level's passive load on its upper vertebra (B, nlev, 6) and its derivative
        (B, nlev, 6, nb, 6) (or None without ``jacobian``); with ``muscles=True`` also a dict of the muscle
        path lengths ``L`` (B, nm), their derivative ``G`` (B, nm, nb, 6) and the active force at full
        activation ``act1`` (B, nm) [N] (what the redundancy solver needs for dQ/da, without evaluating the
        paths twice)."""
        params = params or {}
        B = x.shape[0]
        a = np.broadcast_to(params.get("activation", 0.0), (B, self.ms.n))
        props = self.properties(params)
        Q = np.zeros((B, self.nb, 6)) if loads is None else np.array(loads, float, copy=True)
        J = np.zeros((B, self.nb, 6, self.nb, 6)) if jacobian else None
        if levels:
            FL = np.zeros((B, len(self.levels), 6))
            DL = np.zeros((B, len(self.levels), 6, self.nb, 6)) if jacobian else None
        for k, (lv, m) in enumerate(zip(self.levels, self.level_models)):
            q, j = m.evaluate(x, R, jacobian=jacobian)
            Q += q
            if jacobian:
                J += j
            if levels:
                up = self.body_index[self.geo.levels[lv].upper]
                FL[:, k] = q[:, up]
                if jacobian:
                    DL[:, k] = j[:, up]
        L, Gd = self.paths.lengths(x, R, gradient=True)
        T, dT, act1, _ = props.tension(L, a)
        q, j = self.cables.evaluate(x, R, fmask=T[:, self.paths.seg_m], jacobian=jacobian)
        Q += q
        if jacobian:
            J += j
            g = Gd.reshape(B, self.ms.n, -1)
            J -= (np.swapaxes(g * dT[..., None], 1, 2) @ g).reshape(J.shape)   # sum_m dT_m g_m g_m^T (BLAS)
        if "force_vec" in params:     # fixed-direction point loads on self.load_bodies, all at once
            fv, fp = np.broadcast_to(params["force_vec"], (B,) + np.shape(params["force_vec"])[-2:]), \
                np.broadcast_to(params["force_pt"], (B,) + np.shape(params["force_pt"])[-2:])
            bodies = np.asarray(self.load_bodies, int)
            r = np.einsum("bkij,bkj->bki", R[:, bodies], fp - self.c[bodies])
            tq = np.cross(r, fv)
            jr = so3.hat(fv) @ so3.hat(r) if jacobian else None
            for k, b in enumerate(bodies):                 # a body may carry several loads: add one by one
                Q[:, b, :3] += fv[:, k]
                Q[:, b, 3:] += tq[:, k]
                if jacobian:
                    J[:, b, 3:, b, 3:] += jr[:, k]
        for b, f, s, follower in params.get("forces", ()):
            s = np.broadcast_to(s, (B, 3))
            r = np.einsum("bij,bj->bi", R[:, b], s - self.c[b])
            fw = np.broadcast_to(f, (B, 3)) if not follower else np.einsum("bij,j->bi", R[:, b], f)
            Q[:, b, :3] += fw
            Q[:, b, 3:] += np.cross(r, fw)
            if jacobian:
                if follower:
                    J[:, b, :3, b, 3:] -= so3.hat(fw)
                    J[:, b, 3:, b, 3:] -= so3.hat(np.cross(r, fw))
                else:
                    J[:, b, 3:, b, 3:] += so3.hat(fw) @ so3.hat(r)
        out = (Q, J) + ((FL, DL) if levels else ())
        if muscles:
            out += ({"L": L, "G": Gd, "act1": act1},)
        return out

    def reference_state(self, batch=1):
        x = np.broadcast_to(self.c, (batch, self.nb, 3)).copy()
        R = np.broadcast_to(np.eye(3), (batch, self.nb, 3, 3)).copy()
        return x, R

    def level_loads(self, x, R, jacobian=False):
        """Passive load of each level on its upper vertebra: (B, nlev, 6) (force, moment about the upper
        body's reference point) and optionally its derivative (B, nlev, 6, nb, 6)."""
        B = x.shape[0]
        F = np.zeros((B, len(self.levels), 6))
        D = np.zeros((B, len(self.levels), 6, self.nb, 6)) if jacobian else None
        for k, (lv, m) in enumerate(zip(self.levels, self.level_models)):
            up = self.body_index[self.geo.levels[lv].upper]
            q, j = m.evaluate(x, R, jacobian=jacobian)
            F[:, k] = q[:, up]
            if jacobian:
                D[:, k] = j[:, up]
        return F, D

    def segment_loads(self, x, R) -> pd.DataFrame:
        """Compressive / anterior-shear force and sagittal moment (flexion +) applied to each level's upper
        vertebra, in the disc frame carried by the lower vertebra, about the disc centre (paper Table 1)."""
        F, _ = self.level_loads(x, R)
        rows = []
        for b in range(x.shape[0]):
            for k, lv in enumerate(self.levels):
                lev = self.geo.levels[lv]
                up, lo = self.body_index[lev.upper], self.body_index[lev.lower]
                Rl = R[b, lo] if lo >= 0 else np.eye(3)
                xl = x[b, lo] if lo >= 0 else np.asarray(self.geo.vertebrae[lev.lower].centroid)
                cl = self.c[lo] if lo >= 0 else xl
                pd_ = xl + Rl @ (np.asarray(lev.disc_centre) - cl)
                E = Rl @ disc_frame(lev.disc_normal).T        # columns e1 (anterior), e2 (left), e3 (normal)
                f, mom = F[b, k, :3], F[b, k, 3:]
                md = mom + np.cross(x[b, up] - pd_, f)
                rows.append({"scenario": b, "level": lv, "compressive_n": float(f @ E[:, 2]),
                             "shear_n": float(-f @ E[:, 0]), "moment_nm": float(-md @ E[:, 1]),
                             "lateral_moment_nm": float(-md @ E[:, 0]), "axial_moment_nm": float(-md @ E[:, 2])})
        return pd.DataFrame(rows)

    def thorax_rotation(self, R):
        return so3.log(R[:, self.thorax])

    def muscle_forces(self, x, R, a, props=None):
        props = props or self.props
        L, _ = self.paths.lengths(x, R, gradient=False)
        T, _, act1, pas = props.tension(L, np.atleast_2d(a))
        return L, T, np.atleast_2d(a) * act1, pas, props.sarcomere_length(L)


def group_mask(ms: MuscleSet, scenario) -> np.ndarray:
    """Fascicles a sensitivity scenario (MUL, EXT, EXT+PS, ALL) or a group list applies to."""
    groups = SCENARIOS.get(scenario) if isinstance(scenario, str) else tuple(scenario)
    if groups is None:
        raise ValueError(f"unknown muscle scenario {scenario!r} (field 'scenario'); expected one of {sorted(SCENARIOS)}")
    bad = [g for g in groups if g not in GROUPS]
    if bad:
        raise ValueError(f"unknown muscle group(s) {bad} (field 'groups'); expected some of {GROUPS}")
    return np.isin(ms.groups, groups)


def apply_parameter(props, ms, parameter, value, scenario, ssl_um=None):
    """Props with ``parameter`` (ssl_um, k_n_per_cm2, in_situ_sl_um, spt_n_per_cm2, pennation_deg) set to
    ``value`` for the scenario's fascicles; ``ssl_um`` additionally sets their slack sarcomere length."""
    mask = group_mask(ms, scenario)
    kw = {}
    if parameter == "ssl_um":
        if not value > 0:
            raise ValueError(f"ssl_um must be > 0 um, got {value}")
        kw["ssl_um"] = np.where(mask, value, props.ssl_um)
    elif parameter == "k_n_per_cm2":
        kw["k_pa"] = np.where(mask, value * N_PER_CM2, props.k_pa)
    elif parameter == "in_situ_sl_um":
        kw["in_situ_sl_um"] = np.where(mask, value, props.in_situ_sl_um)
    elif parameter == "spt_n_per_cm2":
        kw["spt_pa"] = np.where(mask, value * N_PER_CM2, props.spt_pa)
    elif parameter == "pennation_deg":
        kw["pennation_rad"] = np.where(mask, np.radians(value), props.pennation_rad)
    else:
        raise ValueError(f"unknown muscle parameter {parameter!r} (field 'parameter'); expected one of "
                         "ssl_um, k_n_per_cm2, in_situ_sl_um, spt_n_per_cm2, pennation_deg")
    if ssl_um is not None and parameter != "ssl_um":
        if not ssl_um > 0:
            raise ValueError(f"ssl_um must be > 0 um, got {ssl_um}")
        kw["ssl_um"] = np.where(mask, ssl_um, props.ssl_um)
    return props.with_(**kw)


__all__ = ["ACTIVITIES", "Activity", "LumbarMuscleModel", "get_activity", "apply_parameter", "group_mask",
           "EXTENSORS", "ABDOMINALS"]


# ====================================================================== study (validation, sensitivity, Sobol)
PARAMETERS = MUSCLE_SENSITIVITY_PARAMETERS        # lumbar.inputs.tables (the rule file names one figure each)
POSTURES = {"standing": "upright_standing", "flexion": "flexion_36deg"}
# what the paper states (Sect. 3.2, original_text); keyed by (parameter, value, ssl_um or None, scope, posture)
PAPER_CHANGES = {
    ("ssl_um", 2.0, None, "MUL", "standing"): "IDP doubled (Sect. 3.2.1)",
    ("ssl_um", 2.0, None, "EXT", "standing"): "IDP x7 (Sect. 3.2.1)",
    ("ssl_um", 2.0, None, "EXT+PS", "standing"): "IDP x10 (Sect. 3.2.1)",
    ("ssl_um", 2.0, None, "MUL", "flexion"): "36 deg flexion not reached (Sect. 3.2.1)",
    ("ssl_um", 2.0, None, "EXT", "flexion"): "36 deg flexion not reached (Sect. 3.2.1)",
    ("ssl_um", 2.0, None, "EXT+PS", "flexion"): "36 deg flexion not reached (Sect. 3.2.1)",
    ("ssl_um", 2.0, None, "ALL", "flexion"): "36 deg flexion not reached (Sect. 3.2.1)",
    ("ssl_um", 3.2, None, "ALL", "standing"): "total IDP unchanged for SSL > 2.8 (Sect. 3.2.1)",
    ("ssl_um", 3.6, None, "ALL", "standing"): "total IDP unchanged for SSL > 2.8 (Sect. 3.2.1)",
    ("k_n_per_cm2", 10.0, None, "ALL", "standing"): "change <= 20% (Sect. 3.2.2)",
    ("k_n_per_cm2", 50.0, None, "ALL", "standing"): "change <= 20% (Sect. 3.2.2)",
    ("k_n_per_cm2", 10.0, None, "ALL", "flexion"): "change <= 20% (Sect. 3.2.2)",
    ("k_n_per_cm2", 50.0, None, "ALL", "flexion"): "change <= 20% (Sect. 3.2.2)",
    ("k_n_per_cm2", 500.0, 2.4, "MUL", "flexion"): "IDP ~1 -> ~2 MPa (Sect. 3.2.2)",
    ("k_n_per_cm2", 1000.0, 2.4, "MUL", "flexion"): "IDP ~1 -> ~3 MPa (Sect. 3.2.2)",
    ("in_situ_sl_um", 3.6, None, "EXT", "standing"): "+79% (0.38 -> 0.68 MPa) (Sect. 3.2.3)",
    ("in_situ_sl_um", 3.6, None, "EXT", "flexion"): "+380% (0.88 -> 3.34 MPa) (Sect. 3.2.3)",
    ("spt_n_per_cm2", 10.0, None, "ALL", "flexion"): "+39% (Sect. 3.2.4)",
    ("spt_n_per_cm2", 10.0, None, "EXT", "standing"): "upright not reached (Sect. 3.2.4)",
    ("spt_n_per_cm2", 5.0, None, "EXT", "standing"): "upright not reached (Sect. 3.2.4)",
    ("spt_n_per_cm2", 5.0, None, "EXT+PS", "standing"): "upright not reached (Sect. 3.2.4)",
    ("spt_n_per_cm2", 5.0, None, "ALL", "standing"): "upright not reached (Sect. 3.2.4)",
    **{("pennation_deg", v, None, s, p): "negligible (Sect. 3.2.5)" for v in (0.0, 7.5, 15.0, 22.5, 30.0)
       for s in ("MUL", "EXT", "EXT+PS", "ALL") for p in ("standing", "flexion")},
}


def idp_parts(compressive_n, moment_nm, area_m2=18e-4):
    """L4-L5 IDP [MPa] and its force and moment parts (paper 2, Sect. 2.4; lumbar.mechanics.idp.idp_paper2)."""
    from ..mechanics.idp import MPA, idp_paper2
    F = np.asarray(compressive_n, float)
    M = np.asarray(moment_nm, float)
    total = idp_paper2(F, M, area_m2=area_m2) / MPA
    force = idp_paper2(F, np.zeros_like(M), area_m2=area_m2) / MPA
    return total, force, total - force


def make_solver(model, cfg=None):
    """RedundancySolver from the config section ``muscle_model.solver`` (weights, iterations, tracking), with
    IPOPT (:class:`lumbar.muscles.nlp.IpoptPostureSolver`) as the certifier of every reached optimum unless
    ``certifier: sqp`` (the SQP's own KKT test, for comparison)."""
    from .redundancy import RedundancySolver, Weights
    cfg = cfg or {}
    keys = ("activation", "fsu_load_per_n2", "tracking_per_deg2", "length_scale_m")
    w = Weights(**{k: cfg[k] for k in keys if k in cfg})
    solver = RedundancySolver(model, w, max_iter=cfg.get("max_iter", 150),
                              max_tracking_deg=cfg.get("max_tracking_deg", 1.0))
    solver.batch_size = int(cfg.get("batch_size", solver.batch_size))
    certifier = cfg.get("certifier", "ipopt")
    if certifier == "ipopt":
        solver.certifier = IpoptPostureSolver(solver, tol=cfg.get("ipopt_tol", 1e-5),
                                              max_iter=cfg.get("ipopt_max_iter", 150))
        solver.multistart = bool(cfg.get("multistart", True))
    elif certifier != "sqp":
        raise ValueError(f"muscle_model.solver.certifier must be 'ipopt' or 'sqp', got {certifier!r}")
    return solver


def model_from_config(cfg: dict, passive_dir) -> LumbarMuscleModel:
    """The model of the config section ``muscle_model`` (``body_mass_kg``, ``passive_set``, ``symmetric_passive``,
    ``in_situ_posture``, ``iap_force_n``), the passive set's tables read from ``passive_dir`` (its folder of declared
    tables, the published or the calibrated one)."""
    d = Path(passive_dir)
    return LumbarMuscleModel(body_mass_kg=cfg["body_mass_kg"], passive_set=cfg["passive_set"], data_dir=d,
                             calibrated_dir=d, symmetric_passive=cfg.get("symmetric_passive", True),
                             in_situ_posture=cfg.get("in_situ_posture", "reference"),
                             iap_force_n=cfg.get("iap_force_n", 0.0))


def write_baseline(sols, names, path) -> Path:
    """The solved baseline postures (:data:`POSTURES`; ``sols`` in the order of ``names``) as one ``.npz``
    (``<posture>_x``, ``_R``, ``_a``), written atomically; :func:`read_baseline` reads it back."""
    base = {}
    for post, name in POSTURES.items():
        s = sols[names.index(name)]
        base.update({f"{post}_x": s.x, f"{post}_R": s.R, f"{post}_a": s.a})
    path = Path(path)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **base)
    tmp.replace(path)
    return path


def read_baseline(path) -> dict:
    """{posture: PostureSolution} of the baseline postures written by :func:`write_baseline` (the start and the
    reference of the sensitivity and Sobol scenarios)."""
    from .redundancy import PostureSolution
    z = np.load(path)
    return {posture: PostureSolution(z[f"{posture}_x"], z[f"{posture}_R"], z[f"{posture}_a"], True, True, 0.0, 0.0,
                                     0.0, 0.0, 0) for posture in POSTURES}


def uncertified_message(what, which, table, statuses=()) -> str | None:
    """The one warning of a job for the reached postures ``which`` whose optimum IPOPT could not certify (None if
    there are none): a reported value (a row of the validation or of the sensitivity study) that may not be the
    optimum; postures the muscles cannot reach are expected outcomes (red stars), counted in the job's summary line.
    The Sobol chunks do not warn: their uncertified samples are kept in the expansion by design and counted in
    sobol_indices.csv (n_uncertified)."""
    if not len(which):
        return None
    why = ", ".join(sorted({str(s) for s in statuses})) or "see ipopt_status"
    return (f"{what}: {len(which)} reached posture(s) whose optimum IPOPT could not certify ({why}; certified=False "
            f"in {table}): read them as equilibria that may not be the optimum. A larger muscle_model.solver."
            "ipopt_max_iter helps where IPOPT was still converging; near the edge of the muscles' capacity it may "
            "stall at any limit")


def solve_postures(model, solver, activities, props_list=None, start=None):
    """Solve the activities (names) as one batch; ``props_list``: per-scenario MuscleProperties;
    ``start``: per-scenario PostureSolution to warm-start from (e.g. the baseline of the same posture)."""
    acts = [get_activity(a) for a in activities]
    F, P = model.load_arrays(acts)
    params = {"force_vec": F, "force_pt": P}
    if model.iap_force_n:
        params["forces"] = model.follower_forces()
    if props_list is not None:
        params["prop_stack"] = model.props_stack(props_list)
    kw = {}
    if start is not None:
        kw = dict(x0=np.stack([s.x for s in start]), R0=np.stack([s.R for s in start]),
                  a0=np.stack([s.a for s in start]))
    return solver.solve_batch([a.thorax_flexion_deg for a in acts], params, **kw)


def solve_with_progress(model, solver, activities, props_list=None, start=None, batch_size=None, label="scenarios"):
    """:func:`solve_postures` in batches of ``batch_size`` scenarios (None: the solver's ``batch_size``, config
    ``muscle_model.solver.batch_size``), logging after each batch the scenarios
    done / total, the elapsed time and an estimate of the remaining time (through this module's logger; the
    workflow scripts send it to the rule's log and the console)."""
    n = len(activities)
    batch_size = int(batch_size or solver.batch_size)
    out, t0 = [], time.perf_counter()
    for k in range(0, n, batch_size):
        sl = slice(k, k + batch_size)
        out += solve_postures(model, solver, list(activities[sl]),
                              None if props_list is None else list(props_list[sl]),
                              None if start is None else list(start[sl]))
        el = time.perf_counter() - t0
        log.info("%s: %d / %d scenarios done, %.0f s elapsed, ~%.0f s remaining (%d reached, %d certified)",
                 label, len(out), n, el, el / len(out) * (n - len(out)), sum(s.reached for s in out),
                 sum(s.certified for s in out))
    return out


def certificate(s) -> dict:
    """The optimality certificate of a solved posture as table columns: ``reached`` (equilibrium, thorax on
    target), ``certified`` (reached and IPOPT's convergence test passed, :mod:`lumbar.muscles.nlp`),
    ``kkt_residual`` (IPOPT's NLP error), ``optimum`` (sqp | ipopt_cold: which start gave the reported optimum)
    and ``other_cost`` (the other start's certified cost, NaN if none; cold solves only)."""
    return {"reached": bool(s.reached), "certified": bool(s.certified), "kkt_residual": float(s.kkt_residual),
            "optimum": s.optimum, "other_cost": float(s.other_cost)}


def read_in_vivo(path) -> pd.DataFrame:
    df = pd.read_csv(path)
    need = {"activity", "idp_mpa", "source", "kind"}
    if need - set(df.columns):
        raise ValueError(f"{path}: missing columns {sorted(need - set(df.columns))}")
    for i, r in df.iterrows():
        if not (np.isfinite(r["idp_mpa"]) and r["idp_mpa"] > 0):
            raise ValueError(f"{path} row {i + 2}: idp_mpa must be > 0 MPa, got {r['idp_mpa']}")
    return df


def flexion_relaxation(model, sols, names):
    """Sum of active and passive extensor (and abdominal active) forces [N] per solved posture, with the
    extensors' sarcomere lengths (PCSA-weighted mean and max [um]) and the PCSA fraction beyond their slack
    sarcomere length (where passive force starts)."""
    rows = []
    ext = np.isin(model.ms.groups, EXTENSORS)
    abd = np.isin(model.ms.groups, ABDOMINALS)
    w = model.props.pcsa_m2[ext]
    for name, s in zip(names, sols):
        _, _, act, pas, sl = model.muscle_forces(s.x[None], s.R[None], s.a)
        se = sl[0, ext]
        rows.append({"activity": name, "extensor_active_n": float(act[0, ext].sum()),
                     "extensor_passive_n": float(pas[0, ext].sum()),
                     "abdominal_active_n": float(act[0, abd].sum()), "converged": s.converged,
                     **certificate(s),
                     "extensor_sl_mean_um": float(np.sum(w * se) / np.sum(w)), "extensor_sl_max_um": float(se.max()),
                     "extensor_pcsa_fraction_beyond_ssl": float(np.sum(w[se > model.props.ssl_um[ext]]) / np.sum(w))})
    return pd.DataFrame(rows)


def _facet_gaps(m, x, R):
    """Smallest gap [m] of each facet surface's contact points (B, n_surfaces); negative = penetration."""
    p, _ = m._attach(x, R, m.k_a, m.k_s)
    P = m._to_body(x, R, m.k_b, p)
    return np.stack([surf.gap(P[:, m.k_surf == sid])[0].min(axis=-1) for sid, surf in enumerate(m.surfaces)],
                    axis=-1)


def face_separation(surface, landmarks) -> float:
    """Mean distance [m] along the joint normal between the two articular faces fitted to a joint's landmarks
    (superior-process and inferior-process surfaces of paper 1 Eq. 4), at the inferior-process landmarks: the joint
    space the landmarks describe (negative: the faces cross, the landmark sets overlap)."""
    def f(c, q):
        p30, p03, p20, p02, p00 = c
        u, v = q[:, 0], q[:, 1]
        return p30 * u**3 + p03 * v**3 + p20 * u**2 + p02 * v**2 + p00

    q = surface.local(landmarks.inferior)
    return float(np.mean(f(surface.coef_inferior, q) - f(surface.coef_superior, q)))


def facet_contact(model, sols, names) -> pd.DataFrame:
    """Facet contact per level, side and solved posture: the total normal contact force [N], the smallest gap of
    the contact points to the contact surface [mm] in the posture and at rest (the as-segmented reference pose;
    negative = the points lie beyond the surface, i.e. a contact preload before any load), the joint space the
    landmarks describe (:func:`face_separation`, [mm]; the lumbar facet joint space is 1.4-2.4 mm,
    data/anatomy) and the facet contact stiffness of the passive set [N/m]. Where the anatomy has the cartilage
    surfaces touching at rest (gap 0), a geometry whose rest gap is far from 0 makes a level's facets engage late
    (gap > 0) or preloaded (gap < 0)."""
    x0, R0 = model.reference_state()
    rows = []
    for lv, m, sides in zip(model.levels, model.level_models, model.facet_sides):
        rest = _facet_gaps(m, x0, R0)[0]
        space = {side: face_separation(surf, fl) for side, fl, surf in facet_surfaces(model.geo.levels[lv])}
        for name, s in zip(names, sols):
            xs, Rs = s.x[None], s.R[None]
            cf, g = m.contact_forces(xs, Rs)[0], _facet_gaps(m, xs, Rs)[0]
            for k, side in enumerate(sides):
                rows.append({"activity": name, "level": lv, "side": side, "contact_n": float(cf[k]),
                             "min_gap_mm": 1e3 * float(g[k]), "rest_min_gap_mm": 1e3 * float(rest[k]),
                             "rest_face_separation_mm": 1e3 * space[side],
                             "facet_stiffness_n_per_m": float(model.charset.facet.stiffness),
                             "reached": bool(s.reached), "passive_set": model.passive_set})
    return pd.DataFrame(rows)


def capacity_check(model, x, R, activity, a=None, props=None) -> pd.DataFrame:
    """Sagittal moment balance of the part above each level at one pose: can the muscles hold it?

    Per level, moments (flexion +, about +y, world frame) about the disc centre at the pose ``x, R``
    (one pose: (nb, 3), (nb, 3, 3)) of everything acting on the vertebrae above the level:
    ``external_moment_nm`` (weights, crate, IAP of ``activity``), ``passive_muscle_moment_nm`` (passive
    fascicle forces), ``active_muscle_moment_nm`` (active forces at activations ``a``, zero without),
    ``intervertebral_moment_nm`` (the level's disc, facets and ligaments). At static equilibrium the four
    sum to zero (``balance_nm``; the levels above act internally). The capacity columns are the largest
    extension and flexion moments the active fascicles can add at a = 1 (each fascicle counted on the side
    its moment arm falls at this pose). ``demand_ratio`` = (external + passive muscle moment) / extension
    capacity: above 1 the fascicles cannot hold the load without the intervertebral tissues or posture
    change; the active capacity scales with specific tension, so ``spt_needed_n_per_cm2`` = mean SpT x
    ``demand_ratio`` is the specific tension at which the extensors alone would just hold it."""
    props = props or model.props
    x, R = np.asarray(x, float)[None], np.asarray(R, float)[None]
    act = get_activity(activity)
    L, Gd = model.paths.lengths(x, R, gradient=True)
    a1 = np.ones((1, model.ms.n))
    _, _, act1, pas = props.tension(L, a1)
    a = np.zeros(model.ms.n) if a is None else np.asarray(a, float)
    F, P = model.load_arrays([act])
    loads = [(b, F[0, k], P[0, k], False) for k, b in enumerate(model.load_bodies)] + list(model.follower_forces())
    FL, _ = model.level_loads(x, R)
    rows = []
    for k, lv in enumerate(model.levels):
        lev = model.geo.levels[lv]
        up, lo = model.body_index[lev.upper], model.body_index[lev.lower]
        above = np.arange(up + 1)          # FREE is ordered L1 (with the thorax) .. L5
        Rl = R[0, lo] if lo >= 0 else np.eye(3)
        cl = model.c[lo] if lo >= 0 else np.asarray(model.geo.vertebrae[lev.lower].centroid)
        xl = x[0, lo] if lo >= 0 else cl
        pd_ = xl + Rl @ (np.asarray(lev.disc_centre) - cl)
        # generalised force of a unit tension on the bodies above (force at x_b, moment about x_b)
        g = -Gd[0][:, above]                                        # (nm, nab, 6)
        unit = g[..., 4] + np.cross(x[0, above] - pd_, g[..., :3])[..., 1]
        unit = unit.sum(axis=1)                                     # (nm,) moment per N of tension
        m_act1 = unit * act1[0]
        ext_cap = float(-m_act1[m_act1 < 0].sum())
        flex_cap = float(m_act1[m_act1 > 0].sum())
        m_pas = float(unit @ pas[0])
        m_act = float(unit @ (a * act1[0]))
        m_ext = 0.0
        for b, f, s, follower in loads:
            if b > up:
                continue
            fw = R[0, b] @ f if follower else np.asarray(f, float)
            pw = x[0, b] + R[0, b] @ (np.asarray(s, float) - model.c[b])
            m_ext += float(np.cross(pw - pd_, fw)[1])
        f, mom = FL[0, k, :3], FL[0, k, 3:]
        m_iv = float((mom + np.cross(x[0, up] - pd_, f))[1])
        demand = m_ext + m_pas
        ratio = demand / ext_cap if ext_cap > 0 else np.inf
        rows.append({"activity": act.name, "level": lv, "external_moment_nm": m_ext,
                     "passive_muscle_moment_nm": m_pas, "active_muscle_moment_nm": m_act,
                     "intervertebral_moment_nm": m_iv, "balance_nm": m_ext + m_pas + m_act + m_iv,
                     "extension_capacity_nm": ext_cap, "flexion_capacity_nm": flex_cap,
                     "demand_ratio": ratio,
                     "spt_needed_n_per_cm2": float(np.mean(props.spt_pa)) / N_PER_CM2 * ratio})
    return pd.DataFrame(rows)


def capacity_table(model, sols, names) -> pd.DataFrame:
    """:func:`capacity_check` of every solved activity at its own solution (column ``pose``); an activity that
    did not converge is also checked at the pose of a converged activity with the same thorax target (its
    loads on that posture, no activations): what the muscles would need to hold the target posture."""
    out = []
    for name, s in zip(names, sols):
        d = capacity_check(model, s.x, s.R, name, s.a)
        d.insert(1, "pose", "own solution")
        d.insert(2, "converged", s.converged)
        d["reached"], d["certified"], d["kkt_residual"] = s.reached, s.certified, s.kkt_residual
        out.append(d)
        if s.converged:
            continue
        tgt = get_activity(name).thorax_flexion_deg
        for other, so in zip(names, sols):
            if so.converged and get_activity(other).thorax_flexion_deg == tgt:
                d = capacity_check(model, so.x, so.R, name)
                d.insert(1, "pose", f"{other} solution")
                d.insert(2, "converged", s.converged)
                d["reached"], d["certified"], d["kkt_residual"] = so.reached, so.certified, so.kkt_residual
                out.append(d)
                break
    return pd.concat(out, ignore_index=True)


def validation(model, sols, names, in_vivo: pd.DataFrame, area_m2=18e-4):
    """Table 1 analog, Fig. 3 table, metrics and flexion-relaxation from solved activities."""
    seg = []
    for name, s in zip(names, sols):
        d = model.segment_loads(s.x[None], s.R[None]).drop(columns="scenario")
        d.insert(1, "activity", name)
        d["converged"] = s.converged
        for k, v in certificate(s).items():
            d[k] = v
        seg.append(d)
    seg = pd.concat(seg, ignore_index=True)
    l45 = seg[seg["level"] == "L4-L5"].set_index("activity")
    iv = in_vivo.set_index("activity")
    rows = []
    for name, s in zip(names, sols):
        act = get_activity(name)
        tot, fp, mp = idp_parts(l45.loc[name, "compressive_n"], l45.loc[name, "moment_nm"], area_m2)
        r = iv.loc[act.in_vivo_row]
        rows.append({"activity": name, "idp_sim_mpa": float(tot), "idp_force_mpa": float(fp),
                     "idp_moment_mpa": float(mp), "idp_in_vivo_mpa": float(r["idp_mpa"]),
                     "in_vivo_row": act.in_vivo_row, "source": r["source"], "kind": r["kind"],
                     "converged": s.converged, "tracking_error_deg": s.tracking_error_deg, **certificate(s),
                     "note": act.note})
    val = pd.DataFrame(rows)
    ok = val[val["converged"]]
    metrics = {"n": int(len(ok)), "n_total": int(len(val)), "r2": None, "rmse_mpa": None,
               "r2_definition": "squared Pearson correlation (linear fit of simulated vs in-vivo IDP, as the paper)",
               "paper_r2": 0.98}
    for suffix, d in (("", ok), ("_all", val)):
        if len(d) >= 3:
            r = np.corrcoef(d["idp_sim_mpa"], d["idp_in_vivo_mpa"])[0, 1]
            metrics["r2" + suffix] = float(r ** 2)
            metrics["rmse" + suffix + "_mpa"] = float(np.sqrt(np.mean((d["idp_sim_mpa"] - d["idp_in_vivo_mpa"]) ** 2)))
        else:
            metrics["r2" + suffix] = metrics["rmse" + suffix + "_mpa"] = None
    metrics["all_definition"] = ("r2_all, rmse_all_mpa: every activity, including the IDP of postures flagged as "
                                 "not converged (their thorax misses the target; not a model prediction)")
    return seg, val, metrics


# expected direction of each statement in PAPER_CHANGES: "increase" (IDP up by more than the tolerance),
# "unchanged" (|change| within the tolerance [%]) or "not_reached" (the posture cannot be held)
UNCHANGED_PCT = {"change <= 20% (Sect. 3.2.2)": 20.0, "total IDP unchanged for SSL > 2.8 (Sect. 3.2.1)": 10.0,
                 "negligible (Sect. 3.2.5)": 5.0}
INCREASE_MIN_PCT = 5.0


def paper_direction(statement: str) -> str:
    """Direction a PAPER_CHANGES statement asserts: ``not_reached``, ``unchanged`` or ``increase``."""
    if not statement:
        return ""
    if "not reached" in statement:
        return "not_reached"
    if statement in UNCHANGED_PCT:
        return "unchanged"
    return "increase"


def sensitivity_directions(df: pd.DataFrame) -> pd.DataFrame:
    """One row per paper statement (``paper_change`` of the sensitivity table, with ``change_pct``,
    ``converged`` and ``reached``): the direction the paper states, the simulated one and whether they agree.
    A posture not reached (no equilibrium, or the thorax misses its target by more than 1 deg: the paper's
    red star) is ``not_reached``; a reached posture whose optimality the SQP did not certify (``converged``
    False) keeps its direction and is marked in ``certified``. An increase needs more than
    ``INCREASE_MIN_PCT``; "unchanged" statements use their tolerance (``UNCHANGED_PCT``)."""
    rows = []
    for _, r in df[df["paper_change"].fillna("") != ""].iterrows():
        want = paper_direction(r["paper_change"])
        tol = UNCHANGED_PCT.get(r["paper_change"], INCREASE_MIN_PCT)
        ch = float(r["change_pct"])
        reached = bool(r["reached"]) if "reached" in r else bool(r["converged"])
        if not reached:
            got = "not_reached"
        elif ch > tol:
            got = "increase"
        elif ch < -tol:
            got = "decrease"
        else:
            got = "unchanged"
        rows.append({"parameter": r["parameter"], "value": r["value"], "ssl_um": r["ssl_um"],
                     "group_scope": r["group_scope"], "posture": r["posture"], "paper_change": r["paper_change"],
                     "paper_direction": want, "tolerance_pct": tol, "change_pct": ch, "reached": reached,
                     "certified": bool(r["certified"] if "certified" in r else r["converged"]),
                     "kkt_residual": float(r["kkt_residual"]) if "kkt_residual" in r else np.nan,
                     "simulated_direction": got, "agrees": got == want})
    return pd.DataFrame(rows)


def sensitivity_rows(parameter, ssl_um, values, scopes, postures) -> pd.DataFrame:
    """The scenarios of one sensitivity chunk (one Paramspace row: parameter and fixed SSL or none)."""
    if parameter not in PARAMETERS:
        raise ValueError(f"unknown muscle parameter {parameter!r}; expected one of {PARAMETERS}")
    rows = [{"parameter": parameter, "value": float(v), "ssl_um": ssl_um, "group_scope": sc, "posture": p}
            for v in values for sc in scopes for p in postures]
    return pd.DataFrame(rows)


def run_sensitivity(model, solver, rows: pd.DataFrame, baseline: dict, area_m2=18e-4, batch_size=None,
                    label="sensitivity") -> pd.DataFrame:
    """Solve every row (batches of ``batch_size``, progress logged), warm-started from the baseline solution
    of its posture."""
    props, start, names = [], [], []
    for _, r in rows.iterrows():
        ssl = None if pd.isna(r["ssl_um"]) else float(r["ssl_um"])
        props.append(apply_parameter(model.props, model.ms, r["parameter"], r["value"], r["group_scope"], ssl))
        names.append(POSTURES[r["posture"]])
        start.append(baseline[r["posture"]])
    sols = solve_with_progress(model, solver, names, props, start, batch_size, label)
    out = rows.copy()
    seg = [model.segment_loads(s.x[None], s.R[None]).query("level == 'L4-L5'").iloc[0] for s in sols]
    tot, fp, mp = idp_parts([s["compressive_n"] for s in seg], [s["moment_nm"] for s in seg], area_m2)
    out["idp_mpa"], out["idp_force_mpa"], out["idp_moment_mpa"] = tot, fp, mp
    out["converged"] = [s.converged for s in sols]
    out["reached"] = [s.reached for s in sols]
    out["certified"] = [s.certified for s in sols]
    out["kkt_residual"] = [s.kkt_residual for s in sols]
    out["ipopt_status"] = [s.ipopt_status for s in sols]      # why a reached posture is not certified
    out["tracking_error_deg"] = [s.tracking_error_deg for s in sols]
    ext, abd = np.isin(model.ms.groups, EXTENSORS), np.isin(model.ms.groups, ABDOMINALS)
    forces = [model.muscle_forces(s.x[None], s.R[None], s.a, pr)[2:4] for s, pr in zip(sols, props)]
    out["extensor_active_n"] = [float(a[0, ext].sum()) for a, _ in forces]
    out["extensor_passive_n"] = [float(q[0, ext].sum()) for _, q in forces]
    out["abdominal_active_n"] = [float(a[0, abd].sum()) for a, _ in forces]
    out["paper_change"] = [PAPER_CHANGES.get((r["parameter"], float(r["value"]),
                                              None if pd.isna(r["ssl_um"]) else float(r["ssl_um"]),
                                              r["group_scope"], r["posture"]), "")
                           for _, r in out.iterrows()]
    return out


SOBOL_BOUNDS = {"ssl_um": (2.0, 3.6), "k_n_per_cm2": (10.0, 1000.0), "in_situ_sl_um": (2.0, 3.6),
                "spt_n_per_cm2": (5.0, 150.0), "pennation_deg": (0.0, 30.0)}
SOBOL_Q2_MIN = 0.9          # a PCE whose leave-one-out Q2 is below this is flagged (fit_ok False)
SOBOL_STABLE_WIDTH = 0.1    # stable: the top parameter's bootstrap 95 % S1 interval is narrower than this
# Sobol indices from a polynomial chaos surrogate (Sudret 2008; lumbar.muscles.pce), not from Saltelli sampling: SALib's
# Saltelli estimator with N = 16 (112 solves per posture) gave S1 up to 3.1 and 95 % half-widths 0.4-0.5 at
# N = 64; stable S1 would need N ~ 4096 (28 672 solves per posture).
# Default n_train 256, degree 3 (config/config.yaml), measured on 2026-11-23 with the config's model and solver
# (SQP certifier), seed 20261123, 500 bootstrap resamples; n_train 64/128 = the first points of the same design:
#   standing: 241 of 256 reached. degree 3: Q2_loo 0.952, top S1 (SSL) 0.340, interval width 0.040; degree 4:
#             Q2 0.978, width 0.050; degree 2: Q2 0.796. n_train 128, degree 3: Q2 0.933, width 0.099.
#   flexion:  193 of 256 reached. degree 3: Q2 0.960, top S1 (SSL) 0.376, width 0.067; degree 4 (126 terms on
#             193 points): Q2 0.960, width 0.284; degree 2: Q2 0.900. n_train 128, degree 3: Q2 0.957 but width
#             0.304 (98 reached points for 56 terms); n_train 64: width 0.18-0.22 in both postures.
# So degree 3 on 256 points is the smallest design stable in both postures (Q2 > 0.95). Tried and not better at
# n_train 128: hyperbolic (q = 0.75) or two-way-interaction truncation (Q2 0.70-0.93, widths 0.13-0.21: the
# SSL x in-situ SL interaction carries 28 % (standing) / 16 % (flexion) of the variance and needs its cubic
# terms, the SSL x K x in-situ SL term another 3 %) and sparse least squares (orthogonal matching pursuit with
# LOO selection; flexion width 0.17). Inputs stay uniform on the paper's ranges (a log-K input would change the
# question: indices for a log-uniform K). Cost: 2 x 256 solves; measured 1.9 s (standing) and 4.6 s (flexion)
# per solve with the SQP + IPOPT certifier on 2026-11-23; 0.38 s and 1.03 s on 2026-11-24 after the
# speed work (batches of 64, full step first, IPOPT polish from the primal point; benchmarks/bench_muscle_model.py,
# which estimates the whole default study at 282 s on 2 cores, target 300 s). The indices were measured with
#   python -c "import pandas as pd; from lumbar.muscles import muscle_model as mm; m = mm.LumbarMuscleModel(); \
#   s = mm.make_solver(m, {'certifier': 'sqp'}); b = dict(zip(mm.POSTURES, mm.solve_postures(m, s, \
#   list(mm.POSTURES.values())))); X = mm.sobol_samples(256, 20261123); d = pd.concat([mm.sobol_evaluate(m, s, b, \
#   X, range(256), p) for p in b]); [print(n, g, mm.sobol_indices(d[d['sample'] < n], n, g, 20261123)) \
#   for n in (64, 128, 256) for g in (2, 3, 4)]"


def sobol_bounds() -> np.ndarray:
    """(lower, upper) of the five parameters (rows in ``PARAMETERS`` order, each in the units of its name)."""
    return np.array([SOBOL_BOUNDS[p] for p in PARAMETERS], float)


def sobol_samples(n_train: int, seed: int) -> np.ndarray:
    """Training design of the Sobol study: ``n_train`` scrambled Sobol QMC points (scipy.stats.qmc.Sobol,
    seeded; ``n_train`` a power of two) uniform on ``SOBOL_BOUNDS``; columns ``PARAMETERS`` in their units."""
    from . import pce
    b = sobol_bounds()
    return b[:, 0] + pce.qmc_points(n_train, len(PARAMETERS), seed) * (b[:, 1] - b[:, 0])


def sobol_chunk_rows(n_samples: int, n_chunks: int, chunk: int) -> np.ndarray:
    """Row indices of Sobol sample chunk ``chunk`` (0-based) of ``n_chunks`` (contiguous, sizes within one)."""
    if not (0 <= chunk < n_chunks):
        raise ValueError(f"sobol chunk must be in [0, {n_chunks}), got {chunk}")
    return np.array_split(np.arange(n_samples), n_chunks)[chunk]


def sobol_evaluate(model, solver, baseline: dict, X: np.ndarray, rows, posture: str, scope="ALL", area_m2=18e-4,
                   batch_size=None, label="sobol") -> pd.DataFrame:
    """Solve the Sobol samples ``X[rows]`` in ``posture`` (parameters applied to ``scope``, warm-started from
    the baseline), one table row per sample: L4-L5 IDP, reached, certified, KKT residual."""
    if posture not in POSTURES:
        raise ValueError(f"unknown posture {posture!r}; expected one of {sorted(POSTURES)}")
    rows = np.asarray(rows, int)
    props = []
    for x in X[rows]:
        pr = model.props
        for name, v in zip(PARAMETERS, x):
            pr = apply_parameter(pr, model.ms, name, float(v), scope)
        props.append(pr)
    sols = solve_with_progress(model, solver, [POSTURES[posture]] * len(rows), props,
                               [baseline[posture]] * len(rows), batch_size, label)
    seg = [model.segment_loads(s.x[None], s.R[None]).query("level == 'L4-L5'").iloc[0] for s in sols]
    y = idp_parts([s["compressive_n"] for s in seg], [s["moment_nm"] for s in seg], area_m2)[0]
    out = pd.DataFrame({"posture": posture, "sample": rows, "scope": scope})
    for k, name in enumerate(PARAMETERS):
        out[name] = X[rows, k]
    out["idp_mpa"] = np.asarray(y, float)
    out["converged"] = [s.converged for s in sols]
    for key in ("reached", "certified", "kkt_residual"):
        out[key] = [certificate(s)[key] for s in sols]
    out["ipopt_status"] = [s.ipopt_status for s in sols]      # why a reached sample is not certified
    return out


def sobol_indices(samples: pd.DataFrame, n_train: int, degree: int, seed: int, n_bootstrap: int = 500) -> pd.DataFrame:
    """First-order (S1) and total (ST) Sobol indices of L4-L5 IDP per posture from a Legendre polynomial chaos
    expansion of total degree ``degree`` fitted by least squares on the reached samples (all ``n_train`` rows of
    each posture, :func:`sobol_evaluate`); indices analytic from the coefficients (:mod:`lumbar.muscles.pce`).

    Columns: ``S1``, ``ST`` (point estimates from the fit to all reached samples); ``S1_lo``/``S1_hi``,
    ``ST_lo``/``ST_hi`` (bootstrap 95 % percentile interval, ``n_bootstrap`` resamples of the reached samples,
    each refitted); ``q2_loo`` (leave-one-out Q2 of the PCE, hat matrix) and ``fit_ok`` (Q2 >= ``SOBOL_Q2_MIN``);
    ``top_parameter`` (largest S1), ``top_s1_width`` (its S1_hi - S1_lo) and ``stable`` (that width <
    ``SOBOL_STABLE_WIDTH``); ``degree`` (the one fitted: lowered if the reached samples do not exceed the
    number of terms), ``n_terms``, ``n_train``, ``n_fit`` (reached samples), ``n_failed`` (samples whose posture
    is not reached: left out, so the indices are those of the reached part of the parameter box),
    ``n_uncertified`` (reached, KKT residual above the solver's tolerance: kept), ``kkt_residual_max``,
    ``idp_mean_mpa`` and ``idp_sd_mpa`` (mean and standard deviation of the PCE)."""
    from math import comb

    from . import pce
    n = int(n_train)
    rows = []
    order = [q for q in POSTURES if q in set(samples["posture"])]       # standing before flexion
    order += [q for q in dict.fromkeys(samples["posture"]) if q not in order]
    for posture in order:
        d = samples[samples["posture"] == posture].sort_values("sample")
        if list(d["sample"]) != list(range(n)):
            raise ValueError(f"Sobol samples of {posture}: expected rows 0..{n - 1} (n_train {n}), got {len(d)} rows")
        ok = d["reached"].to_numpy(bool)
        U = pce.to_unit(d.loc[ok, list(PARAMETERS)].to_numpy(float), sobol_bounds())
        y = d.loc[ok, "idp_mpa"].to_numpy(float)
        deg = int(degree)
        while deg > 0 and comb(len(PARAMETERS) + deg, deg) >= len(y):
            deg -= 1
        if deg < int(degree):
            log.warning("Sobol %s: %d reached samples do not exceed the %d terms of degree %d: degree %d fitted",
                        posture, len(y), comb(len(PARAMETERS) + int(degree), int(degree)), int(degree), deg)
        nan = np.full(len(PARAMETERS), np.nan)
        if deg > 0:
            r = pce.sobol_analysis(U, y, deg, n_bootstrap, seed)
            f = r["fit"]
            q2, mean, sd = f.q2_loo, f.mean, np.sqrt(f.variance)
        else:
            r = {k: nan for k in ("S1", "S1_lo", "S1_hi", "ST", "ST_lo", "ST_hi")}
            q2, mean, sd = np.nan, float(np.mean(y)) if len(y) else np.nan, np.nan
        top = int(np.nanargmax(r["S1"])) if np.isfinite(r["S1"]).any() else None
        width = float(r["S1_hi"][top] - r["S1_lo"][top]) if top is not None else np.nan
        fit_ok = bool(np.isfinite(q2) and q2 >= SOBOL_Q2_MIN)
        if not fit_ok:
            log.warning("Sobol %s: PCE degree %d leave-one-out Q2 = %.3f < %.2f: the indices are not reliable",
                        posture, deg, q2, SOBOL_Q2_MIN)
        kkt = d.loc[ok, "kkt_residual"]
        for k, name in enumerate(PARAMETERS):
            rows.append({"posture": posture, "parameter": name, "S1": r["S1"][k], "S1_lo": r["S1_lo"][k],
                         "S1_hi": r["S1_hi"][k], "ST": r["ST"][k], "ST_lo": r["ST_lo"][k], "ST_hi": r["ST_hi"][k],
                         "q2_loo": q2, "fit_ok": fit_ok,
                         "top_parameter": PARAMETERS[top] if top is not None else "",
                         "top_s1_width": width, "stable": bool(np.isfinite(width) and width < SOBOL_STABLE_WIDTH),
                         "degree": deg, "n_terms": comb(len(PARAMETERS) + deg, deg), "n_train": n,
                         "n_fit": int(ok.sum()), "n_bootstrap": int(n_bootstrap), "n_failed": int((~ok).sum()),
                         "n_uncertified": int((ok & ~d["certified"].to_numpy(bool)).sum()),
                         "kkt_residual_max": float(kkt.max()) if len(kkt) else np.nan,
                         "idp_mean_mpa": mean, "idp_sd_mpa": sd, "scope": d["scope"].iloc[0]})
    return pd.DataFrame(rows)


def sobol_study(model, solver, baseline: dict, n_train: int, seed: int, degree: int = 3, n_bootstrap: int = 500,
                scope="ALL", postures=("standing", "flexion"), area_m2=18e-4):
    """Variance-based (Sobol) indices of L4-L5 IDP to the five parameters (uniform on the paper's ranges,
    applied to ``scope``) from a polynomial chaos surrogate, per posture, in one process (the workflow runs the
    samples in chunks: :func:`sobol_samples`, :func:`sobol_evaluate`, :func:`sobol_indices`)."""
    X = sobol_samples(n_train, seed)
    samples = pd.concat([sobol_evaluate(model, solver, baseline, X, np.arange(len(X)), p, scope, area_m2)
                         for p in postures], ignore_index=True)
    return sobol_indices(samples, n_train, degree, seed, n_bootstrap)
