# Muscle-driven L1-S1 model (paper 2): validation against in-vivo L4-L5 IDP (Table 1, Fig. 3,
# flexion-relaxation), the one-at-a-time sensitivity sweep (Figs. 5-11; one job per Paramspace chunk)
# and a variance-based (Sobol) sensitivity study (muscle_sobol_chunk: model solves of the polynomial chaos
# training design per posture and sample chunk, so that --cores 2 keeps both cores busy; muscle_sobol fits
# the expansion and computes the indices with bootstrap intervals, lumbar.muscles.pce). Long jobs log progress lines
# (scenarios done / total, elapsed, remaining). Library: lumbar.muscles.muscle_model, lumbar.muscles.
import pandas as pd
from snakemake.utils import Paramspace

_mm_sens = config["muscle_model"]["sensitivity"]
MUSCLE_CHUNKS = Paramspace(
    pd.DataFrame(
        [
            ("ssl_um", "none"),
            ("k_n_per_cm2", "none"),
            ("k_n_per_cm2", str(_mm_sens["interplay_ssl_um"])),
            ("in_situ_sl_um", "none"),
            ("in_situ_sl_um", str(_mm_sens["interplay_ssl_um"])),
            ("spt_n_per_cm2", "none"),
            ("pennation_deg", "none"),
        ],
        columns=["parameter", "ssl_um"],
    ),
    filename_params="*",
)
# one figure per parameter of the sensitivity study: MUSCLE_SENSITIVITY_PARAMETERS (lumbar.inputs.tables, common.smk)


rule muscle_validation:
    input:
        in_vivo=config["muscle_model"]["in_vivo_table"],
        landmarks=geometry_inputs,
        # the passive set's tables (muscle_model.passive_set; the script reads the set from their folder)
        passive=muscle_passive_tables(),
        # read by lumbar.muscles.muscle_model from the repository's data/ (its defaults), not from config paths
        data=[
            "data/muscles/muscle_groups.csv",
            config["muscle_model"]["upper_body_table"],
            "data/paper2/paper2_model_inputs_third_party.csv",
            "data/paper2/paper2_claims_original_text.csv",
        ],
        published=published_model_results,
    output:
        **stage_outputs("muscle_model", "muscle_validation"),
    log:
        log_file("muscle_validation"),
    benchmark:
        benchmark_file("muscle_validation")
    # on the longest chain (see stepwise_reduction_surrogate): its baseline starts the Sobol and sensitivity chunks
    priority: 5
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
        published=config["paths"]["published_model_results"],
    script:
        "../scripts/muscle_validation.py"


rule muscle_sensitivity:
    input:
        baseline=out("muscle_model", "baseline"),
        passive=muscle_passive_tables(),
    output:
        **stage_outputs(
            "muscle_model", "muscle_sensitivity", chunk=MUSCLE_CHUNKS.wildcard_pattern
        ),
    log:
        log_file(f"muscle_sensitivity/{MUSCLE_CHUNKS.wildcard_pattern}"),
    benchmark:
        benchmark_file(f"muscle_sensitivity/{MUSCLE_CHUNKS.wildcard_pattern}")
    # leaves of the DAG (only muscle_sensitivity_table and the report wait for them), but the longest jobs of the
    # DAG after the Sobol chunks (20-30 s each on the default config): as soon as the baseline exists, so that the
    # short jobs (the discovery's, 2-14 s) fill both cores at the end (longest processing time first)
    priority: 1
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
    script:
        "../scripts/muscle_sensitivity.py"


rule muscle_sensitivity_table:
    input:
        chunks=expand(
            out("muscle_model", "sensitivity_chunk", chunk="{params}"),
            params=MUSCLE_CHUNKS.instance_patterns,
        ),
        baseline_table=out("muscle_model", "validation"),
    output:
        **stage_outputs("muscle_model", "muscle_sensitivity_table"),
    log:
        log_file("muscle_sensitivity_table"),
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
    script:
        "../scripts/muscle_sensitivity_table.py"


rule muscle_sobol_chunk:
    input:
        baseline=out("muscle_model", "baseline"),
        passive=muscle_passive_tables(),
    output:
        **stage_outputs("muscle_model", "muscle_sobol_chunk"),
    log:
        log_file("muscle_sobol_chunk/{posture}_{chunk}"),
    benchmark:
        benchmark_file("muscle_sobol_chunk/{posture}_{chunk}")
    wildcard_constraints:
        posture="standing|flexion",
        chunk=r"\d+",
    # leaves like muscle_sensitivity (see there), the longest jobs of the DAG (flexion: 35-40 s): first of all
    priority: 2
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
        seed=config["seed"],
    script:
        "../scripts/muscle_sobol_chunk.py"


rule muscle_sobol:
    input:
        chunks=expand(
            out("muscle_model", "sobol_chunk"),
            posture=config["muscle_model"]["sensitivity"]["postures"],
            chunk=range(config["muscle_model"]["sobol"]["chunks"]),
        ),
    output:
        **stage_outputs("muscle_model", "muscle_sobol"),
    log:
        log_file("muscle_sobol"),
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
        seed=config["seed"],
    script:
        "../scripts/muscle_sobol.py"


rule muscle_validation_calibrated:
    # the muscle model on the calibrated passive chain (disc, facets and ligaments of the workflow's calibrated set at
    # every level of the muscle model's geometry): the same activities, its tables under names of their own
    input:
        in_vivo=config["muscle_model"]["in_vivo_table"],
        landmarks=geometry_inputs,
        passive=characteristic_tables(
            config["characteristics"]["calibrated_dir"], ["calibrated"]
        ),
        data=[
            "data/muscles/muscle_groups.csv",
            config["muscle_model"]["upper_body_table"],
            "data/paper2/paper2_model_inputs_third_party.csv",
        ],
    output:
        **stage_outputs("muscle_model", "muscle_validation_calibrated"),
    log:
        log_file("muscle_validation_calibrated"),
    benchmark:
        benchmark_file("muscle_validation_calibrated")
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
    script:
        "../scripts/muscle_validation_calibrated.py"


rule paper2_reproduction:
    # paper 2's stated results (data/paper2/paper2_claims_original_text.csv) claim by claim against the reproduction
    # model and the calibrated passive chain (lumbar.muscles.reproduction)
    input:
        claims="data/paper2/paper2_claims_original_text.csv",
        validation=out("muscle_model", "validation"),
        metrics=out("muscle_model", "metrics"),
        segment_loads=out("muscle_model", "segment_loads"),
        flexion_relaxation=out("muscle_model", "flexion_relaxation"),
        sensitivity=out("muscle_model", "sensitivity"),
        facet_contact=out("muscle_model", "facet_contact"),
        rotations=out("muscle_model", "rotations"),
        calibrated=paper2_calibrated_inputs(),
    output:
        **stage_outputs("muscle_model", "paper2_reproduction"),
    log:
        log_file("paper2_reproduction"),
    conda:
        "../envs/lumbar.yaml"
    script:
        "../scripts/paper2_reproduction.py"
