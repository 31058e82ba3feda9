"""The 210 lumbar fascicles of myo-sim's MyoTorso (Christophy et al. 2012 lineage), in the project frame.

Read at run time from the installed ``myo-sim`` package (compiled with MuJoCo, qpos0): for every
``<general>`` actuator its spatial tendon's sites, in path order, each with the MJCF body it is attached to.
Wrapping geoms (cylinders / ellipsoids on 32 paths) are skipped: paths are straight lines through the
sites (their MuJoCo length with wrapping is kept in ``mujoco_length_m`` for comparison).

Frame: the MJCF bodies are placed with the torso root (``Full Body``) removed, i.e. relative to the
``sacrum`` body, which the torso chain rotates by ``euler="pi/2 -pi/2 0"``; then
``p_project = R @ p_chain`` with ``R = [[0,-1,0],[1,0,0],[0,0,1]]`` (lumbar.geometry.myo_sim), so the sites
sit on the same meshes the geometry module loads (checked in tests/test_muscles.py).

Bodies: sacrum (which carries the pelvis sites) -> fixed ``S1``; ``lumbar1``..``lumbar5`` -> ``L1``..``L5``;
``torso`` (thorax, ribs) and everything above -> ``L1`` (the "L1+thorax" body); ``Abdomen`` (a child of
lumbar5 in the MJCF) -> ``L5``, its kinematic parent.

Per fascicle: ``f_max_n`` = MJCF ``gainprm[2]`` (peak active force; 1.02-1.14 x Christophy et al. 2012's
maximum forces for the back muscles); PCSA = f_max / 46.6 N/cm^2, the specific tension Christophy's maximum forces are
read with in the paper's own model code (data/paper2/paper2_model_inputs_third_party.csv), so that the paper's SpT =
K = 100 N/cm^2 give the paper's muscles (read as f_max / 100 N/cm^2 before: muscles 2.15x weaker, passive force
too). Group, in-situ sarcomere
length, pennation and fibre ratio from ``data/muscles/muscle_groups.csv``. The MJCF's MuJoCo muscle ranges
do not give a physical optimal fibre length, so it is derived (see :mod:`lumbar.muscles.paths`):
``L_opt = fibre_ratio * L_path(reference) * 2.8 um / SL_in_situ`` (Christophy's normalisation).
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..inputs import resources
from ..geometry.myo_sim import R_PROJECT_FROM_WORLD, package_version

GROUPS = ("MF", "IL", "LT", "QL", "Ps", "EO", "IO", "RA")
EXTENSORS = ("MF", "IL", "LT", "QL")
ABDOMINALS = ("EO", "IO", "RA")
SCENARIOS = {"MUL": ("MF",), "EXT": EXTENSORS, "EXT+PS": EXTENSORS + ("Ps",), "ALL": GROUPS}
BODY_MAP = {"sacrum": "S1", "lumbar1": "L1", "lumbar2": "L2", "lumbar3": "L3", "lumbar4": "L4",
            "lumbar5": "L5", "torso": "L1", "Abdomen": "L5"}
OPTIMAL_SL_UM = 2.8                    # Delp et al. 2001 (paper Sect. 2.5)
DATA_DIR = resources.data_dir() / "muscles"


@dataclass
class MuscleSet:
    names: list
    groups: np.ndarray           # (nm,) str
    sides: np.ndarray            # (nm,) "left"/"right"
    sites: list                  # per muscle: list of (body name in the project, (3,) point) in path order
    f_max_n: np.ndarray          # (nm,)
    pcsa_m2: np.ndarray
    in_situ_sl_um: np.ndarray
    pennation_rad: np.ndarray
    fibre_ratio: np.ndarray
    mujoco_length_m: np.ndarray
    source: str = ""
    mjcf_bodies: dict = field(default_factory=dict)   # MJCF body -> (mass, com (3,) project frame)
    mjcf_origins: dict = field(default_factory=dict)  # MJCF body -> its frame origin (3,), project frame
    symmetrized: list = field(default_factory=list)   # left fascicles replaced by the mirrored right one

    @property
    def n(self) -> int:
        return len(self.names)

    def table(self) -> pd.DataFrame:
        return pd.DataFrame({"name": self.names, "group": self.groups, "side": self.sides,
                             "f_max_n": self.f_max_n, "pcsa_cm2": self.pcsa_m2 * 1e4,
                             "in_situ_sl_um": self.in_situ_sl_um,
                             "pennation_deg": np.degrees(self.pennation_rad), "fibre_ratio": self.fibre_ratio,
                             "n_sites": [len(s) for s in self.sites],
                             "bodies": ["/".join(b for b, _ in s) for s in self.sites],
                             "mujoco_length_m": self.mujoco_length_m,
                             "note": ["sites = mirror of the right fascicle (MJCF not symmetric)"
                                      if n in self.symmetrized else "" for n in self.names],
                             "source": self.source})


def read_group_table(path=None) -> pd.DataFrame:
    path = Path(path) if path is not None else DATA_DIR / "muscle_groups.csv"
    from lumbar.inputs.tables import read_kind  # noqa: PLC0415
    read_kind(path, "muscle_groups")   # schema: file, row, column and expected form of a bad cell
    df = pd.read_csv(path)
    need = {"prefix", "group", "in_situ_sl_um", "pennation_deg", "fibre_ratio"}
    miss = need - set(df.columns)
    if miss:
        raise ValueError(f"{path}: missing columns {sorted(miss)}")
    for i, r in df.iterrows():
        if r["group"] not in GROUPS:
            raise ValueError(f"{path} row {i + 2}: unknown group {r['group']!r} (column 'group'); expected one of {GROUPS}")
        if not (r["in_situ_sl_um"] > 0):
            raise ValueError(f"{path} row {i + 2}: in_situ_sl_um must be > 0, got {r['in_situ_sl_um']}")
        if not (0 <= r["pennation_deg"] < 90):
            raise ValueError(f"{path} row {i + 2}: pennation_deg must be in [0, 90), got {r['pennation_deg']}")
        if not (0 < r["fibre_ratio"] <= 1):
            raise ValueError(f"{path} row {i + 2}: fibre_ratio must be in (0, 1], got {r['fibre_ratio']}")
    return df


def prefix_of(name: str) -> str:
    return re.split(r"[_\d]", name)[0]


@functools.lru_cache(maxsize=2)
def _compiled():
    import mujoco  # noqa: PLC0415
    import myo_sim  # noqa: PLC0415
    m = myo_sim.load_model("myotorso")
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return m, d


def _to_project(m, d):
    """Function mapping MuJoCo world points to the project frame (sacrum-rooted chain, then R)."""
    sac = m.body("sacrum").id
    R_chain_sac = Rotation.from_euler("XYZ", [np.pi / 2, -np.pi / 2, 0]).as_matrix()
    xs, Xs = d.xpos[sac].copy(), d.xmat[sac].reshape(3, 3).copy()
    A = R_PROJECT_FROM_WORLD @ R_chain_sac @ Xs.T
    return lambda p: (np.asarray(p) - xs) @ A.T


def _symmetrize(names, sites) -> list:
    """Make every left fascicle the mirror image (y -> -y) of its right partner where the MJCF is not.

    myo-sim 0.2.4 has two such pairs: ``LTpT_T12_l`` repeats the right fascicle's sites unmirrored, and
    ``QL_mid_L2-12.1_l`` runs between other bodies than its right partner. The paper's activities are
    symmetric, so the model keeps bilateral symmetry; the replaced names are listed in ``symmetrized``.
    """
    fixed = []
    for i, n in enumerate(names):
        if not n.endswith("_r") or n[:-2] + "_l" not in names:
            continue
        j = names.index(n[:-2] + "_l")
        mirrored = [(b, p * np.array([1.0, -1.0, 1.0])) for b, p in sites[i]]
        same = (len(mirrored) == len(sites[j]) and all(b == bl for (b, _), (bl, _) in zip(mirrored, sites[j]))
                and all(np.allclose(p, pl, atol=1e-6) for (_, p), (_, pl) in zip(mirrored, sites[j])))
        if not same:
            sites[j] = mirrored
            fixed.append(names[j])
    return fixed


def load_muscle_set(group_table=None, source_spt_n_per_cm2=None) -> MuscleSet:
    """All fascicles of the MyoTorso actuators with their sites (project frame) and parameters; PCSA = maximum force
    / ``source_spt_n_per_cm2`` (the specific tension the source model's maximum forces assume; default
    the paper's model: 46.6 N/cm^2, data/paper2/paper2_model_inputs_third_party.csv)."""
    if source_spt_n_per_cm2 is None:
        from .springs import paper2_pcsa_source_spt_n_per_cm2  # noqa: PLC0415 (the paper-2 inputs table)
        source_spt_n_per_cm2 = paper2_pcsa_source_spt_n_per_cm2()
    spt = float(source_spt_n_per_cm2) * 1e4
    if not spt > 0:
        raise ValueError(f"muscle_model.pcsa_source_spt_n_per_cm2 must be > 0, got {source_spt_n_per_cm2}")
    m, d = _compiled()
    to_p = _to_project(m, d)
    gt = read_group_table(group_table).set_index("prefix")
    names, groups, sides, sites, fmax, mjl = [], [], [], [], [], []
    for a in range(m.nu):
        name = m.actuator(a).name
        pre = prefix_of(name)
        if pre not in gt.index:
            raise ValueError(f"fascicle {name!r}: prefix {pre!r} not in the muscle group table "
                             f"(column 'prefix'); known: {sorted(gt.index)}")
        t = m.actuator_trnid[a, 0]
        pts = []
        for w in range(m.tendon_adr[t], m.tendon_adr[t] + m.tendon_num[t]):
            if m.wrap_type[w] != 3:      # mjWRAP_SITE
                continue
            sid = m.wrap_objid[w]
            body = m.body(m.site_bodyid[sid]).name
            b = body
            while b not in BODY_MAP:
                pid = m.body_parentid[m.body(b).id]
                b = m.body(pid).name
                if b in ("world", ""):
                    raise ValueError(f"site {m.site(sid).name} on body {body!r} has no lumbar ancestor")
            pts.append((BODY_MAP[b], to_p(d.site_xpos[sid])))
        names.append(name)
        groups.append(gt.loc[pre, "group"])
        sides.append("left" if name.endswith("_l") else "right")
        sites.append(pts)
        fmax.append(float(m.actuator_gainprm[a, 2]))
        mjl.append(float(d.ten_length[t]))
    fixes = _symmetrize(names, sites)
    fmax = np.array(fmax)
    if np.any(~(fmax > 0)):
        raise ValueError("MJCF maximum force must be > 0 for every fascicle")
    pref = [prefix_of(n) for n in names]
    bodies, origins = {}, {}
    for b in ("torso", "head", "neck", "lumbar1", "lumbar2", "lumbar3", "lumbar4", "lumbar5", "Arm_attachment"):
        i = m.body(b).id
        bodies[b] = (float(m.body_subtreemass[i] if b == "head" else m.body_mass[i]),
                     to_p(d.xipos[i] if b != "Arm_attachment" else d.xpos[i]))
        origins[b] = to_p(d.xpos[i])
    return MuscleSet(
        names=names, groups=np.array(groups), sides=np.array(sides), sites=sites, f_max_n=fmax,
        pcsa_m2=fmax / spt,
        in_situ_sl_um=np.array([gt.loc[p, "in_situ_sl_um"] for p in pref], float),
        pennation_rad=np.radians([gt.loc[p, "pennation_deg"] for p in pref]),
        fibre_ratio=np.array([gt.loc[p, "fibre_ratio"] for p in pref], float),
        mujoco_length_m=np.array(mjl),
        source=f"myo-sim {package_version()} MyoTorso (Apache-2.0), myotorso_tendon.xml / myotorso_muscle.xml",
        mjcf_bodies=bodies, mjcf_origins=origins, symmetrized=fixes)
