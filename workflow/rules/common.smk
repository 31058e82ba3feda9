import sys
from glob import glob
from pathlib import Path

from lumbar.inputs import manifests
from lumbar.inputs.characteristics import CHARACTERISTIC_TABLES
from lumbar.inputs.config import ConfigError, check_unique_keys, schema_defaults
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

# the run prefix (config run.name) is checked first: its message names the key and the form expected
try:
    manifests.run_name(config)
except ValueError as _e:
    raise WorkflowError(str(_e)) from None

validate(config, schema="../schemas/config.schema.yaml")

# ---- the run's roots and the stage manifests (lumbar.inputs.manifests: every output declared once)
RESULTS = manifests.results_root(config)  # the run's results root (config run.name)
LOGS = manifests.logs_root(config)  # logs, or logs/<run.name>
if RESULTS != manifests.RESULTS_DIR:
    # a configuration default naming a result of the run (calibrated_dir, ...) names this run's own
    for _keys, _default in manifests.results_defaults(schema_defaults()).items():
        _section = config
        for _k in _keys[:-1]:
            _section = _section[_k]
        if _section.get(_keys[-1]) == _default:
            _section[_keys[-1]] = manifests.reroot(_default, RESULTS)


def out(stage, role, **fill):
    """The path of an output role of a stage under the run's results root (wildcards not filled are kept)."""
    return manifests.path(stage, role, RESULTS, **fill)


def outs(stage, role, **fill):
    """Every file of an output role (a role declared with ``expand``: one per value)."""
    return manifests.paths(stage, role, RESULTS, **fill)


def stage_outputs(stage, rule, **fill):
    """The named outputs of ``rule`` as its stage manifest declares them (``output: **stage_outputs(...)``):
    paths under the run's root, report items with their caption and category, folders as directory().
    """
    res = {}
    for name, o in manifests.rule_outputs(stage, rule).items():
        ps = o.paths(RESULTS, **fill)
        item = ps if o.listed(**fill) else ps[0]
        if o.directory:
            item = directory(item)
        if o.caption:
            extra = {"subcategory": o.subcategory} if o.subcategory else {}
            item = report(
                item,
                caption=f"../report/{o.caption}.rst",
                category=o.category,
                **extra,
            )
        res[name] = item
    return res


def log_file(name):
    """A rule's log file under the run's logs root."""
    return f"{LOGS}/{name}.log"


def other_runs_logs(wildcards):
    """Sub-folders of the logs folder that hold other runs' logs (logs/<name>/) rather than a rule's own
    (logs/muscle_sensitivity/...): the report's Flags list this run's warnings only. [] for a named run.
    """
    if LOGS != manifests.LOGS_DIR or not Path(LOGS).is_dir():
        return []
    own = {
        Path(str(f)).parts[1]
        for r in workflow.rules
        for f in r.log
        if len(Path(str(f)).parts) > 2
    }
    return sorted(
        d.name for d in Path(LOGS).iterdir() if d.is_dir() and d.name not in own
    )


def benchmark_file(name):
    """A rule's benchmark file (Snakemake's benchmark:) under the run's results root."""
    return f"{RESULTS}/benchmarks/{name}.tsv"


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

SPECIMEN_REAL_TARGETS = out("specimen", "real_targets")
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

# the geometry rule's figures (one per unit present) and, for a label volume, its meshes (the specimen manifest's
# roles qa and meshes, filled by specimen.smk with these lists)
SPECIMEN_UNITS = list(SPECIMEN_INPUTS.units_present) if SPECIMEN else []
SPECIMEN_MESHES = (
    [f"{v}.stl" for v in SPECIMEN_INPUTS.vertebrae]
    + ["meshing_report.csv", "resolution_limits.csv"]
    if SPECIMEN and SPECIMEN_INPUTS.kind == "label_volume"
    else []
)
SPECIMEN_QA_FIGURES = outs("specimen", "qa", unit=SPECIMEN_UNITS)
SPECIMEN_LABEL_MESHES = outs("specimen", "meshes", mesh=SPECIMEN_MESHES)

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
        "paper2_",
        "in_vivo",
        "flexion_relaxation",
        "sensitivity_",
        "sobol",
        "validation_real_data",
        "validation_scoreboard",
    ),
    # the paper-style report and the documents read every stage's tables
    "report": (manifests.folder("report", "html"),),
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
    # the run prefix (the run's results root) is not part of what is matched: a run named "muscle_test" keeps its
    # outputs (the fragments are matched against the default root's paths)
    prefix = f"{RESULTS}/" if RESULTS != manifests.RESULTS_DIR else None

    def key(p):
        return (
            f"{manifests.RESULTS_DIR}/{p[len(prefix):]}"
            if prefix and p.startswith(prefix)
            else p
        )

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
    """Every result the default target builds: the stage manifests' final outputs, the discovery runs of this
    configuration, and the documents whose numbers are read from the results (rule docs_numbers).
    """
    return (
        manifests.final_outputs(
            RESULTS, [s for s in manifests.MANIFESTS if s != "discovery"], config
        )
        + discovery_final_outputs()
        + doc_outputs()
    )


def geometry_inputs(wildcards):
    """Files the geometry is read from: the Visible Human directory, or the project landmarks
    that go with the myo-sim meshes (the meshes themselves come with the pinned myo-sim package), or for a user's
    specimen the table of rule specimen_geometry (workflow/rules/specimen.smk).
    """
    if (
        SPECIMEN
    ):  # the specimen rule's table: the specimen is built (and cached) once, before the jobs that load it
        return [out("specimen", "levels")]
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
    return [out("stepwise_reduction", "bands")]


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


def paper2_calibrated_inputs():
    """The calibrated passive chain's tables for the claims table (muscle_model.calibrated_variant), else none."""
    if not config["muscle_model"].get("calibrated_variant", True):
        return []
    return [
        out("muscle_model", k)
        for k in (
            "calibrated_validation",
            "calibrated_metrics",
            "calibrated_segment_loads",
            "calibrated_flexion_relaxation",
            "calibrated_facet_contact",
            "calibrated_rotations",
        )
    ]


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
        return out("calibration", "characteristics", name="disc.csv")
    return characteristics_dir()


def stepwise_reduction_tables(wildcards):
    """The characteristic tables rule stepwise_reduction_sim reads for its set (see characteristic_tables)."""
    if wildcards.set == "calibrated":
        return characteristic_tables(calibrated_dir(), ["calibrated"])
    return characteristic_tables(config["characteristics"]["data_dir"], [wildcards.set])


def calibrated_dir():
    """The folder of the calibrated characteristic set the calibration writes (under the run's root)."""
    return manifests.calibrated_dir(RESULTS)


# ---- paper-style report (workflow/rules/report.smk)
DOC_TEMPLATES = sorted(glob("docs/templates/*.md"))


def doc_outputs():
    """docs/templates/<name>.md rendered into the run's report folder."""
    return [out("report", "doc", name=Path(t).name) for t in DOC_TEMPLATES]


def doc_template_inputs(wildcards):
    """The result files the placeholders of the doc templates read (lumbar.inputs.templates.template_files),
    under the run's results root."""
    from lumbar.inputs.templates import template_files

    return sorted(
        {
            manifests.reroot(f, RESULTS)
            for t in DOC_TEMPLATES
            for f in template_files(Path(t).read_text())
        }
    )


# the files the paper-style report reads wherever a rule of this configuration makes them (stage manifests)
REPORT_OPTIONAL = manifests.report_optional(RESULTS)


def report_inputs(wildcards):
    """Every final output except the report itself, the reference tables, and those of the files the report
    reads (REPORT_OPTIONAL) that some rule of this workflow produces; a file absent here is reported as
    "not built in this configuration"."""
    report_dir = str(Path(out("report", "html")).parent) + "/"
    discovery_files = set(manifests.report_optional(RESULTS, ["discovery"]))
    results = [
        p
        for p in final_outputs()
        if not p.startswith(report_dir) and p not in FIGURES_OF_RECORD
    ]
    extra = [stepwise_reduction_experiment(wildcards), l2s1_idp_reference(wildcards)]
    extra += [
        p
        for p in REPORT_OPTIONAL
        if any(r.is_producer(p) for r in workflow.rules)
        # discovery runs whose inputs no rule makes (in vivo before the muscle model) are not requested
        and (p not in discovery_files or p in discovery_final_outputs())
    ]
    # a user's specimen: its first page names it and shows the calibrated unit's landmark QA
    extra += [out("specimen", "levels")] + SPECIMEN_QA_FIGURES if SPECIMEN else []
    return results + [p for p in dict.fromkeys(extra) if p not in results]


# ---- the figures of record (workflow/rules/figures_of_record.smk): read after every other final output
FIGURES_OF_RECORD = manifests.paths("figures_of_record", "json", RESULTS)


def figures_of_record_inputs(wildcards):
    """Every other output of the default target (the stages this configuration runs): the figures are read from
    them, and the jobs' benchmark files are all written by the time they exist."""
    return [p for p in runnable_outputs(final_outputs()) if p not in FIGURES_OF_RECORD]


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
        calibrated_dir()
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
# the report items of one discovery run (roles "<case>.<item>" of the discovery manifest)
DISCOVERY_ITEMS = [role for role, _, _ in manifests.DISCOVERY_CASE_FILES]


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
    return stage_outputs("discovery", f"discovery_{case}")


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
    return [out("discovery", "idp_model")]


def discovery_specimen_bank(experiment):
    """The null bank of virtual specimens of an experiment (rule discovery_specimen_bank), [] when the null has no
    specimens (discovery.null_specimens: 0)."""
    if config["discovery"]["null_specimens"] == 0:
        return []
    name = {"stepwise_rom": "rom", "idp_invitro": "idp"}[experiment]
    return [out("discovery", "specimen_bank", experiment=name)]


def discovery_benchmark_banks(wildcards):
    """The null banks and fixture specimens a benchmark job reads."""
    exps = discovery_job_experiments(wildcards.job)
    files = [p for x in sorted(exps) for p in discovery_specimen_bank(x)]
    b = config["discovery"]["benchmark"]
    if "idp_invitro" in exps and b["generator"] == "virtual_specimens":
        files += [
            out("discovery", "fixture_specimens_idp", part=k)
            for k in range(IDP_FIXTURE_PARTS)
        ]
    return files


def discovery_final_outputs():
    """Discovery outputs of the default target; the in-vivo run only when the muscle model's tables are
    produced by a rule of this workflow or present (the rule discovery_in_vivo declares them anyway).
    """
    cases = ["default", "va_artefact"] + (
        ["intact_rom"] if config["discovery"]["intact_rom"] else []
    )
    muscle = (
        out("muscle_model", "validation"),
        config["discovery"]["in_vivo_segment_loads"],
    )
    if all(
        any(r.is_producer(p) for r in workflow.rules) or Path(p).is_file()
        for p in muscle
    ):
        cases.append("in_vivo")
    runs = [out("discovery", f"{c}.{f}") for c in cases for f in DISCOVERY_ITEMS]
    return runs + manifests.final_outputs(RESULTS, ["discovery"])


def discovery_real_data_runs(wildcards):
    """discovery.json of every run on real measurements: the vertebral-arch artefact, the intact ROM
    (discovery.intact_rom) and the in-vivo validation when the muscle model's tables are built or present.
    """
    cases = ["va_artefact"] + (
        ["intact_rom"] if config["discovery"]["intact_rom"] else []
    )
    if out("discovery", "in_vivo.discovery") in discovery_final_outputs():
        cases.append("in_vivo")
    return [out("discovery", f"{c}.discovery") for c in cases]


def discovery_real_misses_runs(wildcards):
    """real_case.json of every real-miss case this configuration can pose (the in-vivo one when the muscle model's
    tables are built or present, as for discovery_in_vivo)."""
    cases = ["facet_share"]
    if config["load_sharing"]["other_levels"]:
        cases.append("multilevel_rom")
    if out("discovery", "in_vivo.discovery") in discovery_final_outputs():
        cases.append("in_vivo_lying")
    return [out("discovery", f"{c}.real_case") for c in cases]
