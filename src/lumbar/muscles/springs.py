"""Paper 2's passive spine and abdominal pressure: one massless 6-DOF spring per lumbar level (Sect. 2.1) and the
intra-abdominal pressure (IAP) force on the thorax.

The paper connects adjacent vertebrae by "massless 6-DOF springs ... with a 6 x 6 stiffness matrix for each lumbar
functional spinal unit"; "only diagonal terms of the stiffness matrix were included: translational terms were taken
from one study (Gardner-Morse and Stokes, 2004) while the nonlinear formulations for the rotational terms were adopted
from another (Heuer et al., 2007b)". It prints none of the numbers. They are read from
``data/paper2/paper2_model_inputs_third_party.csv``: the values in the ArtiSynth model code of the paper's group
(kind ``third_party``, every row with its repository, file and commit):

* rotational terms ``T = (p1 |d|^2 + p2 |d| + p3) d`` per anatomical direction (d in degrees, flexion and extension
  apart; the ``cubic_deg`` law of :mod:`lumbar.mechanics.elements.disc`), the same at every level;
* translational terms: linear, anterior-posterior, lateral and axial (both ways: a spring, not a contact);
* the IAP force: a constant magnitude on the thorax, at a point anterior to the T12 (here: L1 + thorax body)
  centroid, along the thorax's superior axis tilted posteriorly, turning with the thorax (a follower force).

Stand-ins, said where they act: the spring acts about the level's disc centre in the disc frame carried by the lower
vertebra (the project's disc element, :class:`lumbar.mechanics.model.DiscSpec`); the paper's text puts its forces "at
the centers of the two vertebrae", the code attaches its frames at intervertebral-joint markers. The IAP point is
taken from the model's thorax body (the L1 + thorax centroid), which is the T12 centroid's stand-in.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs import resources

DATA_CSV = resources.data_dir() / "paper2" / "paper2_model_inputs_third_party.csv"
TORQUE_DIRECTIONS = ("flexion", "extension", "lateral_bending", "axial_rotation")
_NEEDED = [("torque_p1", d) for d in TORQUE_DIRECTIONS] + [("torque_p2", d) for d in TORQUE_DIRECTIONS] + \
    [("torque_p3", d) for d in TORQUE_DIRECTIONS] + \
    [("k_anterior_posterior", "shear"), ("k_lateral", "shear"), ("k_axial", "axial"), ("iap_force", "thorax"),
     ("iap_anterior_offset", "thorax"), ("iap_tilt_posterior", "thorax"), ("pcsa_source_specific_tension", "all")]


@functools.lru_cache(maxsize=4)
def read_model_inputs(path=None) -> pd.DataFrame:
    """The paper-2 model inputs table, checked: every needed (parameter, direction) row once, a finite value, a
    source and a kind. Errors name the file, the row and the expected form."""
    path = Path(path) if path is not None else DATA_CSV
    df = pd.read_csv(path)
    miss = {"parameter", "direction", "value", "unit", "kind", "source"} - set(df.columns)
    if miss:
        raise ValueError(f"{path}: missing columns {sorted(miss)}")
    for i, r in df.iterrows():
        if not np.isfinite(pd.to_numeric(r["value"], errors="coerce")):
            raise ValueError(f"{path} row {i + 2}: column 'value' must be a finite number, got {r['value']!r}")
        if not str(r["source"]).strip() or str(r["kind"]) not in ("original_text", "third_party",
                                                                 "derived_from_published_fit"):
            raise ValueError(f"{path} row {i + 2}: every value needs a source and a kind (original_text, third_party "
                             "or derived_from_published_fit)")
    keys = list(zip(df["parameter"], df["direction"]))
    for k in _NEEDED:
        n = keys.count(k)
        if n != 1:
            raise ValueError(f"{path}: expected exactly one row with parameter={k[0]!r}, direction={k[1]!r}; found {n}")
    return df


def _value(df, parameter, direction) -> float:
    return float(df[(df["parameter"] == parameter) & (df["direction"] == direction)]["value"].iat[0])


@dataclass(frozen=True)
class SpringLaw:
    """The diagonal terms of one level's 6-DOF spring (SI; torque coefficients per degree as the source gives them)."""

    torque: dict                 # direction -> (p1 [N*m/deg^3], p2 [N*m/deg^2], p3 [N*m/deg]), law cubic_deg
    k_anterior_posterior: float  # N/m
    k_lateral: float             # N/m
    k_axial: float               # N/m (compression and tension)

    def __post_init__(self):
        for d, (p1, p2, p3) in self.torque.items():
            dd = np.linspace(0.0, 30.0, 301)
            if np.any(3 * p1 * dd ** 2 + 2 * p2 * dd + p3 <= 0):
                raise ValueError(f"spring torque law {d}: not monotone within 0-30 deg (coefficients {p1}, {p2}, {p3})")
        for k in ("k_anterior_posterior", "k_lateral", "k_axial"):
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"spring stiffness {k} must be a finite value > 0 N/m, got {v}")


@dataclass(frozen=True)
class IapForce:
    force_n: float
    anterior_offset_m: float
    tilt_posterior_deg: float
    point_from_torso_m: tuple | None = None    # (anterior, superior) from the thorax frame origin, when the source gives it

    def vector_body(self) -> np.ndarray:
        """The force in the thorax's body frame (x anterior, z superior): superior, tilted posteriorly."""
        t = np.radians(self.tilt_posterior_deg)
        return self.force_n * np.array([-np.sin(t), 0.0, np.cos(t)])


def paper2_spring_law(path=None) -> SpringLaw:
    df = read_model_inputs(None if path is None else str(path))
    torque = {d: tuple(_value(df, f"torque_p{k}", d) for k in (1, 2, 3)) for d in TORQUE_DIRECTIONS}
    return SpringLaw(torque=torque, k_anterior_posterior=_value(df, "k_anterior_posterior", "shear"),
                     k_lateral=_value(df, "k_lateral", "shear"), k_axial=_value(df, "k_axial", "axial"))


def paper2_iap(path=None) -> IapForce:
    df = read_model_inputs(None if path is None else str(path))
    point = None
    if {"iap_point_anterior", "iap_point_superior"} <= set(df["parameter"]):
        point = (_value(df, "iap_point_anterior", "thorax"), _value(df, "iap_point_superior", "thorax"))
    return IapForce(_value(df, "iap_force", "thorax"), _value(df, "iap_anterior_offset", "thorax"),
                    _value(df, "iap_tilt_posterior", "thorax"), point)


def paper2_spring_points(path=None) -> dict:
    """Where each level's spring acts in the paper's model code: level -> (upper body, anterior m, superior m), the
    offset from the upper vertebra's body origin (about the centre of its vertebral body); empty when the table has
    no such rows."""
    df = read_model_inputs(None if path is None else str(path))
    out = {}
    for lv in df.loc[df["parameter"] == "spring_point_anterior", "direction"]:
        out[lv] = (lv.split("-")[0], _value(df, "spring_point_anterior", lv), _value(df, "spring_point_superior", lv))
    return out


def paper2_pcsa_source_spt_n_per_cm2(path=None) -> float:
    return _value(read_model_inputs(None if path is None else str(path)), "pcsa_source_specific_tension", "all")


def spring_rom_deg(law: SpringLaw, direction, moment_nm) -> float:
    """Rotation [deg] at which the spring's ``direction`` term reaches ``moment_nm`` (the smallest positive root)."""
    p1, p2, p3 = law.torque[direction]
    r = np.roots([p1, p2, p3, -float(moment_nm)])
    r = r[np.isclose(r.imag, 0.0) & (r.real > 0)].real
    return float(r.min())


def add_spring_level(model, level, law: SpringLaw, point=None):
    """One level's 6-DOF spring added to a :class:`lumbar.mechanics.model.SpineModel` (bodies already added): at the
    disc centre in the disc frame, or with ``point`` (3,) [m] at that point in frames along the project axes (the
    paper's model code: its springs act at the upper vertebra's body centre, frames aligned with the world)."""
    from ..experiments.fsu import disc_frame  # noqa: PLC0415 (the FSU helpers, not needed to read the table)
    from ..mechanics.model import DiscSpec  # noqa: PLC0415

    up, lo = model.body_index(level.upper), model.body_index(level.lower)
    centre, frame = np.asarray(level.disc_centre, float), disc_frame(level.disc_normal)
    if point is not None:
        centre, frame = np.asarray(point, float), disc_frame([0.0, 0.0, 1.0])
    model.add_disc(DiscSpec(up, lo, centre, frame,
                            0.0, law.k_axial, law.k_anterior_posterior, law.k_axial, dict(law.torque),
                            name=f"{level.name} spring", law="cubic_deg", k_shear_lateral=law.k_lateral))
