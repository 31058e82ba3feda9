# A user's specimen (geometry.kind meshes | label_volume; lumbar.geometry.configured, docs/specimen.md): the checks of
# the geometry ran in common.smk (SPECIMEN, SKIPPED_STAGES) before any job. Rule specimen_geometry builds the specimen
# once (alignment, atlas registration, discs, facets), writes its landmarks, per-level table, 4x4 transform, the
# skipped stages and one QA figure per level, and leaves the geometry in the content-addressed cache
# (lumbar.geometry.diskcache) that every other job loads it from (geometry_inputs names its levels.csv). Both rules are
# defined in every configuration and requested only for a specimen (by hand on another geometry: an error saying so).


rule specimen_geometry:
    input:
        specimen_inputs_files,
    output:
        **stage_outputs(
            "specimen", "specimen_geometry", unit=SPECIMEN_UNITS, mesh=SPECIMEN_MESHES
        ),
    log:
        log_file("specimen_geometry"),
    benchmark:
        benchmark_file("specimen_geometry")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        skipped=[list(s) for s in SKIPPED_STAGES],
        backend=config["render"]["backend"],
    script:
        "../scripts/specimen_geometry.py"


rule specimen_real_targets:
    input:
        yamamoto="data/experiments/yamamoto1989_levels_original_text.csv",
    output:
        **stage_outputs("specimen", "specimen_real_targets"),
    log:
        log_file("specimen_real_targets"),
    conda:
        "../envs/lumbar.yaml"
    params:
        level=config["fsu"]["level"],
    script:
        "../scripts/specimen_real_targets.py"
