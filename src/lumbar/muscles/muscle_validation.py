"""The muscle model's in-vivo validation (paper 2, Sect. 2.4 and 3.1) and what explains it: the L4-L5 IDP of every
activity against the in-vivo measurements (:func:`validation`), flexion-relaxation (:func:`flexion_relaxation`),
facet contact per level (:func:`facet_contact`) and the sagittal moment capacity (:func:`capacity_check`,
:func:`capacity_table`), on postures solved by :func:`lumbar.muscles.muscle_model.solve_postures`."""
from __future__ import annotations

import numpy as np
import pandas as pd

from ..experiments.fsu import facet_surfaces
from .muscle_model import certificate, facet_gaps, get_activity, idp_parts
from .muscle_set import ABDOMINALS, EXTENSORS
from .paths import N_PER_CM2


def flexion_relaxation(model, sols, names):
    """Sum of active and passive extensor (and abdominal active) forces [N] per solved posture, with the
    extensors' sarcomere lengths (PCSA-weighted mean and max [um]), the multifidus's PCSA-weighted mean sarcomere
    length [um] and the PCSA fraction beyond their slack sarcomere length (where passive force starts)."""
    rows = []
    ext = np.isin(model.ms.groups, EXTENSORS)
    abd = np.isin(model.ms.groups, ABDOMINALS)
    mf = model.ms.groups == "MF"
    w = model.props.pcsa_m2[ext]
    for name, s in zip(names, sols):
        _, _, act, pas, sl = model.muscle_forces(s.x[None], s.R[None], s.a)
        se = sl[0, ext]
        rows.append({"activity": name, "extensor_active_n": float(act[0, ext].sum()),
                     "mf_sl_mean_um": float(np.average(sl[0, mf], weights=model.props.pcsa_m2[mf])),
                     "extensor_passive_n": float(pas[0, ext].sum()),
                     "abdominal_active_n": float(act[0, abd].sum()), "converged": s.converged,
                     **certificate(s),
                     "extensor_sl_mean_um": float(np.sum(w * se) / np.sum(w)), "extensor_sl_max_um": float(se.max()),
                     "extensor_pcsa_fraction_beyond_ssl": float(np.sum(w[se > model.props.ssl_um[ext]]) / np.sum(w))})
    return pd.DataFrame(rows)


FACET_CONTACT_COLUMNS = ["activity", "level", "side", "contact_n", "min_gap_mm", "rest_min_gap_mm", "surface_moved_mm",
                         "rest_face_separation_mm", "facet_stiffness_n_per_m", "reached", "passive_set"]


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
    data/anatomy), how far the contact surface was moved out of a rest overlap (``surface_moved_mm``,
    :func:`lumbar.muscles.muscle_model.clear_rest_overlap`) and the facet contact stiffness of the passive set [N/m]. Where the anatomy has the cartilage
    surfaces touching at rest (gap 0), a geometry whose rest gap is far from 0 makes a level's facets engage late
    (gap > 0) or preloaded (gap < 0)."""
    x0, R0 = model.reference_state()
    rows = []
    moved_all = getattr(model, "facet_surface_moved_m", None) or [np.zeros(len(m.surfaces)) for m in model.level_models]
    for lv, m, sides, moved in zip(model.levels, model.level_models, model.facet_sides, moved_all):
        if not sides:          # a level without facet joints (paper 2's 6-DOF springs)
            continue
        rest = facet_gaps(m, x0, R0)[0]
        space = {side: face_separation(surf, fl) for side, fl, surf in facet_surfaces(model.geo.levels[lv])}
        for name, s in zip(names, sols):
            xs, Rs = s.x[None], s.R[None]
            cf, g = m.contact_forces(xs, Rs)[0], facet_gaps(m, xs, Rs)[0]
            for k, side in enumerate(sides):
                rows.append({"activity": name, "level": lv, "side": side, "contact_n": float(cf[k]),
                             "min_gap_mm": 1e3 * float(g[k]), "rest_min_gap_mm": 1e3 * float(rest[k]),
                             "surface_moved_mm": 1e3 * float(moved[k]),
                             "rest_face_separation_mm": 1e3 * space[side],
                             "facet_stiffness_n_per_m": float(model.charset.facet.stiffness),
                             "reached": bool(s.reached), "passive_set": model.passive_set})
    return pd.DataFrame(rows, columns=FACET_CONTACT_COLUMNS)


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


def intervertebral_rotations(model, sols, names, reference="upright_standing") -> pd.DataFrame:
    """Sagittal intervertebral rotation [deg] of every level (upper vertebra relative to the lower, flexion +) in each
    solved posture, and its change from the ``reference`` posture (paper 2 Sect. 2.4 compares the changes from upright
    standing in 10 deg extension and 40 deg flexion with Wong et al. 2004's healthy range)."""
    from ..mechanics import so3  # noqa: PLC0415

    def angles(s):
        out = {}
        for lv in model.levels:
            lev = model.geo.levels[lv]
            up, lo = model.body_index[lev.upper], model.body_index[lev.lower]
            Rl = s.R[lo] if lo >= 0 else np.eye(3)
            out[lv] = float(np.degrees(so3.log((Rl.T @ s.R[up])[None])[0, 1]))
        return out

    ref = angles(sols[names.index(reference)])
    rows = []
    for name, s in zip(names, sols):
        a = angles(s)
        for lv in model.levels:
            rows.append({"activity": name, "level": lv, "rotation_deg": a[lv],
                         "rotation_from_standing_deg": a[lv] - ref[lv], **certificate(s)})
    return pd.DataFrame(rows)


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
    reached = val[val["reached"].astype(bool)]
    metrics["n_reached"] = int(len(reached))
    for suffix, d in (("", ok), ("_reached", reached), ("_all", val)):
        if len(d) >= 3:
            r = np.corrcoef(d["idp_sim_mpa"], d["idp_in_vivo_mpa"])[0, 1]
            metrics["r2" + suffix] = float(r ** 2)
            metrics["rmse" + suffix + "_mpa"] = float(np.sqrt(np.mean((d["idp_sim_mpa"] - d["idp_in_vivo_mpa"]) ** 2)))
        else:
            metrics["r2" + suffix] = metrics["rmse" + suffix + "_mpa"] = None
    metrics["all_definition"] = ("r2_all, rmse_all_mpa: every activity, including the IDP of postures flagged as "
                                 "not converged (their thorax misses the target; not a model prediction)")
    metrics["reached_definition"] = ("r2_reached, rmse_reached_mpa: the activities reached (equilibrium, thorax on "
                                     "target), including those whose optimum IPOPT could not certify (an equilibrium "
                                     "that may not be the optimum)")
    return seg, val, metrics


VARIANTS = ("reproduction", "calibrated_chain")


def validation_study(cfg: dict, passive_dir, in_vivo: pd.DataFrame, variant="reproduction", log=None) -> dict:
    """The muscle stage's validation of one variant (config section ``muscle_model`` in ``cfg``): ``reproduction``
    as configured, ``calibrated_chain`` on the workflow's calibrated disc, facets and ligaments at every level. Solves
    the activities, the baseline postures of the sweep and the rotation-check postures; a baseline posture of the
    reproduction model that IPOPT cannot certify raises (the sensitivity study starts from them); the calibrated
    chain's are flagged (``certified`` False: not comparable in the claims table). Returns the tables
    (``segment_loads``, ``validation``, ``metrics``, ``flexion_relaxation``, ``rotations``, ``facet_contact``) and
    ``model``, ``sols``, ``names``, ``keep`` (the configured activities) for the reproduction's further outputs."""
    import logging  # noqa: PLC0415
    import time  # noqa: PLC0415

    from . import muscle_model as mm  # noqa: PLC0415
    from .reproduction import paper_flexion_relaxation  # noqa: PLC0415

    log = log or logging.getLogger(__name__)
    if variant not in VARIANTS:
        raise ValueError(f"muscle validation variant must be one of {VARIANTS}, got {variant!r}")
    p = dict(cfg)
    if variant == "calibrated_chain":
        p.update(passive_model="detailed", passive_set="workflow_calibrated")
    model = mm.model_from_config(p, passive_dir)
    log.info("muscle model variant %s: passive model %s, passive set %s, in-situ posture %s, IAP %.0f N, "
             "extensor PCSA %.1f cm2", variant, model.passive_model, p["passive_set"], model.in_situ_posture,
             model.iap_force_n, 1e4 * model.props.pcsa_m2[mm.group_mask(model.ms, "EXT")].sum())
    solver = mm.make_solver(model, p["solver"])
    names = list(p["activities"])
    for post in mm.POSTURES.values():          # the baseline postures of the sweep are always solved
        if post not in names:
            names.append(post)
    t0 = time.perf_counter()
    sols = mm.solve_postures(model, solver, names)
    log.info("%d activities solved in %.1f s; converged: %s", len(names), time.perf_counter() - t0,
             {n: s.converged for n, s in zip(names, sols)})
    bad = [n for n, s in zip(names, sols) if n in mm.POSTURES.values() and not s.certified]
    if bad and variant == "reproduction":     # its baselines start the sweep; the chain's are compared, flagged
        raise RuntimeError(f"muscle validation ({variant}): baseline posture(s) {bad} not certified "
                           f"({[(s.reached, s.ipopt_status, s.message) for n, s in zip(names, sols) if n in bad]}); "
                           "the sensitivity study and the claims need certified baselines (muscle_model.solver)")
    for n, s in zip(names, sols):
        log.info("%s: converged=%s reached=%s certified=%s KKT residual %.1e, residual %.1e N %.1e N*m, tracking "
                 "error %.3f deg, %d iterations %s", n, s.converged, s.reached, s.certified, s.kkt_residual,
                 s.residual_force_n, s.residual_moment_nm, s.tracking_error_deg, s.iterations, s.message)
    keep = [n for n in names if n in p["activities"]]
    seg, _, _ = validation(model, sols, names, in_vivo, p["disc_area_m2"])
    seg = seg[seg["activity"].isin(keep)]
    _, val, metrics = validation(model, [s for n, s in zip(names, sols) if n in keep], keep, in_vivo,
                                 p["disc_area_m2"])
    metrics["variant"] = variant
    fr = flexion_relaxation(model, sols, names)
    fr = fr[fr["activity"].isin(list(mm.POSTURES.values()))].copy()
    paper = paper_flexion_relaxation()
    fr["paper_extensor_active_n"] = [paper[a][0] for a in fr["activity"]]
    fr["paper_extensor_passive_n"] = [paper[a][1] for a in fr["activity"]]
    fr["paper_abdominal_active_n"] = [paper[a][2] for a in fr["activity"]]
    fr["paper_source"] = "paraspinal_muscle_properties_spinal_loading.md, Sect. 3.1 (original_text)"
    fr["note"] = (f"{variant}: as the paper (Sect. 2.1): pelvis fixed, all 36 deg of thorax rotation in L1-S1; SL = "
                  f"in-situ SL x fibre length / its length in the {model.in_situ_posture} posture (Christophy 2012 "
                  "normalisation); docs/findings.md, Muscle-driven model.")
    # paper 2's rotation check (10 deg extension, 40 deg flexion; changes from upright standing, Sect. 2.4)
    rot_names = list(mm.ROTATION_CHECK)
    rot_sols = mm.solve_postures(model, solver, rot_names)
    rot = intervertebral_rotations(model, sols + rot_sols, names + rot_names)
    rot = rot[rot["activity"].isin(rot_names + ["flexion_36deg"])].copy()
    rot["healthy_range"] = ("Wong et al. 2004's per-level ranges (100 volunteers, the paper's comparison) are not "
                            "available here")
    contact = facet_contact(model, sols, names)
    contact = contact[contact["activity"].isin(keep)]
    return {"segment_loads": seg[["level", "activity", "compressive_n", "shear_n", "moment_nm", "converged",
                                  "lateral_moment_nm", "axial_moment_nm", "reached", "certified", "kkt_residual"]],
            "validation": val, "metrics": metrics, "flexion_relaxation": fr, "rotations": rot,
            "facet_contact": contact, "model": model, "sols": sols, "names": names, "keep": keep,
            "uncertified": [n for n, s in zip(names, sols) if s.reached and not s.certified],
            "ipopt_status": [s.ipopt_status for s in sols if s.reached and not s.certified]}


def write_variant_tables(study: dict, output, log=None):
    """The tables every variant writes (``output``: the rule's named outputs), with their log lines."""
    import json  # noqa: PLC0415
    import logging  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    from ..inputs.io import write_table_atomic  # noqa: PLC0415

    log = log or logging.getLogger(__name__)
    write_table_atomic(study["segment_loads"], output.segment_loads)
    write_table_atomic(study["validation"], output.validation)
    Path(output.metrics).parent.mkdir(parents=True, exist_ok=True)
    Path(output.metrics).write_text(json.dumps(study["metrics"], indent=2, sort_keys=True) + "\n")
    write_table_atomic(study["flexion_relaxation"], output.flexion_relaxation)
    write_table_atomic(study["rotations"], output.rotations)
    write_table_atomic(study["facet_contact"], output.facet_contact)
    log.info("in-vivo validation (%s): %s", study["metrics"]["variant"], study["metrics"])
    for a, d in study["rotations"].groupby("activity", sort=False):
        log.info("intervertebral rotations from standing, %s (reached %s, certified %s): %s", a,
                 bool(d["reached"].iat[0]), bool(d["certified"].iat[0]),
                 {r["level"]: round(float(r["rotation_from_standing_deg"]), 1) for _, r in d.iterrows()})
    for lv, d in study["facet_contact"].groupby("level", sort=False):
        log.info("facets %s (set %s, %.3g N/m): rest gap %.2f mm; contact force per posture %s", lv,
                 d["passive_set"].iat[0], d["facet_stiffness_n_per_m"].iat[0], d["rest_min_gap_mm"].min(),
                 {a: round(float(v), 1) for a, v in d.groupby("activity", sort=False)["contact_n"].sum().items()})
