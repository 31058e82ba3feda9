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
            "data/anthropometry/upper_body_segments.csv",
        ],
        published=published_model_results,
    output:
        segment_loads=report(
            "results/tables/muscle_model_segment_loads.csv",
            caption="../report/muscle_model_segment_loads.rst",
            category="Muscle model",
        ),
        validation=report(
            "results/tables/in_vivo_validation.csv",
            caption="../report/in_vivo_validation.rst",
            category="Muscle model",
        ),
        metrics="results/muscle_model/in_vivo_metrics.json",
        flexion_relaxation=report(
            "results/tables/flexion_relaxation.csv",
            caption="../report/flexion_relaxation.rst",
            category="Muscle model",
        ),
        figure=report(
            "results/figures/muscle_in_vivo_validation.png",
            caption="../report/muscle_in_vivo_validation.rst",
            category="Muscle model",
        ),
        baseline="results/muscle_model/baseline.npz",
        fascicles="results/tables/muscle_fascicles.csv",
        facet_contact="results/tables/muscle_facet_contact.csv",
        capacity=report(
            "results/tables/muscle_capacity.csv",
            caption="../report/muscle_capacity.rst",
            category="Muscle model",
        ),
    log:
        "logs/muscle_validation.log",
    benchmark:
        "results/benchmarks/muscle_validation.tsv"
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
        published=config["paths"]["published_model_results"],
    script:
        "../scripts/muscle_validation.py"


rule muscle_sensitivity:
    input:
        baseline="results/muscle_model/baseline.npz",
        passive=muscle_passive_tables(),
    output:
        f"results/muscle_model/sensitivity/{MUSCLE_CHUNKS.wildcard_pattern}.csv",
    log:
        f"logs/muscle_sensitivity/{MUSCLE_CHUNKS.wildcard_pattern}.log",
    benchmark:
        f"results/benchmarks/muscle_sensitivity/{MUSCLE_CHUNKS.wildcard_pattern}.tsv"
    # leaves of the DAG (only muscle_sensitivity_table and the report wait for them): below the default priority 0,
    # so that the jobs heading longer chains (calibration -> forward sets -> tables; the discovery's specimen banks ->
    # benchmark jobs) start first and these short jobs fill both cores at the end (lowest: the shortest jobs)
    priority: -10
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
    script:
        "../scripts/muscle_sensitivity.py"


rule muscle_sensitivity_table:
    input:
        chunks=expand(
            "results/muscle_model/sensitivity/{params}.csv",
            params=MUSCLE_CHUNKS.instance_patterns,
        ),
        baseline_table="results/tables/in_vivo_validation.csv",
    output:
        table=report(
            "results/tables/sensitivity_idp.csv",
            caption="../report/sensitivity_idp.rst",
            category="Muscle model",
        ),
        figures=report(
            expand(
                "results/figures/muscle_sensitivity_{parameter}.png",
                parameter=MUSCLE_SENSITIVITY_PARAMETERS,
            ),
            caption="../report/muscle_sensitivity.rst",
            category="Muscle model",
        ),
        directions=report(
            "results/tables/sensitivity_directions.csv",
            caption="../report/sensitivity_directions.rst",
            category="Muscle model",
        ),
    log:
        "logs/muscle_sensitivity_table.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
    script:
        "../scripts/muscle_sensitivity_table.py"


rule muscle_sobol_chunk:
    input:
        baseline="results/muscle_model/baseline.npz",
        passive=muscle_passive_tables(),
    output:
        "results/muscle_model/sobol/{posture}_{chunk}.csv",
    log:
        "logs/muscle_sobol_chunk/{posture}_{chunk}.log",
    benchmark:
        "results/benchmarks/muscle_sobol_chunk/{posture}_{chunk}.tsv"
    wildcard_constraints:
        posture="standing|flexion",
        chunk=r"\d+",
    # leaves like muscle_sensitivity (see there), longer ones: after the other rules, before the sensitivity chunks
    priority: -5
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
            "results/muscle_model/sobol/{posture}_{chunk}.csv",
            posture=config["muscle_model"]["sensitivity"]["postures"],
            chunk=range(config["muscle_model"]["sobol"]["chunks"]),
        ),
    output:
        table=report(
            "results/tables/sobol_indices.csv",
            caption="../report/sobol_indices.rst",
            category="Muscle model",
        ),
        figure=report(
            "results/figures/muscle_sobol.png",
            caption="../report/muscle_sobol.rst",
            category="Muscle model",
        ),
    log:
        "logs/muscle_sobol.log",
    conda:
        "../envs/lumbar.yaml"
    params:
        muscle_model=config["muscle_model"],
        seed=config["seed"],
    script:
        "../scripts/muscle_sobol.py"
