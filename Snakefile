# lumbar: lumbar-spine multibody biomechanics (see README.md).
# Run from the repository root:  snakemake --cores 2
from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"


# every stage's rule file, in the order of the stage manifests (lumbar.inputs.manifests: a new stage is a
# manifest entry naming its rule file, not a line here)
for _rule_file in manifests.rule_files():

    include: _rule_file


rule all:
    default_target: True
    input:
        runnable_outputs(final_outputs()),
