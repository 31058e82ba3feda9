"""Each stage's outputs declared once: the stage manifests.

A stage (a rule file of the workflow, ``workflow/rules/<stage>.smk``, and the library module that computes it) has
one :class:`Manifest`: its outputs by role, each an :class:`Output` (path relative to the run's results root, the
rule that writes it, its caption and category in Snakemake's report, whether the default target builds it and
whether the paper-style report reads it). Everything else is derived from here:

* the rule outputs of workflow/rules/*.smk (``output: **stage_outputs("load_sharing", "load_sharing_summary")``
  and ``out(stage, role)`` for a file another rule reads; common.smk);
* ``final_outputs()`` (the default target) and ``REPORT_OPTIONAL`` (what the report reads when some rule makes it)
  in workflow/rules/common.smk (:func:`final_outputs`, :func:`report_optional`);
* the report's look-ups (:mod:`lumbar.report`): a section asks for ``builder.out(stage, role)``, never a path.

The run prefix: config ``run: {name: ""}``. An empty name keeps every output under ``results/`` (and logs under
``logs/``); ``name: X`` puts them under ``results/X/`` (``logs/X/``), so that runs of different configurations share
a checkout without overwriting each other (:func:`results_root`, :func:`logs_root`, :func:`check_run_name`).

Imports only the vocabularies of :mod:`lumbar.inputs.characteristics` (the calibrated set's file names) and
:mod:`lumbar.inputs.tables` (the muscle sensitivity parameters): the workflow reads this module while it parses.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from itertools import product
from typing import Iterable, Mapping

from .characteristics import (
    DISC_TABLE,
    FACET_TABLE,
    PRESTRAIN_TABLE,
    RUPP2015_SHAPE_TABLE,
    RUPP2015_TABLE,
    SOFTPLUS_TABLE,
)
from .tables import MUSCLE_SENSITIVITY_PARAMETERS

#: the folder every run's results live under (a run's own root: :func:`results_root`)
RESULTS_DIR = "results"
#: the folder of the rules' logs (a run's own: :func:`logs_root`)
LOGS_DIR = "logs"

#: the files of the calibrated characteristic set the calibration writes (lumbar.experiments.calibration.tables)
CALIBRATED_CHARACTERISTIC_FILES = (DISC_TABLE, FACET_TABLE, PRESTRAIN_TABLE, SOFTPLUS_TABLE, RUPP2015_TABLE,
                                   RUPP2015_SHAPE_TABLE)
#: the discovery runs and the files each writes (role -> file name, caption)
DISCOVERY_CASES = ("default", "in_vivo", "va_artefact", "intact_rom")
#: the real misses posed to the discovery (lumbar.discovery.real_data) with the outputs of a discovery run, plus
#: real_case.json; not read by the report's discrepancy section (the real-data summary is)
REAL_MISS_CASES = ("multilevel_rom", "in_vivo_lying")
DISCOVERY_CASE_FILES = (("discovery", "discovery.json", "discovery_json"),
                        ("disagreement_map", "disagreement_map.png", "discovery_disagreement_map"),
                        ("ranking", "ranking.png", "discovery_ranking"),
                        ("before_after", "before_after.png", "discovery_before_after"),
                        ("section", "section.md", "discovery_json"))

_RUN_NAME = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")


@dataclass(frozen=True)
class Output:
    """One output of a stage.

    ``path``: relative to the run's results root (may hold the rule's wildcards, ``{set}``). ``rule``: the rule
    that writes it. ``caption``: the stem of ``workflow/report/<caption>.rst`` (with ``category`` and
    ``subcategory``: an item of Snakemake's report). ``final``: the default target builds it. ``report``:
    "optional" when the paper-style report reads it wherever a rule makes it (REPORT_OPTIONAL; "final" outputs are
    always among the report's inputs). ``expand``: {wildcard: values} for a list of files (one role).
    ``directory``: a folder output. ``name``: the output's name in the rule when it is not the role's (a role
    is unique in its stage, a name in its rule).
    """
    path: str
    rule: str
    caption: str | None = None
    category: str | None = None
    subcategory: str | None = None
    final: bool = False
    report: str | None = None
    expand: tuple = ()
    directory: bool = False
    name: str | None = None

    def listed(self, **fill) -> bool:
        """Whether the output is a list of files: declared with ``expand``, or a wildcard of its path filled with a
        list (a rule's run-time list, e.g. the units a specimen holds; an empty list: no file)."""
        return bool(self.expand) or any(isinstance(v, (list, tuple)) and "{" + k + "}" in self.path
                                        for k, v in fill.items())

    def paths(self, root: str = RESULTS_DIR, **fill) -> list[str]:
        """The output's path(s) under ``root``: its ``expand`` wildcards and the list values of ``fill`` expanded,
        the other values of ``fill`` substituted."""
        lists = dict(self.expand)
        lists.update({k: v for k, v in fill.items() if isinstance(v, (list, tuple)) and "{" + k + "}" in self.path})
        p = _fill(f"{root}/{self.path}", {k: v for k, v in fill.items() if k not in lists})
        if not lists:
            return [p]
        keys = list(lists)
        return [_fill(p, dict(zip(keys, vals))) for vals in product(*(lists[k] for k in keys))]


@dataclass(frozen=True)
class Manifest:
    """A stage: its outputs by role (declaration order = the rule outputs' order), the rule file that makes them
    (``workflow/rules/<rule_file>``, default ``<stage>.smk``; the Snakefile includes the stages' rule files in
    manifest order), the module of its report section (imported by :mod:`lumbar.report`, where it registers
    itself with ``report_section``), if it has one of its own, and ``when``: the configuration key that switches
    its final outputs on."""
    stage: str
    outputs: Mapping[str, Output] = field(default_factory=dict)
    rule_file: str | None = None
    report_module: str | None = None
    when: tuple = ()

    def built(self, config: Mapping | None) -> bool:
        """Whether the default target builds the stage's final outputs: its ``when`` configuration key (a path of
        keys, e.g. ``("landmark_accuracy", "run")``) is true, or it has none (or no configuration is given)."""
        v = config
        for k in self.when:
            if not isinstance(v, Mapping):
                return True
            v = v.get(k)
        return bool(v) if self.when and config is not None else True

    @property
    def rules_path(self) -> str:
        return f"workflow/rules/{self.rule_file or self.stage + '.smk'}"

    def rules(self) -> list[str]:
        return list(dict.fromkeys(o.rule for o in self.outputs.values()))


def _fill(path: str, fill: Mapping) -> str:
    for k, v in fill.items():
        path = path.replace("{" + k + "}", str(v))
    return path


def _o(path, rule, caption=None, category=None, **kw) -> Output:
    return Output(path, rule, caption, category, **kw)


# ----------------------------------------------------------------------------------------------- the manifests
_CAL = "Stepwise reduction"
_LS = "Load sharing"
_IDP = "IDP (L2-S1)"
_MM = "Muscle model"
_VAL = "Validation on real data"
_D = "Discrepancy"


def _discovery_outputs() -> dict[str, Output]:
    out = {
        "specimen_bank": _o("discrepancy/model/specimen_bank_{experiment}.csv", "discovery_specimen_bank"),
        "fixture_specimens_idp": _o("discrepancy/model/fixture_specimens_idp_{part}.csv",
                                    "discovery_fixture_specimens_idp"),
        "idp_model": _o("discrepancy/model/idp_invitro_model.csv", "discovery_idp_model"),
    }
    for case in DISCOVERY_CASES:
        for role, name, caption in DISCOVERY_CASE_FILES:
            # final only through discovery_final_outputs (common.smk): which cases run depends on the config
            out[f"{case}.{role}"] = _o(f"discrepancy/{case}/{name}", f"discovery_{case}", caption, _D,
                                       subcategory=case, report="optional", name=role)
        out[f"{case}.scenarios"] = _o(f"discrepancy/{case}/scenarios.csv", f"discovery_{case}", name="scenarios")
    for case in REAL_MISS_CASES:
        for role, name, caption in DISCOVERY_CASE_FILES:
            out[f"{case}.{role}"] = _o(f"discrepancy/{case}/{name}", f"discovery_{case}", caption, _D,
                                       subcategory=case, name=role)
        out[f"{case}.scenarios"] = _o(f"discrepancy/{case}/scenarios.csv", f"discovery_{case}", name="scenarios")
        out[f"{case}.real_case"] = _o(f"discrepancy/{case}/real_case.json", f"discovery_{case}", name="real_case")
    out["facet_share.rows"] = _o("discrepancy/facet_share/rows.csv", "discovery_facet_share", name="rows")
    out["facet_share.real_case"] = _o("discrepancy/facet_share/real_case.json", "discovery_facet_share",
                                      name="real_case")
    out.update({
        "real_data_summary": _o("discrepancy/real_data_summary.csv", "discovery_real_data_summary",
                                "discovery_real_data_summary", _D, final=True, report="optional"),
        "benchmark_job": _o("discrepancy/benchmark/{job}.csv", "discovery_benchmark_job", name="table"),
        "benchmark_fixtures": _o("discrepancy/benchmark/{job}_fixtures", "discovery_benchmark_job", directory=True,
                                 name="fixtures"),
        "benchmark_table": _o("discrepancy/benchmark.csv", "discovery_benchmark", "discrepancy_benchmark_table", _D,
                              final=True, report="optional", name="table"),
        "benchmark_summary": _o("discrepancy/benchmark_summary.json", "discovery_benchmark",
                                "discrepancy_benchmark_table", _D, final=True, report="optional", name="summary"),
        "benchmark_figure": _o("figures/discrepancy_benchmark.png", "discovery_benchmark", "discrepancy_benchmark",
                               _D, final=True, report="optional", name="figure"),
        "benchmark_paragraph": _o("discrepancy/benchmark_section.md", "discovery_benchmark", final=True,
                                  name="paragraph"),
    })
    return out


MANIFESTS: dict[str, Manifest] = {m.stage: m for m in (
    # a user's specimen (geometry.kind meshes | label_volume): defined in every configuration, requested for a
    # specimen only; {unit}: the units present, {mesh}: a label volume's meshes and reports (the rule fills them)
    Manifest("specimen", {
        "landmarks": _o("geometry/landmarks.csv", "specimen_geometry"),
        "levels": _o("geometry/levels.csv", "specimen_geometry"),
        "transform": _o("geometry/transform.json", "specimen_geometry"),
        "skipped": _o("geometry/skipped_stages.csv", "specimen_geometry"),
        "qa": _o("geometry/qa_{unit}.png", "specimen_geometry"),
        "meshes": _o("geometry/meshes/{mesh}", "specimen_geometry"),
        "real_targets": _o("geometry/real_targets.csv", "specimen_real_targets"),
    }),
    Manifest("geometry", {
        "table": _o("tables/fsu_geometry.csv", "fsu_geometry", "fsu_geometry", "Geometry", final=True),
        "figure": _o("figures/fig1_l4l5_model.png", "fig1_l4l5_model", "fig1_l4l5_model", "Geometry", final=True),
    }),
    Manifest("fsu", {
        "rom": _o("tables/fsu_rom_intact.csv", "fsu_rom", "fsu_rom_intact", "Functional spinal unit", final=True),
    }),
    Manifest("virtual_experiment", {
        "table": _o("experiments/stepwise_reduction_surrogate.csv", "stepwise_reduction_surrogate"),
        "generator_fit": _o("experiments/stepwise_reduction_generator_fit.csv", "stepwise_reduction_surrogate"),
        "generator_targets": _o("experiments/stepwise_reduction_generator_targets.csv",
                                "stepwise_reduction_surrogate"),
        "idp": _o("experiments/idp_wilke1996_surrogate.csv", "idp_surrogate"),
    }),
    Manifest("calibration", {
        "characteristics": _o("calibration/characteristics/{name}", "calibrate",
                              expand=(("name", CALIBRATED_CHARACTERISTIC_FILES),)),
        "summary": _o("calibration/calibration_summary.csv", "calibrate", report="optional"),
        "real_fit": _o("calibration/calibration_real_fit.csv", "calibrate", report="optional"),
        "targets": _o("calibration/calibration_targets.csv", "calibrate", report="optional"),
        "prior": _o("calibration/calibration_prior.csv", "calibrate"),
        "penalties": _o("calibration/calibration_penalties.csv", "calibrate"),
        "posterior": _o("calibration/posterior.csv", "calibrate", final=True),
        "covariance": _o("calibration/posterior_covariance.csv", "calibrate"),
        "row_influence": _o("calibration/row_influence.csv", "calibration_influence", final=True),
        "draws": _o("calibration/posterior_draws.csv", "calibration_draws"),
        "sampling": _o("calibration/posterior_sampling.csv", "calibration_draws", final=True),
        "rom_fit": _o("calibration/calibration_rom_fit.csv", "calibrate"),
        "disc_points": _o("calibration/fig4_points.csv", "calibrate"),
        "ligament_points": _o("calibration/fig5_points.csv", "calibrate"),
        "table1": _o("tables/table1_disc_calibrated.csv", "calibrate", "table1_disc_calibrated", _CAL, final=True),
        "table2": _o("tables/table2_facet_surfaces.csv", "calibrate", "table2_facet_surfaces", _CAL, final=True),
        "table3": _o("tables/table3_ligaments_calibrated.csv", "calibrate", "table3_ligaments_calibrated", _CAL,
                     final=True),
        "fig4": _o("figures/fig4_disc_torque_angle.png", "fig4_disc_torque_angle", "fig4_disc_torque_angle", _CAL,
                   final=True),
        "fig5": _o("figures/fig5_ligament_characteristics.png", "fig5_ligament_characteristics",
                   "fig5_ligament_characteristics", _CAL, final=True),
        "posterior_figure": _o("figures/calibration_posterior.png", "posterior_figure", "calibration_posterior",
                               _CAL, final=True),
    }, report_module="lumbar.report.posterior"),
    # The calibrated units as OpenSim 4.6 models (lumbar.experiments.export_opensim): every level of the configured geometry with
    # the calibrated (MAP) set, the parameters' 90 % intervals beside them, and the models' ROM in OpenSim beside the
    # project's (docs/opensim_export.md)
    Manifest("export_opensim", {
        "models": _o("export/calibrated", "export_opensim", directory=True, final=True),
        "check": _o("export/opensim_check.csv", "export_opensim", "opensim_check", "OpenSim export", final=True),
        "figure": _o("figures/opensim_rom_check.png", "export_opensim", "opensim_rom_check", "OpenSim export",
                     final=True),
    }, report_module="lumbar.report.export_opensim_section", when=("export_opensim", "run")),
    Manifest("landmark_accuracy", {
        "summary": _o("geometry/landmark_accuracy_summary.csv", "landmark_accuracy", final=True),
        "groups": _o("geometry/landmark_accuracy_groups.csv", "landmark_accuracy"),
        "lengths": _o("geometry/landmark_accuracy_lengths.csv", "landmark_accuracy", final=True),
        "facets": _o("geometry/landmark_accuracy_facets.csv", "landmark_accuracy", final=True),
        "effect": _o("geometry/landmark_error_effect.csv", "landmark_accuracy", final=True),
        "voxelised": _o("geometry/landmark_accuracy_voxelised.csv", "landmark_accuracy", final=True),
        "voxelised_facets": _o("geometry/landmark_accuracy_voxelised_facets.csv", "landmark_accuracy", final=True),
    }, report_module="lumbar.report.landmark_accuracy_section", when=("landmark_accuracy", "run")),
    Manifest("load_sharing", {
        "curves": _o("load_sharing/curves_{set}.csv", "load_sharing_curves"),
        "compression": _o("load_sharing/compression_{set}.csv", "load_sharing_curves"),
        "bands": _o("load_sharing/bands_calibrated.csv", "load_sharing_bands", final=True),
        "band_draws": _o("load_sharing/band_draws_calibrated.csv", "load_sharing_bands", final=True),
        "summary": _o("load_sharing/load_sharing_summary.csv", "load_sharing_summary", "load_sharing_summary", _LS,
                      final=True),
        "reduction": _o("load_sharing/reduction_flexion.csv", "load_sharing_summary", "load_sharing_reduction", _LS,
                        report="optional"),
        "compression_summary": _o("load_sharing/compression_summary.csv", "load_sharing_summary",
                                  "load_sharing_compression", _LS, report="optional", name="compression"),
        "cables": _o("load_sharing/l2s1_cables_l4l5.csv", "load_sharing_summary", "load_sharing_cables", _LS,
                     final=True),
        "curves_figure": _o("figures/load_sharing_curves.png", "load_sharing_summary", "load_sharing_curves", _LS,
                            final=True),
        "shares_figure": _o("figures/load_sharing_shares.png", "load_sharing_summary", "load_sharing_shares", _LS,
                            final=True),
    }, report_module="lumbar.report.load_sharing_section"),
    Manifest("admissibility", {
        "table": _o("calibration/admissibility.csv", "admissibility", "admissibility", _LS, final=True),
        "limits": _o("calibration/pretension_limits.csv", "admissibility"),
        "remus": _o("calibration/remus2021_comparison.csv", "admissibility", "remus2021_comparison", _LS,
                    report="optional"),
    }),
    Manifest("stepwise_reduction", {
        "rom": _o("stepwise_reduction/rom_{set}.csv", "stepwise_reduction_sim"),
        "bands": _o("stepwise_reduction/bands_calibrated.csv", "stepwise_reduction_bands", report="optional"),
        "synopsis": _o("tables/table4_rom_synopsis.csv", "table4", "table4_rom_synopsis", _CAL, final=True),
        "counts": _o("tables/table4_outlier_counts.csv", "table4", "table4_outlier_counts", _CAL, final=True),
        "vs_paper": _o("tables/table4_vs_paper.csv", "table4", "table4_vs_paper", _CAL, final=True),
        "grid": _o("figures/table4_grid.png", "table4", "table4_grid", _CAL, final=True),
        "fig6": _o("figures/fig6_rom_stepwise_reduction.png", "fig6_rom_stepwise_reduction",
                   "fig6_rom_stepwise_reduction", _CAL, final=True),
    }),
    Manifest("l2s1", {
        "idp": _o("l2s1/idp_{set}.csv", "l2s1_idp"),
        "bands": _o("l2s1/bands_calibrated.csv", "l2s1_bands", report="optional"),
        "synopsis": _o("tables/table5_idp_synopsis.csv", "table5", "table5_idp_synopsis", _IDP, final=True),
        "counts": _o("tables/table5_outlier_counts.csv", "table5", "table5_outlier_counts", _IDP, final=True),
        "vs_paper": _o("tables/table5_vs_paper.csv", "table5", "table5_vs_paper", _IDP, final=True),
        "internal": _o("tables/l2s1_internal_loads.csv", "table5", "l2s1_internal_loads", _IDP, final=True),
        "grid": _o("figures/table5_grid.png", "table5", "table5_grid", _IDP, final=True),
        "fig7": _o("figures/fig7_idp.png", "table5", "fig7_idp", _IDP, final=True),
        "fig3": _o("figures/fig3_l2s1_cables.png", "fig3_l2s1_cables", "fig3_l2s1_cables", _IDP, final=True),
    }),
    Manifest("muscle_model", {
        "segment_loads": _o("tables/muscle_model_segment_loads.csv", "muscle_validation", "muscle_model_segment_loads",
                            _MM, final=True, report="optional"),
        "validation": _o("tables/in_vivo_validation.csv", "muscle_validation", "in_vivo_validation", _MM, final=True,
                         report="optional"),
        "metrics": _o("muscle_model/in_vivo_metrics.json", "muscle_validation", final=True, report="optional"),
        "flexion_relaxation": _o("tables/flexion_relaxation.csv", "muscle_validation", "flexion_relaxation", _MM,
                                 final=True, report="optional"),
        "figure": _o("figures/muscle_in_vivo_validation.png", "muscle_validation", "muscle_in_vivo_validation", _MM,
                     final=True, report="optional"),
        "baseline": _o("muscle_model/baseline.npz", "muscle_validation"),
        "fascicles": _o("tables/muscle_fascicles.csv", "muscle_validation"),
        "facet_contact": _o("tables/muscle_facet_contact.csv", "muscle_validation"),
        "capacity": _o("tables/muscle_capacity.csv", "muscle_validation", "muscle_capacity", _MM, final=True,
                       report="optional"),
        "rotations": _o("tables/muscle_intervertebral_rotations.csv", "muscle_validation",
                        "muscle_intervertebral_rotations", _MM, final=True, report="optional"),
        # the calibrated passive chain (rule muscle_validation_calibrated, config muscle_model.calibrated_variant)
        "calibrated_segment_loads": _o("tables/muscle_model_segment_loads_calibrated_chain.csv",
                                       "muscle_validation_calibrated", report="optional", name="segment_loads"),
        "calibrated_validation": _o("tables/in_vivo_validation_calibrated_chain.csv", "muscle_validation_calibrated",
                                    report="optional", name="validation"),
        "calibrated_metrics": _o("muscle_model/in_vivo_metrics_calibrated_chain.json", "muscle_validation_calibrated",
                                 report="optional", name="metrics"),
        "calibrated_flexion_relaxation": _o("tables/flexion_relaxation_calibrated_chain.csv",
                                            "muscle_validation_calibrated", report="optional",
                                            name="flexion_relaxation"),
        "calibrated_facet_contact": _o("tables/muscle_facet_contact_calibrated_chain.csv",
                                       "muscle_validation_calibrated", report="optional", name="facet_contact"),
        "calibrated_rotations": _o("tables/muscle_intervertebral_rotations_calibrated_chain.csv",
                                   "muscle_validation_calibrated", report="optional", name="rotations"),
        # paper 2's claims against both variants (rule paper2_reproduction, lumbar.muscles.reproduction)
        "reproduction": _o("tables/paper2_reproduction.csv", "paper2_reproduction", "paper2_reproduction", _MM,
                           final=True, report="optional"),
        "reproduction_counts": _o("tables/paper2_reproduction_counts.csv", "paper2_reproduction",
                                  "paper2_reproduction_counts", _MM, final=True, report="optional"),
        "chain_admissibility": _o("tables/muscle_chain_admissibility.csv", "paper2_reproduction",
                                  "muscle_chain_admissibility", _MM, final=True, report="optional"),
        # {chunk}: the Paramspace pattern of the sweep (muscle_model.smk fills it)
        "sensitivity_chunk": _o("muscle_model/sensitivity/{chunk}.csv", "muscle_sensitivity"),
        "sensitivity": _o("tables/sensitivity_idp.csv", "muscle_sensitivity_table", "sensitivity_idp", _MM,
                          final=True, report="optional", name="table"),
        "sensitivity_figures": _o("figures/muscle_sensitivity_{parameter}.png", "muscle_sensitivity_table",
                                  "muscle_sensitivity", _MM, final=True, name="figures",
                                  expand=(("parameter", MUSCLE_SENSITIVITY_PARAMETERS),)),
        "directions": _o("tables/sensitivity_directions.csv", "muscle_sensitivity_table", "sensitivity_directions",
                         _MM, final=True, report="optional"),
        "sobol_chunk": _o("muscle_model/sobol/{posture}_{chunk}.csv", "muscle_sobol_chunk"),
        "sobol": _o("tables/sobol_indices.csv", "muscle_sobol", "sobol_indices", _MM, final=True, report="optional",
                    name="table"),
        "sobol_figure": _o("figures/muscle_sobol.png", "muscle_sobol", "muscle_sobol", _MM, final=True,
                           report="optional", name="figure"),
    }),
    Manifest("validation", {
        "scoreboard_table": _o("tables/validation_real_data.csv", "validation_real_data", "validation_real_data",
                               _VAL, final=True, name="table"),
        "null_models": _o("tables/validation_null_models.csv", "validation_real_data", "validation_null_models", _VAL,
                          report="optional"),
        "multilevel_rom": _o("tables/multilevel_rom.csv", "multilevel_validation", "multilevel_rom", _VAL,
                             final=True, name="rom"),
        "multilevel_admissibility": _o("tables/multilevel_admissibility.csv", "multilevel_validation",
                                       report="optional", name="admissibility"),
        "multilevel_curves": _o("load_sharing/multilevel_curves.csv", "multilevel_validation", name="curves"),
        "multilevel_readings": _o("tables/multilevel_transfer_readings.csv", "multilevel_validation",
                                  "multilevel_transfer_readings", _VAL, report="optional", name="readings"),
        "multilevel_figure": _o("figures/multilevel_rom.png", "multilevel_validation", "multilevel_rom_figure", _VAL,
                                final=True, name="figure"),
        "scoreboard": _o("figures/validation_scoreboard.png", "validation_scoreboard_figure", "validation_scoreboard",
                         _VAL, final=True),
        "internal_loads": _o("figures/validation_internal_loads.png", "validation_scoreboard_figure",
                             "validation_internal_loads", _VAL, report="optional"),
    }),
    Manifest("discovery", _discovery_outputs(), rule_file="discover.smk"),
    Manifest("report", {
        "html": _o("report/paper.html", "paper_report", "paper_report", "Paper-style report", final=True),
        "pdf": _o("report/paper.pdf", "paper_report", "paper_report", "Paper-style report", final=True),
        # one per docs/templates/<name>.md (report.smk fills {name})
        "doc": _o("report/{name}", "docs_numbers"),
    }),
    # the figures of record (lumbar.report.figures_of_record): read from every other final output and the jobs'
    # benchmark files after them; feeds nothing (not a report input), the default target's last job
    Manifest("figures_of_record", {
        "json": _o("figures_of_record.json", "figures_of_record", final=True),
    }),
)}


# ----------------------------------------------------------------------------------------------- the run prefix
def check_run_name(name) -> str:
    """The run name of config ``run.name``: "" or a single folder name (letters, digits, ``_``, ``-``, ``.``;
    not starting with ``.``); a ValueError naming the key and the expected form otherwise."""
    if name is None:
        return ""
    if not isinstance(name, str) or (name and not _RUN_NAME.match(name)):
        raise ValueError(f"config run.name = {name!r}: expected \"\" or one folder name (letters, digits, '_', '-', "
                         "'.', not starting with '.'; no '/' or '..'), the sub-folder of results/ and logs/ the "
                         "run writes to")
    return name


def run_name(config: Mapping | None) -> str:
    run = (config or {}).get("run") or {}
    return check_run_name(run.get("name", "") if isinstance(run, Mapping) else run)


def results_root(config: Mapping | None = None) -> str:
    """``results`` (empty run name) or ``results/<name>``: the folder every output of the run lives under."""
    name = run_name(config)
    return f"{RESULTS_DIR}/{name}" if name else RESULTS_DIR


def logs_root(config: Mapping | None = None) -> str:
    """``logs`` or ``logs/<name>``: the run's rule logs."""
    name = run_name(config)
    return f"{LOGS_DIR}/{name}" if name else LOGS_DIR


def reroot(path: str, root: str) -> str:
    """A path written against the default root (``results/...``: a doc template's placeholder, a config default
    naming a result) as the same file under ``root``; any other path unchanged."""
    p = str(path)
    if root != RESULTS_DIR and p.startswith(RESULTS_DIR + "/"):
        return root + p[len(RESULTS_DIR):]
    return p


def results_defaults(defaults: Mapping, prefix: tuple = ()) -> dict[tuple, str]:
    """{key path: value} of every configuration default that names a result of the run (a string under
    ``results/``, e.g. ``characteristics.calibrated_dir``): a run with a name reads those from its own root."""
    out = {}
    for k, v in defaults.items():
        if isinstance(v, Mapping):
            out.update(results_defaults(v, prefix + (k,)))
        elif isinstance(v, str) and v.startswith(RESULTS_DIR + "/"):
            out[prefix + (k,)] = v
    return out


# ----------------------------------------------------------------------------------------------- look-ups
def rule_files() -> list[str]:
    """The rule files of the stages, in manifest order (the Snakefile includes them after common.smk)."""
    return [m.rules_path for m in MANIFESTS.values()]


def report_modules() -> list[str]:
    """The modules of the stages' own report sections, in manifest order."""
    return [m.report_module for m in MANIFESTS.values() if m.report_module]


def manifest(stage: str) -> Manifest:
    if stage not in MANIFESTS:
        raise KeyError(f"no stage manifest {stage!r}; stages: {sorted(MANIFESTS)}")
    return MANIFESTS[stage]


def output(stage: str, role: str) -> Output:
    m = manifest(stage)
    if role not in m.outputs:
        raise KeyError(f"stage {stage!r} has no output role {role!r}; roles: {list(m.outputs)}")
    return m.outputs[role]


def path(stage: str, role: str, root: str = RESULTS_DIR, **fill) -> str:
    """The path of a single-file role under ``root`` (wildcards not in ``fill`` are kept)."""
    o = output(stage, role)
    if o.expand and not {k for k, _ in o.expand} <= set(fill):
        raise ValueError(f"{stage}.{role} is a list of files ({o.path}): use paths(), or fill "
                         f"{[k for k, _ in o.expand]}")
    return _fill(f"{root}/{o.path}", fill)


def folder(stage: str, role: str, root: str = RESULTS_DIR) -> str:
    """The folder of a role's file(s) under ``root``, with a trailing ``/``."""
    return paths(stage, role, root)[0].rsplit("/", 1)[0] + "/"


def paths(stage: str, role: str, root: str = RESULTS_DIR, **fill) -> list[str]:
    """Every file of a role under ``root`` (a role with ``expand``: one per value)."""
    return output(stage, role).paths(root, **fill)


def rule_outputs(stage: str, rule: str) -> dict[str, Output]:
    """{output name in the rule (``snakemake.output.<name>``): Output} of the roles a rule writes, in declaration
    order; the name is the role's unless the manifest gives another."""
    out = {o.name or r: o for r, o in manifest(stage).outputs.items() if o.rule == rule}
    if not out:
        raise KeyError(f"stage {stage!r} declares no output of rule {rule!r}; its rules: {manifest(stage).rules()}")
    return out


def calibrated_dir(root: str = RESULTS_DIR) -> str:
    """The folder of the calibrated characteristic set the calibration writes (role calibration.characteristics)."""
    return paths("calibration", "characteristics", root)[0].rsplit("/", 1)[0]


def final_outputs(root: str = RESULTS_DIR, stages: Iterable[str] | None = None,
                  config: Mapping | None = None) -> list[str]:
    """Every output the default target builds (``final``, of the stages ``config`` switches on), in manifest
    order."""
    return [p for s in (stages or MANIFESTS) if MANIFESTS[s].built(config)
            for o in MANIFESTS[s].outputs.values() if o.final for p in o.paths(root)]


def report_optional(root: str = RESULTS_DIR, stages: Iterable[str] | None = None) -> list[str]:
    """The files the paper-style report reads wherever a rule of the configuration makes them."""
    return [p for s in (stages or MANIFESTS) for o in MANIFESTS[s].outputs.values() if o.report == "optional"
            for p in o.paths(root)]
