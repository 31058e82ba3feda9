# A user's specimen (geometry.kind meshes | label_volume; lumbar.geometry.configured, docs/specimen.md): the checks of
# the geometry ran in common.smk (SPECIMEN, SKIPPED_STAGES) before any job. Rule specimen_geometry builds the specimen
# once (alignment, atlas registration, discs, facets), writes its landmarks, per-level table, 4x4 transform, the
# skipped stages and one QA figure per level, and leaves the geometry in the content-addressed cache
# (lumbar.geometry.diskcache) that every other job loads it from (geometry_inputs names its levels.csv).

SPECIMEN_DIR = "results/geometry"

# outputs of the stages a specimen cannot feed (lumbar.geometry.specimen_io.skipped_stages), dropped from the default
# target by runnable_outputs(): path fragments per stage, with the stages that read their tables
SKIPPED_STAGE_OUTPUTS = {
    # the L2-S1 model: Table 5, Figs. 3 and 7, the IDP surrogate; the load-sharing summary, the real-data validation
    # and the discrepancy discovery (its in-vitro IDP experiment and benchmark) read its tables
    "l2s1": ("/l2s1", "table5", "fig3_", "fig7_", "idp_", "load_sharing_summary", "l2s1_cables", "load_sharing_curves.png",
             "load_sharing_shares.png", "validation_real_data", "validation_scoreboard", "results/discrepancy/"),
    "muscle_model": ("muscle", "in_vivo", "flexion_relaxation", "sensitivity_", "sobol", "validation_real_data",
                     "validation_scoreboard"),
    # the paper-style report and the documents read every stage's tables
    "report": ("results/report/",),
    "load_sharing.other_levels": ("multilevel", "validation_real_data", "validation_scoreboard"),
}


def runnable_outputs(paths):
    """``paths`` without the outputs of the stages the configured specimen cannot feed (SKIPPED_STAGES; the report
    with them). Other levels that are missing are left out of load_sharing.other_levels (common.smk); with none
    left, the other-level validation is skipped."""
    stages = {s for s, _ in SKIPPED_STAGES if not s.startswith("load_sharing.other_levels")}
    if not config["load_sharing"]["other_levels"]:
        stages.add("load_sharing.other_levels")
    if stages:
        stages.add("report")
    frags = [f for s in stages for f in SKIPPED_STAGE_OUTPUTS.get(s, ())]
    return [p for p in paths if not any(f in p for f in frags)]


def specimen_inputs_files(wildcards):
    """The specimen's files (every vertebra's mesh or mask, a label table)."""
    si = SPECIMEN_INPUTS
    return [str(f) for f in si.files.values()] + ([str(si.label_table)] if si.label_table else [])


if SPECIMEN:

    rule specimen_geometry:
        input:
            specimen_inputs_files,
        output:
            landmarks=f"{SPECIMEN_DIR}/landmarks.csv",
            levels=f"{SPECIMEN_DIR}/levels.csv",
            transform=f"{SPECIMEN_DIR}/transform.json",
            skipped=f"{SPECIMEN_DIR}/skipped_stages.csv",
            qa=[f"{SPECIMEN_DIR}/qa_{u}.png" for u in SPECIMEN_INPUTS.units_present],
            meshes=(
                [f"{SPECIMEN_DIR}/meshes/{v}.stl" for v in SPECIMEN_INPUTS.vertebrae]
                + [
                    f"{SPECIMEN_DIR}/meshes/meshing_report.csv",
                    f"{SPECIMEN_DIR}/meshes/resolution_limits.csv",
                ]
                if SPECIMEN_INPUTS.kind == "label_volume"
                else []
            ),
        log:
            "logs/specimen_geometry.log",
        benchmark:
            "results/benchmarks/specimen_geometry.tsv"
        conda:
            "../envs/lumbar.yaml"
        params:
            geometry=config["geometry"],
            skipped=[list(s) for s in SKIPPED_STAGES],
            backend=config["render"]["backend"],
        script:
            "../scripts/specimen_geometry.py"
