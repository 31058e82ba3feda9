# lumbar: lumbar-spine multibody biomechanics (see README.md).
# Run from the repository root:  snakemake --cores 2
from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/specimen.smk"
include: "workflow/rules/geometry.smk"
include: "workflow/rules/fsu.smk"
include: "workflow/rules/virtual_experiment.smk"
include: "workflow/rules/calibration.smk"
include: "workflow/rules/landmark_accuracy.smk"
include: "workflow/rules/load_sharing.smk"
include: "workflow/rules/admissibility.smk"
include: "workflow/rules/stepwise_reduction.smk"
include: "workflow/rules/l2s1.smk"
include: "workflow/rules/muscle_model.smk"
include: "workflow/rules/validation.smk"
include: "workflow/rules/discover.smk"
include: "workflow/rules/report.smk"


rule all:
    default_target: True
    input:
        runnable_outputs(final_outputs()),
