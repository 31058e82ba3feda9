"""Muscle-driven lumbar spine (paper 2, Sect. 2.1-2.4): L1-L5 free, thorax fused to L1, sacrum/pelvis fixed.

Passive intervertebral behaviour: the project's disc, facet and ligament elements at every level
(:func:`lumbar.fsu.add_level`, characteristic set selectable). Muscles: the 210 MyoTorso fascicles
(:mod:`lumbar.muscles`), Hill-type without tendon compliance. Upper-body weights: de Leva (1996) fractions
for a ``body_mass_kg`` body plus the MyoTorso lumbar slice masses (``data/anthropometry``). Activities
(paper Sect. 2.4): thorax sagittal rotation targets and the 190 N crate held 25 / 55 cm anterior to the
L5-S1 disc, applied to the L1+thorax body. The redundancy solver is :mod:`lumbar.muscles.redundancy`.

One passive model per level (same bodies) gives each level's intervertebral load and its exact
derivative; their sum is the spine. Muscle forces are constant-tension cables per path segment (exact
geometric stiffness from :class:`lumbar.model.SpineModel`, tension per scenario through ``fmask``) plus
the rank-one tension-stiffness term ``-dT/dL g g^T`` added here.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from . import so3
from .fsu import add_level, disc_frame
from .geometry.core import LEVEL_NAMES
from .model import SpineModel
from .muscles.muscle_set import ABDOMINALS, EXTENSORS, GROUPS, SCENARIOS, MuscleSet, load_muscle_set
from .muscles.paths import N_PER_CM2, MusclePaths, baseline_properties

G = 9.81
FREE = ("L1", "L2", "L3", "L4", "L5")
DATA = Path(__file__).resolve().parents[2] / "data"
LENGTH_SCALE = 0.05   # m, moments -> forces in the FSU-load cost


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
    """Opaque container (numpy treats it as a scalar, so it passes through ``lumbar.solve`` params)."""

    def __init__(self, items):
        self.items = list(items)

    def __iter__(self):
        return iter(self.items)


class LumbarMuscleModel:
    """Bodies, passive levels, muscles and weights; ``evaluate`` is the equilibrium residual + Jacobian."""

    def __init__(self, geometry=None, charset=None, muscle_set: MuscleSet | None = None, body_mass_kg=71.0,
                 anthropometry_csv=None, iap_force_n=0.0, characteristics="calibrated", data_dir=None):
        from .characteristics import load_characteristic_set
        from .geometry import load_geometry
        if not body_mass_kg > 0:
            raise ValueError(f"body_mass_kg must be > 0, got {body_mass_kg}")
        if not iap_force_n >= 0:
            raise ValueError(f"iap_force_n must be >= 0, got {iap_force_n}")
        self.geo = geometry if geometry is not None else load_geometry("default")
        self.charset = charset if charset is not None else load_characteristic_set(
            characteristics, **({"data_dir": data_dir} if data_dir else {}))
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
        for lv in self.levels:
            m = SpineModel()
            bodies(m)
            add_level(m, self.geo.levels[lv], self.charset)
            self.level_models.append(m.finalize())
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
            out.append((r["segment"], self.body_index[r["body"]], float(mass), np.asarray(com, float)))
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
        if self.iap_force_n:
            p = self.c[0] + np.array([0.06, 0, 0.05])   # below the diaphragm centre, anterior to L1
            f.append((self.thorax, np.array([0, 0, self.iap_force_n]), p, True))
        return PointForces(f)

    def upper_body_weight_n(self):
        return sum(m for _, _, m, _ in self.segments) * G

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, x, R, loads=None, fmask=1.0, cmask=1.0, jacobian=True, params=None):
        """Residual (B, nb, 6) and Jacobian; ``params``: activation (B, nm), props (MuscleProperties),
        forces (list from ``point_forces``)."""
        params = params or {}
        B = x.shape[0]
        a = np.broadcast_to(params.get("activation", 0.0), (B, self.ms.n))
        props = params.get("props", self.props)
        Q = np.zeros((B, self.nb, 6)) if loads is None else np.array(loads, float, copy=True)
        J = np.zeros((B, self.nb, 6, self.nb, 6)) if jacobian else None
        for m in self.level_models:
            q, j = m.evaluate(x, R, jacobian=jacobian)
            Q += q
            if jacobian:
                J += j
        L, Gd = self.paths.lengths(x, R, gradient=True)
        T, dT, _, _ = props.tension(L, a)
        q, j = self.cables.evaluate(x, R, fmask=T[:, self.paths.seg_m], jacobian=jacobian)
        Q += q
        if jacobian:
            J += j
            g = Gd.reshape(B, self.ms.n, -1)
            J -= np.einsum("bm,bmi,bmj->bij", dT, g, g).reshape(J.shape)
        for b, f, s, follower in params.get("forces", ()):
            r = (s - self.c[b]) @ R[:, b].transpose(0, 2, 1)
            fw = np.broadcast_to(f, (B, 3)) if not follower else np.einsum("bij,j->bi", R[:, b], f)
            Q[:, b, :3] += fw
            Q[:, b, 3:] += np.cross(r, fw)
            if jacobian:
                if follower:
                    J[:, b, :3, b, 3:] -= so3.hat(fw)
                    J[:, b, 3:, b, 3:] -= so3.hat(np.cross(r, fw))
                else:
                    J[:, b, 3:, b, 3:] += so3.hat(fw) @ so3.hat(r)
        return Q, J

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
