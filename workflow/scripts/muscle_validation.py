"""Muscle-driven model (paper 2), rules muscle_validation (the reproduction model of muscle_model: the activities
and the baseline postures solved, the L4-L5 segment loads, the in-vivo validation of the IDP (table, metrics, Fig. 3
analog), flexion-relaxation, facet contact, the fascicles and the extension capacity; the baseline postures for the
sensitivity and Sobol jobs) and muscle_validation_calibrated (params.variant = calibrated_chain: the same activities
on the calibrated passive chain, its tables under names of their own). A baseline posture (upright standing, 36 deg
flexion) whose optimum is not certified stops the job with an error naming it: the sensitivity study and the claims
are built on certified optima only. The solve logs progress lines through the library's logger.

By hand: python workflow/scripts/muscle_validation.py muscle_validation --configfile config/test/config.yaml
"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import time  # noqa: E402

from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.muscles import muscle_validation as mv  # noqa: E402
from lumbar.muscles.reproduction import paper_flexion_relaxation  # noqa: E402


def main(snakemake, log):
    p = dict(snakemake.params.muscle_model)
    variant = getattr(snakemake.params, "variant", "reproduction")
    if variant == "calibrated_chain":
        p.update(passive_model="detailed", passive_set="workflow_calibrated")
    elif variant != "reproduction":
        raise ValueError(f"params.variant must be 'reproduction' or 'calibrated_chain', got {variant!r}")
    model = mm.model_from_config(p, Path(_common.as_list(snakemake.input.passive)[0]).parent)
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
    if bad:
        raise RuntimeError(f"muscle_validation ({variant}): baseline posture(s) {bad} not certified "
                           f"({[(s.reached, s.ipopt_status, s.message) for n, s in zip(names, sols) if n in bad]}); "
                           "the sensitivity study and the claims need certified baselines (muscle_model.solver)")
    warning = mm.uncertified_message("muscle_validation", [n for n, s in zip(names, sols) if s.reached and not s.certified],
                                     snakemake.output.segment_loads,
                                     [s.ipopt_status for s in sols if s.reached and not s.certified])
    if warning:
        log.warning("%s", warning)
    for n, s in zip(names, sols):
        log.info("%s: converged=%s reached=%s certified=%s KKT residual %.1e, residual %.1e N %.1e N*m, tracking "
                 "error %.3f deg, %d iterations %s", n, s.converged, s.reached, s.certified, s.kkt_residual,
                 s.residual_force_n, s.residual_moment_nm, s.tracking_error_deg, s.iterations, s.message)
    seg, val, metrics = mv.validation(model, sols, names, mm.read_in_vivo(snakemake.input.in_vivo), p["disc_area_m2"])
    keep = [n for n in names if n in p["activities"]]
    seg = seg[seg["activity"].isin(keep)]
    val = val[val["activity"].isin(keep)]
    _, val2, metrics = mv.validation(model, [s for n, s in zip(names, sols) if n in keep], keep,
                                     mm.read_in_vivo(snakemake.input.in_vivo), p["disc_area_m2"])
    fr = mv.flexion_relaxation(model, sols, names)
    fr = fr[fr["activity"].isin(list(mm.POSTURES.values()))].copy()
    paper = paper_flexion_relaxation()
    fr["paper_extensor_active_n"] = [paper[a][0] for a in fr["activity"]]
    fr["paper_extensor_passive_n"] = [paper[a][1] for a in fr["activity"]]
    fr["paper_abdominal_active_n"] = [paper[a][2] for a in fr["activity"]]
    fr["paper_source"] = "paraspinal_muscle_properties_spinal_loading.md, Sect. 3.1 (original_text)"
    fr["note"] = (f"{variant}: as the paper (Sect. 2.1): pelvis fixed, all 36 deg of thorax rotation in L1-S1; SL = "
                  f"in-situ SL x fibre length / its length in the {model.in_situ_posture} posture (Christophy 2012 "
                  "normalisation); docs/findings.md, Muscle-driven model.")
    write_table_atomic(seg[["level", "activity", "compressive_n", "shear_n", "moment_nm", "converged",
                            "lateral_moment_nm", "axial_moment_nm", "reached", "certified", "kkt_residual"]],
                       snakemake.output.segment_loads)
    write_table_atomic(val2, snakemake.output.validation)
    Path(snakemake.output.metrics).parent.mkdir(parents=True, exist_ok=True)
    metrics["variant"] = variant
    Path(snakemake.output.metrics).write_text(json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    write_table_atomic(fr, snakemake.output.flexion_relaxation)
    log.info("in-vivo validation (%s): %s", variant, metrics)
    # paper 2's rotation check (10 deg extension, 40 deg flexion; changes from upright standing, Sect. 2.4)
    rot_names = list(mm.ROTATION_CHECK)
    rot_sols = mm.solve_postures(model, solver, rot_names)
    rot = mv.intervertebral_rotations(model, sols + rot_sols, names + rot_names)
    rot = rot[rot["activity"].isin(rot_names + ["flexion_36deg"])]
    rot["healthy_range"] = ("Wong et al. 2004's per-level ranges (100 volunteers, the paper's comparison) are not "
                            "available here")
    write_table_atomic(rot, snakemake.output.rotations)
    for a, d in rot.groupby("activity", sort=False):
        log.info("intervertebral rotations from standing, %s (reached %s, certified %s): %s", a,
                 bool(d["reached"].iat[0]), bool(d["certified"].iat[0]),
                 {r["level"]: round(float(r["rotation_from_standing_deg"]), 1) for _, r in d.iterrows()})
    contact = mv.facet_contact(model, sols, names)
    contact = contact[contact["activity"].isin(keep)]
    write_table_atomic(contact, snakemake.output.facet_contact)
    for lv, d in contact.groupby("level", sort=False):
        log.info("facets %s (set %s, %.3g N/m): rest gap %.2f mm; contact force per posture %s", lv, p["passive_set"],
                 d["facet_stiffness_n_per_m"].iat[0], d["rest_min_gap_mm"].min(),
                 {a: round(float(v), 1) for a, v in d.groupby("activity", sort=False)["contact_n"].sum().items()})
    if variant != "reproduction":
        return
    from lumbar.plots.muscle_model import plot_in_vivo_validation  # noqa: PLC0415 (matplotlib: this rule only)

    plot_in_vivo_validation(val2, metrics, snakemake.output.figure)        # Fig. 3 analog
    mm.write_baseline(sols, names, snakemake.output.baseline)
    fas = model.ms.table()
    fas["l_ref_m"] = model.props.l_ref_m
    fas["l_opt_m"] = model.props.l_opt_m
    write_table_atomic(fas, snakemake.output.fascicles)
    cap = mv.capacity_table(model, [s for n, s in zip(names, sols) if n in keep], keep)
    write_table_atomic(cap, snakemake.output.capacity)
    short = cap[(cap["pose"] == "own solution") & (cap["demand_ratio"] > 1.0)]
    for _, r in short.iterrows():
        log.info("%s, %s: external + passive muscle moment %.1f N*m exceeds the active extension capacity %.1f N*m "
                 "(ratio %.2f; SpT %.0f N/cm2 would be needed)", r["activity"], r["level"],
                 r["external_moment_nm"] + r["passive_muscle_moment_nm"], r["extension_capacity_nm"],
                 r["demand_ratio"], r["spt_needed_n_per_cm2"])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
