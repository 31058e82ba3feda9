"""Muscle-driven model (paper 2), rule muscle_validation: the reproduction model (lumbar.muscles.muscle_validation.
validation_study): the activities, the baseline postures and the rotation-check postures solved; the L4-L5 segment
loads, the in-vivo validation of the IDP (table, metrics, Fig. 3 analog), flexion-relaxation, the rotations, facet
contact, the fascicles and the extension capacity; the baseline postures for the sensitivity and Sobol jobs. A
baseline posture whose optimum IPOPT cannot certify stops the job with an error naming it. The solve logs progress
lines through the library's logger.

By hand: python workflow/scripts/muscle_validation.py muscle_validation --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.muscles import muscle_validation as mv  # noqa: E402


def main(snakemake, log):
    p = snakemake.params.muscle_model
    study = mv.validation_study(p, Path(_common.as_list(snakemake.input.passive)[0]).parent,
                                mm.read_in_vivo(snakemake.input.in_vivo), "reproduction", log)
    warning = mm.uncertified_message("muscle_validation", study["uncertified"], snakemake.output.segment_loads,
                                     study["ipopt_status"])
    if warning:
        log.warning("%s", warning)
    mv.write_variant_tables(study, snakemake.output, log)
    model, sols, names, keep = study["model"], study["sols"], study["names"], study["keep"]
    from lumbar.plots.muscle_model import plot_in_vivo_validation  # noqa: PLC0415 (matplotlib: this rule only)

    plot_in_vivo_validation(study["validation"], study["metrics"], snakemake.output.figure)        # Fig. 3 analog
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
