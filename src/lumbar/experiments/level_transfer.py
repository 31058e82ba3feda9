"""How the calibrated characteristics are carried from the calibrated level to the other lumbar levels, and what
that choice does to their range of motion (rule ``multilevel_validation``).

The adopted transfer is paper 1's for its L2-S1 model: the same disc laws, facet stiffness and ligament laws at every
level, the ligament laws acting on elongation, moments about the project axes. Three other physically motivated
readings of "the same characteristics at another level" are evaluated beside it, so that a reader can see whether
the misses of the other levels against Yamamoto et al. (1989) come from the transfer rule or from something the
model does not have:

* ``ligaments_on_strain``: each ligament group's law acts on the same *strain* of the level's fibres as of the
  calibrated level's (paper 1's own, strain-based laws): its law length is scaled by the level's mean fibre length
  over the calibrated level's.
* ``size_scaled``: the structures keep their *material*, not their structural, stiffness: the disc's axial and shear
  stiffness scale with its cross-section over its height (A / h), its torque laws with A^2 / h (second moment of a
  similar section over the height), the facet contact stiffness with the articular face area (a thin cartilage
  layer: k = E A / t).
* ``disc_frame_loading``: the level is turned so that its disc normal is the project's axial axis, i.e. the moments
  are applied, and the rotations read, about the disc's own axes (the disc law turns with it) rather than about
  the project axes; the lumbosacral disc is the most tilted.

None of these is fitted: every factor comes from the geometry. The readings are results, not calibration targets.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

#: reading name -> one-line description (the results table's ``reading_note``)
READINGS = {
    "as_calibrated": "adopted: the calibrated laws unchanged, ligament laws on elongation, moments about the "
                     "project axes",
    "ligaments_on_strain": "ligament laws on the same strain as at the calibrated level (law length x the level's "
                           "mean fibre length / the calibrated level's)",
    "size_scaled": "disc stiffness x A/h (axial, shear) and x A^2/h (torque), facet stiffness x articular face area, "
                   "each over the calibrated level's",
    "disc_frame_loading": "moments applied and rotations read about each disc's own axes (the level turned so that "
                          "its disc normal is the axial axis)",
}


def face_area(points) -> float:
    """Area [m^2] of the convex hull of (n, 3) points of one articular face, projected on their best-fit plane."""
    from scipy.spatial import ConvexHull  # noqa: PLC0415

    P = np.asarray(points, float)
    c = P.mean(axis=0)
    _, _, vt = np.linalg.svd(P - c)
    return float(ConvexHull((P - c) @ vt[:2].T).volume)


def level_sizes(level) -> dict:
    """Disc cross-section [m^2] and height [m], total articular face area of both facet joints [m^2] and the mean
    reference fibre length [m] of every ligament kind of one geometry level."""
    fibres: dict[str, list] = {}
    for lig in level.ligaments:
        fibres.setdefault(lig.kind, []).append(np.asarray(lig.lengths, float))
    return {"disc_csa": float(level.disc_csa), "disc_height": float(level.disc_height),
            "facet_area": sum(face_area(f.contact_set) for f in level.facets.values()),
            "fibre_length": {k: float(np.concatenate(v).mean()) for k, v in fibres.items()}}


def size_scale_factors(level, reference) -> dict:
    """Factors of the ``size_scaled`` reading for ``level`` relative to the calibrated ``reference`` level."""
    s, r = level_sizes(level), level_sizes(reference)
    return {"disc_axial": (s["disc_csa"] / s["disc_height"]) / (r["disc_csa"] / r["disc_height"]),
            "disc_torque": (s["disc_csa"] ** 2 / s["disc_height"]) / (r["disc_csa"] ** 2 / r["disc_height"]),
            "facet": s["facet_area"] / r["facet_area"]}


def size_scaled_set(charset, level, reference, disc_shear_stiffness_n_per_m=None, facet_stiffness_n_per_m=None):
    """The characteristic set with the disc and facet stiffness scaled by :func:`size_scale_factors` (torque law
    amplitudes p1 and p3 scaled, the angle scale p2 kept); ``disc_shear_stiffness_n_per_m`` /
    ``facet_stiffness_n_per_m``: the unit's overrides (None = the set's own)."""
    f = size_scale_factors(level, reference)
    d = charset.disc
    ks = d.k_shear if disc_shear_stiffness_n_per_m is None else disc_shear_stiffness_n_per_m
    kf = charset.facet.stiffness if facet_stiffness_n_per_m is None else facet_stiffness_n_per_m
    torque = {k: (p1 * f["disc_torque"], p2, p3 * f["disc_torque"]) for k, (p1, p2, p3) in d.torque.items()}
    disc = dataclasses.replace(d, torque=torque, k_axial_quadratic=d.k_axial_quadratic * f["disc_axial"],
                               k_axial_linear=d.k_axial_linear * f["disc_axial"],
                               k_shear=None if ks is None else ks * f["disc_axial"])
    facet = dataclasses.replace(charset.facet, stiffness=kf * f["facet"])
    return dataclasses.replace(charset, disc=disc, facet=facet)


def strain_transfer_set(charset, level, reference):
    """The characteristic set with each elongation law's length scaled by the level's mean fibre length over the
    reference level's (the same strain, prestrain included, at every level); laws without a law length (the
    paper's strain form) and kinds absent from either level are left as they are."""
    s, r = level_sizes(level)["fibre_length"], level_sizes(reference)["fibre_length"]
    ligs = {}
    for kind, law in charset.ligaments.items():
        L = getattr(law, "law_length_m", None)
        if L is None or kind not in s or kind not in r:
            ligs[kind] = law
        else:
            ligs[kind] = dataclasses.replace(law, law_length_m=L * (s[kind] / r[kind]))
    return dataclasses.replace(charset, ligaments=ligs)


def sagittal_tilt_deg(level) -> float:
    """Angle [deg] of the disc normal from the project's axial axis in the sagittal plane (positive: the normal
    leans anterior)."""
    n = np.asarray(level.disc_normal, float)
    return float(np.degrees(np.arctan2(n[0], n[2])))


def disc_frame_geometry(geometry, level_name):
    """A geometry holding only ``level_name`` and its two vertebrae, turned rigidly about the disc centre (about the
    lateral axis) so that its disc normal is the project's axial axis; nothing else of the level changes (fibre
    lengths, facet gaps). The out-of-sagittal lean of a disc normal (< 1 deg on the Visible Human levels) is kept."""
    from scipy.spatial.transform import Rotation  # noqa: PLC0415

    lev = geometry.levels[level_name]
    c = np.asarray(lev.disc_centre, float)
    R = Rotation.from_rotvec([0.0, -np.radians(sagittal_tilt_deg(lev)), 0.0]).as_matrix()

    def turn(P):
        return None if P is None else (np.asarray(P, float) - c) @ R.T + c

    ligs = [dataclasses.replace(lig, upper=turn(lig.upper), lower=turn(lig.lower)) for lig in lev.ligaments]
    facets = {side: dataclasses.replace(f, superior=turn(f.superior), inferior=turn(f.inferior),
                                        contact_points=turn(f.contact_points)) for side, f in lev.facets.items()}
    new = dataclasses.replace(lev, disc_normal=R @ np.asarray(lev.disc_normal, float), ligaments=ligs, facets=facets)
    verts = {v: dataclasses.replace(geometry.vertebrae[v], centroid=turn(geometry.vertebrae[v].centroid))
             for v in (lev.upper, lev.lower)}
    return dataclasses.replace(geometry, vertebrae=verts, levels={level_name: new}, similarity=None)


def reading_unit(reading, geometry, charset, level, reference, build, **kw):
    """The unit of ``level`` under one transfer ``reading`` (:data:`READINGS`); ``build(geometry, charset, level,
    **kw)`` is :func:`lumbar.experiments.fsu.build_fsu`; ``reference``: the calibrated level's geometry level."""
    if reading not in READINGS:
        raise ValueError(f"unknown transfer reading {reading!r}; expected one of {sorted(READINGS)}")
    lev = geometry.levels[level]
    if reading == "as_calibrated":
        return build(geometry, charset, level, **kw)
    if reading == "ligaments_on_strain":
        return build(geometry, strain_transfer_set(charset, lev, reference), level, **kw)
    if reading == "size_scaled":
        from .fsu import UNIT_KEYS, unit_options  # noqa: PLC0415
        cs = size_scaled_set(charset, lev, reference, **unit_options(kw))
        return build(geometry, cs, level, **{**kw, **dict.fromkeys(UNIT_KEYS)})
    return build(disc_frame_geometry(geometry, level), charset, level, **kw)


def readings_table(rom_by_reading: dict[str, pd.DataFrame], calibrated_level: str, moment_step_nm=0.25) -> pd.DataFrame:
    """One table of the readings' ROM rows (:func:`lumbar.experiments.validation.multilevel_rom`), with the reading,
    its note, whether the row is the calibrated level (not an independent comparison) and ``snap_through``: the
    curve's largest rotation step, per 0.25 N*m (a coarser ``moment_step_nm`` scaled down, as the admissibility
    criterion does), at least :data:`lumbar.experiments.load_sharing.JUMP_DEG`."""
    from .admissibility import JUMP_STEP_NM  # noqa: PLC0415
    from .load_sharing import JUMP_DEG  # noqa: PLC0415

    out = []
    for reading, rom in rom_by_reading.items():
        t = rom[["level", "direction", "moment_nm", "sim_deg", "measured_deg", "ratio", "within", "converged",
                 "largest_jump_deg"]].copy()
        t.insert(0, "reading", reading)
        t["calibrated_level"] = t["level"] == calibrated_level
        t["snap_through"] = t["largest_jump_deg"] * min(1.0, JUMP_STEP_NM / moment_step_nm) >= JUMP_DEG
        t["reading_note"] = READINGS[reading]
        out.append(t)
    return pd.concat(out, ignore_index=True)


def readings_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per reading: other-level ROM values within the tolerance, of how many, the calibrated level's count, the
    (level, direction) rows with a snap-through or not converged, and the misses (model / measured)."""
    rows = []
    for reading, t in table.groupby("reading", sort=False):
        other, cal = t[~t["calibrated_level"]], t[t["calibrated_level"]]
        rows.append({"reading": reading, "other_within": int(other["within"].sum()), "other_n": len(other),
                     "calibrated_within": int(cal["within"].sum()), "calibrated_n": len(cal),
                     "snap_or_not_converged": int((t["snap_through"] | ~t["converged"]).sum()),
                     "misses": "; ".join(f"{r.level} {r.direction.replace('_one_side', '').replace('_', ' ')} "
                                         f"{r.ratio:.2f}" for r in other[~other["within"]].itertuples()),
                     "reading_note": READINGS[reading]})
    return pd.DataFrame(rows)
