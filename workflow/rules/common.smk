import sys
from glob import glob
from pathlib import Path

from lumbar.inputs.characteristics import CHARACTERISTIC_TABLES
from lumbar.inputs.config import ConfigError, check_unique_keys
from lumbar.inputs.tables import (
    IDP_FIXTURE_PARTS,
    MUSCLE_SENSITIVITY_PARAMETERS,
    OUT_OF_LIBRARY_EXPERIMENT,
)
from snakemake.utils import validate

# Snakemake's YAML loading keeps the last of two equal keys (a second `fsu:` replaces the first): every config
# file is re-read with a loader that rejects them (lumbar.inputs.config.check_unique_keys names file and line).
for _cf in workflow.configfiles:
    if Path(_cf).is_file() and str(_cf).endswith((".yaml", ".yml")):
        try:
            check_unique_keys(_cf)
        except ConfigError as _e:
            raise WorkflowError(
                f"Error in config file {_cf}, {_e.errors[0][1]}"
            ) from None

validate(config, schema="../schemas/config.schema.yaml")


def _sorted_keys(x):
    """Nested dicts with their keys sorted: rule params built from the config then compare equal however
    the config file orders its keys (Snakemake's params rerun trigger compares their text).
    """
    if isinstance(x, dict):
        return {k: _sorted_keys(x[k]) for k in sorted(x)}
    if isinstance(x, list):
        return [_sorted_keys(v) for v in x]
    return x


_canonical_config = _sorted_keys(config)
config.clear()
config.update(_canonical_config)


# ---- the geometry: a user's specimen (geometry.kind meshes | label_volume) is checked here, before any job
# (lumbar.geometry.configured.check_config: file names, levels present, units, axes, fsu.level among the units);
# the stages it cannot feed are said once, here, and left out of the default target (runnable_outputs, below)
from lumbar.geometry.configured import (
    SPECIMEN_KINDS,
    check_config as check_geometry_config,
    specimen_inputs,
)
from lumbar.geometry.core import GeometryError

# the specimen keys left at null are dropped: a Visible Human or myo-sim run keeps the rule params it had before
config["geometry"] = {k: v for k, v in config["geometry"].items() if v is not None}
SPECIMEN = config["geometry"]["kind"] in SPECIMEN_KINDS
try:
    SKIPPED_STAGES = check_geometry_config(
        config["geometry"],
        config["fsu"]["level"],
        config["load_sharing"]["other_levels"],
    )
    SPECIMEN_INPUTS = specimen_inputs(config["geometry"]) if SPECIMEN else None
except GeometryError as _e:
    raise WorkflowError(f"Error in config geometry: {_e}") from None
if SKIPPED_STAGES:
    print(
        f"Geometry {config['geometry']['path']}: units {', '.join(SPECIMEN_INPUTS.units_present)}; skipped stages:\n"
        + "".join(f"  {st}: {why}\n" for st, why in SKIPPED_STAGES),
        file=sys.stderr,
    )
    _missing_units = {
        st.split(" ")[1]
        for st, _ in SKIPPED_STAGES
        if st.startswith("load_sharing.other_levels ")
    }
    config["load_sharing"]["other_levels"] = [
        u for u in config["load_sharing"]["other_levels"] if u not in _missing_units
    ]
# a specimen calibrated on another unit than L4-L5: its real targets are Yamamoto et al.'s values of that unit
# (rule specimen_real_targets) where the config keeps the default L4-L5 table
from lumbar.inputs.config import schema_defaults

SPECIMEN_REAL_TARGETS = "results/geometry/real_targets.csv"
if (
    SPECIMEN
    and config["fsu"]["level"] != "L4-L5"
    and config["stepwise_reduction"]["real_targets"]
    == schema_defaults("stepwise_reduction", "real_targets")
):
    config["stepwise_reduction"]["real_targets"] = [SPECIMEN_REAL_TARGETS]
    print(
        f"Calibrated unit {config['fsu']['level']}: real targets {SPECIMEN_REAL_TARGETS} (Yamamoto et al. 1989, "
        "data/experiments/yamamoto1989_levels_original_text.csv)",
        file=sys.stderr,
    )

SPECIMEN_DIR = "results/geometry"
# the geometry rule's figures (one per unit present) and, for a label volume, its meshes
SPECIMEN_QA_FIGURES = (
    [f"{SPECIMEN_DIR}/qa_{u}.png" for u in SPECIMEN_INPUTS.units_present]
    if SPECIMEN
    else []
)
SPECIMEN_LABEL_MESHES = (
    [f"{SPECIMEN_DIR}/meshes/{v}.stl" for v in SPECIMEN_INPUTS.vertebrae]
    + [
        f"{SPECIMEN_DIR}/meshes/meshing_report.csv",
        f"{SPECIMEN_DIR}/meshes/resolution_limits.csv",
    ]
    if SPECIMEN and SPECIMEN_INPUTS.kind == "label_volume"
    else []
)

# outputs of the stages a specimen cannot feed (lumbar.geometry.specimen_io.skipped_stages), dropped from the default
# target by runnable_outputs(): path fragments per stage, with the stages that read their tables
SKIPPED_STAGE_OUTPUTS = {
    # the L2-S1 model: Table 5, Figs. 3 and 7, the IDP surrogate; the load-sharing summary, the real-data validation
    # and the discrepancy discovery (its in-vitro IDP experiment and benchmark: every discrepancy output) read its tables
    "l2s1": (
        "l2s1",
        "table5",
        "fig3_",
        "fig7_",
        "idp_",
        "load_sharing_summary",
        "l2s1_cables",
        "load_sharing_curves.png",
        "load_sharing_shares.png",
        "validation_real_data",
        "validation_scoreboard",
        "discrepancy",
    ),
    "muscle_model": (
        "muscle",
        "in_vivo",
        "flexion_relaxation",
        "sensitivity_",
        "sobol",
        "validation_real_data",
        "validation_scoreboard",
    ),
    # the paper-style report and the documents read every stage's tables
    "report": ("results/report/",),
    "load_sharing.other_levels": (
        "multilevel",
        "validation_real_data",
        "validation_scoreboard",
    ),
}


def runnable_outputs(paths):
    """``paths`` without the outputs of the stages the configured specimen cannot feed (SKIPPED_STAGES; the report
    with them). Other levels that are missing are left out of load_sharing.other_levels (above); with none
    left, the other-level validation is skipped."""
    stages = {
        s for s, _ in SKIPPED_STAGES if not s.startswith("load_sharing.other_levels")
    }
    if not config["load_sharing"]["other_levels"]:
        stages.add("load_sharing.other_levels")
    if stages:
        stages.add("report")
    frags = [f for s in stages for f in SKIPPED_STAGE_OUTPUTS.get(s, ())]
    # a run prefix (results/<run.name>/) is not part of what is matched: a run named "muscle_test" keeps its outputs
    name = (config.get("run") or {}).get("name") or ""
    prefix = f"results/{name}/" if name else None

    def key(p):
        return f"results/{p[len(prefix):]}" if prefix and p.startswith(prefix) else p

    return [p for p in paths if not any(f in key(p) for f in frags)]


def specimen_inputs_files(wildcards):
    """The specimen's files (every vertebra's mesh or mask, a label table)."""
    si = SPECIMEN_INPUTS
    if si is None:  # not a specimen: the rule is never requested
        return []
    return [str(f) for f in si.files.values()] + (
        [str(si.label_table)] if si.label_table else []
    )


def final_outputs():
    """Every result the default target builds; rules of later stages add theirs here."""
    return [
        "results/tables/fsu_geometry.csv",
        "results/figures/fig1_l4l5_model.png",
        "results/tables/fsu_rom_intact.csv",
        # stepwise reduction: calibration (Tables 1-3, Figs. 4-5), forward (Table 4, Fig. 6)
        "results/tables/table1_disc_calibrated.csv",
        "results/tables/table2_facet_surfaces.csv",
        "results/tables/table3_ligaments_calibrated.csv",
        "results/figures/fig4_disc_torque_angle.png",
        "results/figures/fig5_ligament_characteristics.png",
        "results/tables/table4_rom_synopsis.csv",
        "results/tables/table4_outlier_counts.csv",
        # validation on real data (workflow/rules/validation.smk): the report opens with it
        "results/tables/validation_real_data.csv",
        # load sharing, physical admissibility, other levels (workflow/rules/load_sharing.smk, admissibility.smk)
        "results/load_sharing/load_sharing_summary.csv",
        "results/load_sharing/l2s1_cables_l4l5.csv",
        "results/figures/load_sharing_curves.png",
        "results/figures/load_sharing_shares.png",
        "results/calibration/admissibility.csv",
        # the calibration's posterior (MAP + Laplace) and the bands of the intact curves
        "results/calibration/posterior.csv",
        "results/calibration/row_influence.csv",
        "results/figures/calibration_posterior.png",
        "results/load_sharing/bands_calibrated.csv",
        "results/tables/multilevel_rom.csv",
        "results/figures/multilevel_rom.png",
        "results/figures/validation_scoreboard.png",
        "results/tables/table4_vs_paper.csv",
        "results/figures/table4_grid.png",
        "results/figures/fig6_rom_stepwise_reduction.png",
        # L2-S1 with wire cables, L4-L5 IDP: Table 5, Figs. 3 and 7
        "results/figures/fig3_l2s1_cables.png",
        "results/tables/table5_idp_synopsis.csv",
        "results/tables/table5_outlier_counts.csv",
        "results/tables/table5_vs_paper.csv",
        "results/tables/l2s1_internal_loads.csv",
        "results/figures/table5_grid.png",
        "results/figures/fig7_idp.png",
        # muscle-driven model (workflow/rules/muscle_model.smk): validation, sensitivity, Sobol
        "results/tables/muscle_model_segment_loads.csv",
        "results/tables/in_vivo_validation.csv",
        "results/muscle_model/in_vivo_metrics.json",
        "results/tables/flexion_relaxation.csv",
        "results/figures/muscle_in_vivo_validation.png",
        "results/tables/muscle_capacity.csv",
        "results/tables/sensitivity_idp.csv",
        "results/tables/sensitivity_directions.csv",
        "results/figures/muscle_sensitivity_ssl_um.png",
        "results/figures/muscle_sensitivity_k_n_per_cm2.png",
        "results/figures/muscle_sensitivity_in_situ_sl_um.png",
        "results/figures/muscle_sensitivity_spt_n_per_cm2.png",
        "results/figures/muscle_sensitivity_pennation_deg.png",
        "results/tables/sobol_indices.csv",
        "results/figures/muscle_sobol.png",
        # discrepancy discovery (workflow/rules/discover.smk)
        *discovery_final_outputs(),
        # the automatic landmarks scored on the embedded geometry (workflow/rules/landmark_accuracy.smk)
        *landmark_accuracy_outputs(),
        # paper-style report (workflow/rules/report.smk): reads every output above
        "results/report/paper.html",
        "results/report/paper.pdf",
        # documents whose numbers are read from the results (rule docs_numbers)
        *[f"results/report/{Path(t).name}" for t in DOC_TEMPLATES],
    ]


def landmark_accuracy_outputs():
    """The landmark-accuracy tables when landmark_accuracy.run (the rule's outputs), else none."""
    if not config["landmark_accuracy"]["run"]:
        return []
    return [
        "results/geometry/landmark_accuracy_summary.csv",
        "results/geometry/landmark_accuracy_lengths.csv",
        "results/geometry/landmark_error_effect.csv",
    ]


def geometry_inputs(wildcards):
    """Files the geometry is read from: the Visible Human directory, or the project landmarks
    that go with the myo-sim meshes (the meshes themselves come with the pinned myo-sim package), or for a user's
    specimen the table of rule specimen_geometry (workflow/rules/specimen.smk).
    """
    if (
        SPECIMEN
    ):  # the specimen rule's table: the specimen is built (and cached) once, before the jobs that load it
        return ["results/geometry/levels.csv"]
    if config["geometry"]["kind"] == "visible_human":
        # every file of the folder (not the folder: its mtime does not change when a file is edited in place)
        files = sorted(
            str(p) for p in Path(config["geometry"]["path"]).rglob("*") if p.is_file()
        )
        return files or [config["geometry"]["path"]]
    return sorted(glob("data/landmarks/*.csv"))


# ---- declared data files: every table a rule reads is one of its input files, so that an in-place
# edit re-runs exactly the rules that read it (a folder's mtime does not change when a file in it is rewritten).
# The folder itself stays a named input only to tell the script where the tables are; ancient(): never a trigger.
def characteristic_tables(data_dir, sets=None):
    """The tables lumbar.inputs.characteristics.load_characteristic_set reads from ``data_dir`` for ``sets``
    (every *.csv of the folder when ``sets`` is None: calibrate copies them all, discovery may load any set).
    """
    d = Path(data_dir)
    if sets is None:
        return sorted(str(p) for p in d.glob("*.csv"))
    names = {
        n
        for s in sets
        for n in CHARACTERISTIC_TABLES["rupp2015" if s == "rupp2015" else "softplus"]
    }
    return [str(d / n) for n in sorted(names)]


def discovery_calibrated_tables():
    """The calibration output that discovery reads when discovery.characteristic_set is "calibrated"
    (characteristics.calibrated_dir; lumbar.inputs.characteristics.resolve_characteristic_set).
    """
    if config["discovery"]["characteristic_set"] != "calibrated":
        return []
    return characteristic_tables(
        config["characteristics"]["calibrated_dir"], ["calibrated"]
    )


def discovery_model_bands():
    """The calibrated unit's posterior band of every stepwise-reduction scenario, part of the model's spread in the
    real-data discovery of the intact ROM (when discovery.characteristic_set is "calibrated").
    """
    if config["discovery"]["characteristic_set"] != "calibrated":
        return []
    return ["results/stepwise_reduction/bands_calibrated.csv"]


def muscle_passive_tables():
    """The tables of the muscle model's passive set (muscle_model.passive_set): the calibration output
    (characteristics.calibrated_dir; rule calibrate's files, so the DAG chains) for workflow_calibrated, the
    published set "calibrated" of characteristics.data_dir for published_table3, else that literature set's tables.
    The script reads the set from the folder of these files (lumbar.muscles.muscle_model.passive_characteristics).
    """
    name = config["muscle_model"]["passive_set"]
    if name == "workflow_calibrated":
        return characteristic_tables(
            config["characteristics"]["calibrated_dir"], ["calibrated"]
        )
    return characteristic_tables(
        config["characteristics"]["data_dir"],
        ["calibrated" if name == "published_table3" else name],
    )


def characteristics_dir():
    """characteristics.data_dir as the location input of a rule (ancient, so its mtime is never a trigger)."""
    return ancient(config["characteristics"]["data_dir"])


def published_model_results(wildcards):
    """paths.published_model_results as an input when the file exists (../shared is optional): adding it later
    re-runs the rules that fill the paper columns (the set of input files changed)."""
    p = config["paths"]["published_model_results"]
    return [p] if Path(p).is_file() else []


# ---- stepwise reduction
def stepwise_reduction_experiment(wildcards):
    """The ROM table to calibrate on and compare with: stepwise_reduction.measured_table
    when set, else the table of rule stepwise_reduction_surrogate."""
    measured = config["stepwise_reduction"]["measured_table"]
    return measured or str(rules.stepwise_reduction_surrogate.output.table)


def stepwise_reduction_derived(wildcards):
    """Disc-only rows derived from the published Eq. 3 fit (replace the surrogate's w/o ALL rows)."""
    path = config["stepwise_reduction"]["disc_only_derived"]
    return [path] if path else []


def stepwise_reduction_characteristics(wildcards):
    """The calibrated set comes from the calibration; the literature sets from the data directory."""
    if wildcards.set == "calibrated":
        return "results/calibration/characteristics/disc.csv"
    return characteristics_dir()


def stepwise_reduction_tables(wildcards):
    """The characteristic tables rule stepwise_reduction_sim reads for its set (see characteristic_tables)."""
    if wildcards.set == "calibrated":
        return characteristic_tables(
            "results/calibration/characteristics", ["calibrated"]
        )
    return characteristic_tables(config["characteristics"]["data_dir"], [wildcards.set])


# ---- paper-style report (workflow/rules/report.smk)
DOC_TEMPLATES = sorted(glob("docs/templates/*.md"))


def doc_template_inputs(wildcards):
    """The result files the placeholders of the doc templates read (lumbar.inputs.templates.template_files)."""
    from lumbar.inputs.templates import template_files

    return sorted(
        {f for t in DOC_TEMPLATES for f in template_files(Path(t).read_text())}
    )


REPORT_OPTIONAL = [
    "results/tables/validation_null_models.csv",
    "results/figures/validation_internal_loads.png",
    "results/load_sharing/reduction_flexion.csv",
    "results/stepwise_reduction/bands_calibrated.csv",
    "results/l2s1/bands_calibrated.csv",
    "results/calibration/calibration_summary.csv",
    "results/load_sharing/compression_summary.csv",
    "results/calibration/remus2021_comparison.csv",
    "results/tables/multilevel_admissibility.csv",
    "results/tables/multilevel_transfer_readings.csv",
    "results/calibration/calibration_real_fit.csv",
    "results/calibration/calibration_targets.csv",
    "results/muscle_model/in_vivo_metrics.json",
    "results/tables/muscle_model_segment_loads.csv",
    "results/tables/in_vivo_validation.csv",
    "results/tables/flexion_relaxation.csv",
    "results/tables/sensitivity_idp.csv",
    "results/tables/sensitivity_directions.csv",
    "results/tables/muscle_capacity.csv",
    "results/tables/sobol_indices.csv",
    "results/figures/muscle_in_vivo_validation.png",
    "results/figures/muscle_sobol.png",
    "results/discrepancy/benchmark.csv",
    "results/discrepancy/benchmark_summary.json",
    "results/figures/discrepancy_benchmark.png",
    "results/discrepancy/real_data_summary.csv",
] + [
    f"results/discrepancy/{case}/{name}"
    for case in ("default", "in_vivo", "va_artefact", "intact_rom")
    for name in (
        "discovery.json",
        "disagreement_map.png",
        "ranking.png",
        "before_after.png",
        "section.md",
    )
]


def report_inputs(wildcards):
    """Every final output except the report itself, the reference tables, and those of the files the report
    reads (REPORT_OPTIONAL) that some rule of this workflow produces; a file absent here is reported as
    "not built in this configuration"."""
    results = [p for p in final_outputs() if not p.startswith("results/report/")]
    extra = [stepwise_reduction_experiment(wildcards), l2s1_idp_reference(wildcards)]
    extra += [
        p
        for p in REPORT_OPTIONAL
        if any(r.is_producer(p) for r in workflow.rules)
        # discovery runs whose inputs no rule makes (in vivo before the muscle model) are not requested
        and (not p.startswith("results/discrepancy/") or p in discovery_final_outputs())
    ]
    return results + [p for p in dict.fromkeys(extra) if p not in results]


# ---- L2-S1 IDP experiment
def l2s1_idp_reference(wildcards):
    """The IDP table Table 5 compares with: l2s1.measured_table when set, else the surrogate
    (rule idp_surrogate)."""
    return config["l2s1"]["measured_table"] or str(rules.idp_surrogate.output[0])


def l2s1_characteristics(wildcards):
    """Tables of one characteristic set for the L2-S1 model. "calibrated": l2s1.calibrated_characteristics
    (a file inside it when rule calibrate produces that directory, so the DAG chains), or the published
    characteristics.data_dir when that is null / neither produced nor present."""
    data_dir = config["characteristics"]["data_dir"]
    cal = config["l2s1"]["calibrated_characteristics"]
    if wildcards.set != "calibrated" or not cal:
        return ancient(data_dir)
    cal_dir = Path(cal)
    produced = any(r.name == "calibrate" for r in workflow.rules) and cal_dir == Path(
        "results", "calibration", "characteristics"
    )
    if produced:
        return str(cal_dir.joinpath("disc.csv"))
    return ancient(cal) if cal_dir.is_dir() else ancient(data_dir)


def l2s1_tables(wildcards):
    """The characteristic tables rule l2s1_idp reads for its set (the folder l2s1_characteristics names)."""
    d = l2s1_characteristics(wildcards)
    d = Path(d).parent if str(d).endswith(".csv") else Path(d)
    return characteristic_tables(d, [wildcards.set])


# ---- discrepancy discovery (workflow/rules/discover.smk)
DISCOVERY_FILES = (
    "discovery.json",
    "disagreement_map.png",
    "ranking.png",
    "before_after.png",
    "section.md",
)


def discovery_config(wildcards):
    """The config sections lumbar.discovery reads (canonical key order, see _sorted_keys)."""
    keys = ("geometry", "characteristics", "fsu", "solver", "l2s1", "discovery", "seed")
    cfg = {k: config[k] for k in keys if k in config}
    # lumbar.discovery reads characteristics.data_dir and, for the set "calibrated", characteristics.calibrated_dir
    # (the calibration output, declared input discovery_calibrated_tables): a changed list of sets must not re-run
    # discovery, a dropped calibrated_dir would silently compare with the published Table 3 set
    cfg["characteristics"] = {"data_dir": config["characteristics"]["data_dir"]}
    if config["discovery"]["characteristic_set"] == "calibrated":
        cfg["characteristics"]["calibrated_dir"] = config["characteristics"][
            "calibrated_dir"
        ]
    # and of the stepwise-reduction section only the specimen variation (the ROM null bank's)
    cfg["stepwise_reduction"] = {
        "variation": config["stepwise_reduction"]["variation"],
        "moments_nm": config["stepwise_reduction"]["moments_nm"],
    }
    return cfg


def discovery_case_outputs(case):
    """Named outputs of one discovery run: report items (category Discrepancy) + the per-scenario table."""
    d = f"results/discrepancy/{case}"
    caption = {
        "discovery.json": "discovery_json",
        "section.md": "discovery_json",
        "disagreement_map.png": "discovery_disagreement_map",
        "ranking.png": "discovery_ranking",
        "before_after.png": "discovery_before_after",
    }
    out = {
        f.split(".")[0]: report(
            f"{d}/{f}",
            caption=f"../report/{caption[f]}.rst",
            category="Discrepancy",
            subcategory=case,
        )
        for f in DISCOVERY_FILES
    }
    out["scenarios"] = f"{d}/scenarios.csv"
    return out


# the in-vitro IDP effects (lumbar.experiments.effects: kind "idp") and the out-of-library causes of each experiment
# (lumbar.inputs.tables.OUT_OF_LIBRARY_EXPERIMENT, imported above): which benchmark job needs which model and
# specimen files
DISCOVERY_IDP_EFFECTS = ("axial_preload", "idp_moment_term", "disc_load_share")


def discovery_benchmark_jobs():
    """One benchmark job per hidden effect, one for the null tables, one for the out-of-library causes."""
    b = config["discovery"]["benchmark"]
    ool = b["generator"] == "virtual_specimens" and bool(
        discovery_job_experiments("out_of_library")
    )
    return (
        list(b["effects"])
        + (["null"] if b["n_null"] > 0 else [])
        + (["out_of_library"] if ool else [])
    )


def discovery_job_experiments(job):
    """The experiments of a benchmark job's cases (lumbar.discovery.benchmark_cases)."""
    b = config["discovery"]["benchmark"]
    exps = [x for x in ("stepwise_rom", "idp_invitro") if x in b["experiments"]]
    if job == "null":
        return set(exps[: max(1, min(len(exps), b["n_null"]))])
    if job == "out_of_library":
        return {OUT_OF_LIBRARY_EXPERIMENT[o] for o in b["out_of_library"]} & set(exps)
    return {"idp_invitro" if job in DISCOVERY_IDP_EFFECTS else "stepwise_rom"} & set(
        exps
    )


def discovery_benchmark_idp_model(wildcards):
    """The nominal L2-S1 model table, for the benchmark jobs with in-vitro IDP cases."""
    if "idp_invitro" not in discovery_job_experiments(wildcards.job):
        return []
    return ["results/discrepancy/model/idp_invitro_model.csv"]


def discovery_specimen_bank(experiment):
    """The null bank of virtual specimens of an experiment (rule discovery_specimen_bank), [] when the null has no
    specimens (discovery.null_specimens: 0)."""
    if config["discovery"]["null_specimens"] == 0:
        return []
    name = {"stepwise_rom": "rom", "idp_invitro": "idp"}[experiment]
    return [f"results/discrepancy/model/specimen_bank_{name}.csv"]


def discovery_benchmark_banks(wildcards):
    """The null banks and fixture specimens a benchmark job reads."""
    exps = discovery_job_experiments(wildcards.job)
    out = [p for x in sorted(exps) for p in discovery_specimen_bank(x)]
    b = config["discovery"]["benchmark"]
    if "idp_invitro" in exps and b["generator"] == "virtual_specimens":
        out += [
            f"results/discrepancy/model/fixture_specimens_idp_{k}.csv"
            for k in range(IDP_FIXTURE_PARTS)
        ]
    return out


def discovery_final_outputs():
    """Discovery outputs of the default target; the in-vivo run only when the muscle model's tables are
    produced by a rule of this workflow or present (the rule discovery_in_vivo declares them anyway).
    """
    cases = ["default", "va_artefact"] + (
        ["intact_rom"] if config["discovery"]["intact_rom"] else []
    )
    muscle = (
        "results/tables/in_vivo_validation.csv",
        config["discovery"]["in_vivo_segment_loads"],
    )
    if all(
        any(r.is_producer(p) for r in workflow.rules) or Path(p).is_file()
        for p in muscle
    ):
        cases.append("in_vivo")
    out = [f"results/discrepancy/{c}/{f}" for c in cases for f in DISCOVERY_FILES]
    return out + [
        "results/discrepancy/real_data_summary.csv",
        "results/discrepancy/benchmark.csv",
        "results/discrepancy/benchmark_summary.json",
        "results/discrepancy/benchmark_section.md",
        "results/figures/discrepancy_benchmark.png",
    ]


def discovery_real_data_runs(wildcards):
    """discovery.json of every run on real measurements: the vertebral-arch artefact, the intact ROM
    (discovery.intact_rom) and the in-vivo validation when the muscle model's tables are built or present.
    """
    cases = ["va_artefact"] + (
        ["intact_rom"] if config["discovery"]["intact_rom"] else []
    )
    if "results/discrepancy/in_vivo/discovery.json" in discovery_final_outputs():
        cases.append("in_vivo")
    return [f"results/discrepancy/{c}/discovery.json" for c in cases]
