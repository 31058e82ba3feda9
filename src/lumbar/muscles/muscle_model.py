"""Muscle-driven lumbar spine (paper 2, Sect. 2.1-2.4): L1-L5 free, thorax fused to L1, sacrum/pelvis fixed.

Two variants of the passive spine (``passive_model``, config ``muscle_model.passive_model``):

* ``springs`` (the default, the reproduction model): paper 2's own model, one massless 6-DOF spring per level with
  nonlinear rotational and linear translational diagonal terms (:mod:`lumbar.muscles.springs`, values from the
  paper's model code, data/paper2/paper2_model_inputs_third_party.csv), acting where the code attaches it, at the
  upper vertebra's body centre (``spring_point``);
* ``detailed`` (the calibrated passive chain): the project's disc, facet and ligament elements at every level
  (:func:`lumbar.experiments.fsu.add_level`) from the passive set named by ``passive_set`` (config
  ``muscle_model.passive_set``, :func:`passive_characteristics`): ``workflow_calibrated`` = the workflow's own
  calibration output applied unchanged at every level (ligament laws on elongation, the same facet and disc shear
  stiffness: the adopted "as_calibrated" rule of :mod:`lumbar.experiments.level_transfer`), ``published_table3`` =
  paper 1's published Table 3 set as printed, or a literature set by name.

With ``symmetric_passive`` (default) the geometry is first mirror-averaged about y = 0
(:func:`lumbar.geometry.symmetry.mirror_average`) and the segment COMs are put on y = 0, so that with the mirrored
fascicles the model is exactly bilateral. Muscles: the 210 MyoTorso fascicles (:mod:`lumbar.muscles`), Hill-type
without tendon compliance, PCSA = maximum force / 46.6 N/cm^2 as in the paper's model, in-situ sarcomere lengths
(paper 2 Table 2) in solved upright standing (``in_situ_posture``, the paper's multifidus is at 2.27 um in
standing). Upper-body weights: the paper's model code's (``UPPER_BODY_TABLE``; ``DE_LEVA_TABLE``: de Leva (1996)
fractions for a ``body_mass_kg`` body plus the MyoTorso lumbar slice masses). Intra-abdominal pressure: the paper's
model's force on the thorax at its code's point (:meth:`LumbarMuscleModel.follower_forces`, ``iap_point``). Activities (paper Sect. 2.4): thorax sagittal rotation targets and the
190 N crate held 25 / 55 cm anterior to the L5-S1 disc, applied to the L1+thorax body. The redundancy solver is
:mod:`lumbar.muscles.redundancy`.

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
from ..experiments.fsu import add_level, disc_frame
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
#: the upper-body weights of the paper's model code (masses and centres of mass; config ``muscle_model.upper_body_table``)
UPPER_BODY_TABLE = DATA / "paper2" / "paper2_upper_body_third_party.csv"
#: de Leva 1996's segment fractions at MyoTorso's centres of mass (the muscle stage's loads before it took the paper's)
DE_LEVA_TABLE = DATA / "anthropometry" / "upper_body_segments.csv"
IN_SITU_POSTURES = ("reference", "standing")   # where the fascicles have their in-situ sarcomere length
#: where each level's 6-DOF spring acts (config ``muscle_model.spring_point``; springs passive model only)
SPRING_POINTS = {
    "disc_centre": "the disc centre of the myo-sim landmarks, in the disc frame",
    "source": "the paper's model code's point: the upper vertebra's body centre, frames along the project axes",
}
#: where the intra-abdominal pressure force acts (config ``muscle_model.iap_point``)
IAP_POINTS = {
    "stand_in": "the T12 centroid stood in for by the L1 centroid moved up by the L1-L2 centroid spacing, + the "
                "source's anterior offset",
    "source": "the paper's model code's point: its T12 mesh centroid + 0.08 m anterior, on the thorax",
}
#: how each level's passive structures are modelled (config ``muscle_model.passive_model``)
PASSIVE_MODELS = {
    "springs": "paper 2's model (Sect. 2.1): one 6-DOF spring per level, its rotational terms fitted to the intact "
               "L4-L5 unit of the passive set (lumbar.muscles.springs)",
    "detailed": "the project's disc, facet joints and ligaments of the passive set at every level, on the muscle "
                "model's geometry",
}


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
    # the postures of paper 2's rotation check (Sect. 2.4: intervertebral rotations from upright standing against
    # Wong et al. 2004); no in-vivo IDP
    "extension_10deg": Activity("extension_10deg", -10.0, note="rotation check (paper 2 Sect. 2.4)"),
    "flexion_40deg": Activity("flexion_40deg", 40.0, note="rotation check (paper 2 Sect. 2.4)"),
}
#: the activities of the rotation check and the posture their rotations are measured from
ROTATION_CHECK = ("extension_10deg", "flexion_40deg")


def get_activity(name) -> Activity:
    if isinstance(name, Activity):
        return name
    if name not in ACTIVITIES:
        raise ValueError(f"unknown activity {name!r} (field 'activity'); expected one of {sorted(ACTIVITIES)}")
    return ACTIVITIES[name]


def read_anthropometry(path=None) -> pd.DataFrame:
    path = Path(path) if path is not None else UPPER_BODY_TABLE
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


def facet_gaps(m, x, R):
    """Smallest gap [m] of each facet surface's contact points (B, n_surfaces) of a level's model ``m`` in the states
    ``x``, ``R``; negative = the points lie beyond the surface (penetration)."""
    p, _ = m._attach(x, R, m.k_a, m.k_s)
    P = m._to_body(x, R, m.k_b, p)
    return np.stack([surf.gap(P[:, m.k_surf == sid], hessian=False)[0].min(axis=-1) for sid, surf in enumerate(m.surfaces)],
                    axis=-1)


def clear_rest_overlap(m, x0, R0) -> np.ndarray:
    """Move each facet contact surface of a level's model ``m`` whose contact points lie beyond it in the rest state
    (``x0``, ``R0``: the as-segmented pose) along its own normal until the nearest point touches it (rest gap 0);
    surfaces with a positive rest gap are kept. A contact preload before any load is not anatomy: the cartilage
    surfaces of a facet joint touch at rest, they are not pressed into each other (the calibrated Visible Human unit
    has its surfaces "touching", data/landmarks/README.md). Used where the calibrated set is carried onto another
    geometry whose landmarks put the faces into each other (the muscle model's myo-sim levels). Returns the
    distance [m] each surface was moved (0 where kept), in surface order."""
    import dataclasses  # noqa: PLC0415

    g = facet_gaps(m, x0, R0)[0] if m.nc else np.zeros(0)
    moved = np.zeros(len(m.surfaces))
    for sid, surf in enumerate(m.surfaces):
        if g[sid] < -1e-9:                        # below 1 nm: the round-off of a surface already moved
            coef = np.array(surf.coef, float)
            coef[4] += g[sid]                     # w = f(u, v) lowered by the overlap: the rest gap becomes 0
            m.surfaces[sid] = dataclasses.replace(surf, coef=coef)
            moved[sid] = -g[sid]
    return moved


class LumbarMuscleModel:
    """Bodies, passive levels, muscles and weights; ``evaluate`` is the equilibrium residual + Jacobian."""

    def __init__(self, geometry=None, charset=None, muscle_set: MuscleSet | None = None, body_mass_kg=71.0,
                 anthropometry_csv=None, iap_force_n=None, passive_set="published_table3", data_dir=None,
                 calibrated_dir=None, symmetric_passive=True, in_situ_posture="standing", passive_model="springs",
                 pcsa_source_spt_n_per_cm2=None, clear_facet_overlap=True, iap_point="source",
                 spring_point="source"):
        from ..geometry import load_geometry
        from ..geometry.symmetry import mirror_average
        if not body_mass_kg > 0:
            raise ValueError(f"body_mass_kg must be > 0, got {body_mass_kg}")
        from .springs import paper2_iap
        self.iap = paper2_iap()
        if iap_force_n is None:
            iap_force_n = self.iap.force_n
        if not iap_force_n >= 0:
            raise ValueError(f"muscle_model.iap_force_n must be >= 0 N (or null for the source's value), got {iap_force_n}")
        if iap_point not in IAP_POINTS:
            raise ValueError(f"muscle_model.iap_point must be one of {sorted(IAP_POINTS)}, got {iap_point!r}")
        if iap_point == "source" and self.iap.point_from_torso_m is None:
            raise ValueError("muscle_model.iap_point = source: data/paper2/paper2_model_inputs_third_party.csv has no "
                             "rows iap_point_anterior and iap_point_superior (thorax, m)")
        self.iap_point = iap_point
        if spring_point not in SPRING_POINTS:
            raise ValueError(f"muscle_model.spring_point must be one of {sorted(SPRING_POINTS)}, got {spring_point!r}")
        self.spring_point = spring_point
        if in_situ_posture not in IN_SITU_POSTURES:
            raise ValueError(f"in_situ_posture must be one of {IN_SITU_POSTURES}, got {in_situ_posture!r}")
        if passive_model not in PASSIVE_MODELS:
            raise ValueError(f"muscle_model.passive_model must be one of {sorted(PASSIVE_MODELS)}, got "
                             f"{passive_model!r}")
        self.passive_model = passive_model
        self.geo = geometry if geometry is not None else load_geometry("default")
        self.symmetric_passive = bool(symmetric_passive)
        if self.symmetric_passive:
            # passive elements (and body reference points) mirror-averaged about y = 0: the muscles are
            # already bilateral (load_muscle_set), so the whole model is mirror-symmetric
            self.geo = mirror_average(self.geo)
        self.passive_set = "given" if charset is not None else passive_set
        self.charset = charset if charset is not None else passive_characteristics(passive_set, data_dir,
                                                                                   calibrated_dir)
        self.ms = muscle_set if muscle_set is not None else load_muscle_set(source_spt_n_per_cm2=pcsa_source_spt_n_per_cm2)
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
        self.spring_law = None
        spring_points = {}
        if passive_model == "springs":
            from .springs import paper2_spring_law, paper2_spring_points
            self.spring_law = paper2_spring_law()
            if spring_point == "source":
                spring_points = paper2_spring_points()
                if set(spring_points) != set(LEVEL_NAMES):
                    raise ValueError("muscle_model.spring_point = source: data/paper2/paper2_model_inputs_third_party."
                                     f"csv needs spring_point_anterior/superior rows for {list(LEVEL_NAMES)}, has "
                                     f"{sorted(spring_points)}")
        for lv in self.levels:
            m = SpineModel()
            bodies(m)
            if self.spring_law is not None:
                from .springs import add_spring_level
                point = None
                if lv in spring_points:
                    body, a, sup = spring_points[lv]
                    point = self._body_offset(f"lumbar{body[1:]}:{a}:{sup}", f"spring point of {lv}")
                add_spring_level(m, self.geo.levels[lv], self.spring_law, point)
                sides = []
            else:
                _, sides = add_level(m, self.geo.levels[lv], self.charset)
            self.level_models.append(m.finalize())
            self.facet_sides.append(list(sides))
        # the calibrated facets carried onto this geometry: no contact preload at rest (clear_rest_overlap)
        x0 = np.broadcast_to(cents, (1, len(FREE), 3)).copy()
        R0 = np.broadcast_to(np.eye(3), (1, len(FREE), 3, 3)).copy()
        self.facet_surface_moved_m = [clear_rest_overlap(m, x0, R0) if clear_facet_overlap else np.zeros(len(m.surfaces))
                                      for m in self.level_models]
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
            rule, arg = str(r["com_rule"]).split(":", 1)
            if rule == "mjcf_com":
                com = self.ms.mjcf_bodies[arg][1]
            elif rule == "shoulder_drop":
                com = self.ms.mjcf_bodies["Arm_attachment"][1] - np.array([0, 0, float(arg)])
            elif rule == "body_offset":
                com = self._body_offset(arg, r["com_rule"])
            else:
                raise ValueError(f"unknown com_rule {r['com_rule']!r} in the anthropometry table")
            com = np.array(com, float)
            if self.symmetric_passive:
                com[1] = 0.0        # MyoTorso COMs are within 0.15 mm of y = 0; exactly on it when symmetric
            out.append((r["segment"], self.body_index[r["body"]], float(mass), com))
        return out

    def _body_offset(self, arg, text):
        """``body_offset:<MJCF body>:<anterior m>:<superior m>``: a point at that offset from the body's frame
        origin in the upright reference pose (the paper's model code gives its centres of mass so, on the same
        body origins as MyoTorso: ``data/paper2/README.md``)."""
        parts = arg.split(":")
        if len(parts) != 3 or parts[0] not in self.ms.mjcf_origins:
            raise ValueError(f"com_rule {text!r}: expected body_offset:<body>:<anterior m>:<superior m> with a body "
                             f"of {sorted(self.ms.mjcf_origins)}")
        try:
            a, s = float(parts[1]), float(parts[2])
        except ValueError:
            raise ValueError(f"com_rule {text!r}: offsets must be numbers in metres") from None
        return np.asarray(self.ms.mjcf_origins[parts[0]], float) + np.array([a, 0.0, s])

    # ------------------------------------------------------------------ loads
    def point_forces(self, activity):
        """Weights, crate and IAP: a :class:`PointForces` of (body, force (3,), reference point (3,), follower)."""
        f = [(b, np.array([0, 0, -m * G]), com, False) for _, b, m, com in self.segments]
        act = get_activity(activity)
        if act.crate_n:
            z = self.ms.mjcf_bodies["torso"][1][2]     # the crate at the MyoTorso torso COM height
            p = np.array([self.l5s1_centre[0] + act.crate_anterior_m, 0.0, z])
            f.append((self.thorax, np.array([0, 0, -act.crate_n]), p, False))
        return PointForces(f + list(self.follower_forces()))

    def follower_forces(self):
        """The intra-abdominal pressure force (``iap_force_n``; paper 2 Sect. 2.1, point and direction from
        :func:`lumbar.muscles.springs.paper2_iap`): a follower force on the thorax, along its superior axis tilted
        posteriorly, applied anterior to the T12 centroid (stand-in: the L1 centroid moved up by the L1-L2 centroid
        spacing) at its height, as a :class:`PointForces`; empty when off. Passed to the solver as ``forces`` beside
        the per-activity arrays of :meth:`load_arrays`."""
        if not self.iap_force_n:
            return PointForces([])
        if self.iap_point == "source":                     # the source's point: T12 centroid + its offset
            a, s = self.iap.point_from_torso_m
            p = np.asarray(self.ms.mjcf_origins["torso"], float) + np.array([a, 0.0, s])
        else:                                              # stand-in: T12 = L1 centroid + the L1-L2 spacing
            t12 = self.c[0] + (self.c[0] - self.c[1])
            p = t12 + np.array([self.iap.anterior_offset_m, 0.0, 0.0])
        f = self.iap.vector_body() * (self.iap_force_n / self.iap.force_n)
        return PointForces([(self.thorax, f, p, True)])

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
            P[i, -1] = [self.l5s1_centre[0] + act.crate_anterior_m, 0.0, self.ms.mjcf_bodies["torso"][1][2]]
            F[i, -1, 2] = -act.crate_n
        return F, P

    def load_params(self, activities) -> dict:
        """Every external load of the activities as solver ``params``: the per-activity arrays of :meth:`load_arrays`
        (``force_vec``, ``force_pt``) and, when on, the IAP follower force (``forces``): what a residual of this model
        in these activities needs, nothing left out."""
        F, P = self.load_arrays(activities)
        params = {"force_vec": F, "force_pt": P}
        if self.iap_force_n:
            params["forces"] = self.follower_forces()
        return params

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


# ====================================================================== what the studies share (the studies:
# lumbar.muscles.muscle_validation, the in-vivo validation; lumbar.muscles.muscle_sensitivity, sensitivity and Sobol)
PARAMETERS = MUSCLE_SENSITIVITY_PARAMETERS        # lumbar.inputs.tables (the rule file names one figure each)
POSTURES = {"standing": "upright_standing", "flexion": "flexion_36deg"}


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
                                              max_iter=cfg.get("ipopt_max_iter", 50))
        solver.multistart = bool(cfg.get("multistart", True))
        solver.handover_window = int(cfg.get("handover_window", 10))
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
                             in_situ_posture=cfg.get("in_situ_posture", "standing"),
                             iap_force_n=cfg.get("iap_force_n"), passive_model=cfg.get("passive_model", "springs"),
                             pcsa_source_spt_n_per_cm2=cfg.get("pcsa_source_spt_n_per_cm2"),
                             anthropometry_csv=cfg.get("upper_body_table"),
                             iap_point=cfg.get("iap_point", "source"),
                             spring_point=cfg.get("spring_point", "source"))


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
    The Sobol chunks do not warn: their uncertified samples are left out of the expansion and counted in
    sobol_indices.csv (n_uncertified)."""
    if not len(which):
        return None
    why = ", ".join(sorted({str(s) for s in statuses})) or "see ipopt_status"
    return (f"{what}: {len(which)} reached posture(s) whose optimum IPOPT could not certify ({why}; certified=False "
            f"in {table}): read them as equilibria that may not be the optimum. A larger muscle_model.solver."
            "ipopt_max_iter helps where IPOPT was still converging; near the edge of the muscles' capacity, or where "
            "the cost leaves the posture's distribution over the levels almost free (upright standing on the "
            "calibrated passive set: docs/findings.md), it stalls at any limit")


def solve_postures(model, solver, activities, props_list=None, start=None):
    """Solve the activities (names) as one batch; ``props_list``: per-scenario MuscleProperties;
    ``start``: per-scenario PostureSolution to warm-start from (e.g. the baseline of the same posture)."""
    acts = [get_activity(a) for a in activities]
    params = model.load_params(acts)
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
