"""Muscle-driven model (paper 2), rule muscle_validation_calibrated: the same activities on the calibrated passive
chain (the workflow's calibrated disc, facets and ligaments at every level of the muscle model's geometry;
lumbar.muscles.muscle_validation.validation_study, variant calibrated_chain), its tables under names of their own
for the claims table. A posture whose optimum IPOPT cannot certify is flagged (certified False, one WARNING naming
it): not comparable in the claims table.

By hand: python workflow/scripts/muscle_validation_calibrated.py muscle_validation_calibrated --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.muscles import muscle_validation as mv  # noqa: E402


def main(snakemake, log):
    study = mv.validation_study(snakemake.params.muscle_model,
                                Path(_common.as_list(snakemake.input.passive)[0]).parent,
                                mm.read_in_vivo(snakemake.input.in_vivo), "calibrated_chain", log)
    warning = mm.uncertified_message("muscle_validation_calibrated", study["uncertified"],
                                     snakemake.output.segment_loads, study["ipopt_status"])
    if warning:
        log.warning("%s", warning)
    mv.write_variant_tables(study, snakemake.output, log)


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
