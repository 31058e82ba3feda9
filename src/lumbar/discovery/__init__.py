"""Discrepancy discovery (issue 6): where do model and measurement disagree, and which missing effect explains it?

``python -m lumbar.discovery --config CONFIG --measured FILE.csv --out DIR``

1. The experiment is detected from the table's columns (:data:`lumbar.inputs.tables.MEASURED`): stepwise-reduction ROM
   (``stage, direction, moment_nm, rom_mean_deg, ...``), L2-S1 IDP (``muscle_setup, load_case,
   idp_mean_mpa, idp_sd_mpa, ...``), in-vivo validation (``activity, idp_sim_mpa, idp_in_vivo_mpa, ...``;
   moments from the muscle model's segment loads) or the neutral lordotic angle per reduction stage
   (``stage, lordosis_deg, ...``: the vertebral-arch artefact). Bad files and columns are rejected before
   any computation.
2. Residuals ``z = (model - measured) / sigma`` per scenario, sigma = the uncertainty of the measured mean:
   ROM: (max - min) / d2(n) / sqrt(n) (range -> SD with the expected range of n normal samples), rows
   without a range ``no_range_sd_deg``; IDP: SD / sqrt(n); in vivo and neutral angle: configured SDs
   (none published). ``gap`` = RMS of z. Disagreement map: z by stage x (direction, moment), set-up x
   load case, activity, or stage.
3. Every candidate effect of :mod:`lumbar.experiments.effects` acting on the experiment is fitted (one bounded
   parameter): one batched forward solve on a coarse parameter grid for all candidates together, a cubic
   spline per scenario, ``scipy.optimize.minimize_scalar`` (bounded), one batched solve on a fine grid
   around each optimum, and one exact solve at the estimates (3 batches in total).
4. Decision (issue 15): the likelihood-ratio statistic of each candidate against "no effect",
   ``T_c = (chi2_none - chi2_c) / c`` with the overdispersion of the no-effect model
   ``c = max(1, chi2_none / (n - 1))``; its null distribution from a parametric bootstrap
   (``n_bootstrap`` datasets from the project's generator around the nominal model: per row n virtual
   specimens with the row's per-specimen spread, summarised as the experiment's table is; only the cached
   grid solves are reused, no new forward solve); p-value = single-step max-T over the candidates
   (corrected for their number). ``confidence`` = probability of the named effect among the candidates
   (weights exp(-chi2_c / 2 c_best)); null when nothing is named. QAICc and grouped cross-validation are
   reported as diagnostics.
5. Naming rule: an effect is named only if the data have at least ``min_rows`` compared scenarios (fewer:
   "too few rows", nothing named), gap_before > ``min_gap``, p < ``alpha`` and the refit reduces the gap by
   ``min_gap_reduction``. Estimates on a bound (``at_bound``) and a gap after the refit still above
   ``min_gap`` (``gap_after_above_threshold``) are flagged.
6. Identifiability: the correlation of every pair of candidates' sensitivity vectors on the experiment; a
   pair with |r| >= ``max_correlation`` is reported as not separable, with the ``n_next`` load cases of the
   experiment's design space that separate it best ("measure next").

Outputs in DIR: discovery.json, scenarios.csv, disagreement_map.png, ranking.png, before_after.png,
section.md. The benchmark (hidden-effect fixtures) is :func:`make_hidden_effect_dataset` /
:func:`run_benchmark_cases` / :func:`summarise_benchmark`.

Modules: :mod:`.detect` (settings, reading and recognising a measured table), :mod:`.problems` (measured data +
batched forward model per experiment), :mod:`.fit` (:func:`discover`: fit, test, name, identifiability),
:mod:`.report` (output files, :func:`run`, the summary of the real-data discoveries), :mod:`.benchmark`
(hidden-effect fixtures), :mod:`.cli` (``python -m lumbar.discovery``); the candidate effects are
:mod:`lumbar.experiments.effects`, the figures :mod:`lumbar.plots.discovery`. This package re-exports the public names.
"""
from __future__ import annotations

from .benchmark import (
                        OUT_OF_LIBRARY,
                        TARGETS,
                        FixtureSpecimens,
                        benchmark_cases,
                        job_cases,
                        benchmark_magnitudes,
                        benchmark_settings,
                        make_hidden_effect_dataset,
                        run_benchmark_cases,
                        summarise_benchmark,
)
from .cli import main
from .detect import (
                        INTERNAL_SETTINGS,
                        DiscoveryInputError,
                        default_settings,
                        detect_experiment,
                        discovery_settings,
                        read_measured,
)
from .fit import discover
from .problems import (
                        D2,
                        Problem,
                        build_problem,
                        fsu_variants_from_config,
                        idp_forward,
                        idp_model_table,
                        idp_problem,
                        in_vivo_problem,
                        neutral_problem,
                        read_segment_loads,
                        resolve_charset,
                        rom_problem,
                        solve_idp_model,
)
from .report import REAL_DATA_COLUMNS, benchmark_paragraph, real_data_summary, run, section_markdown, write_outputs

__all__ = ["OUT_OF_LIBRARY", "FixtureSpecimens", "job_cases", "TARGETS", "benchmark_cases", "benchmark_magnitudes", "benchmark_settings", "make_hidden_effect_dataset",
           "run_benchmark_cases", "summarise_benchmark", "main", "INTERNAL_SETTINGS", "DiscoveryInputError",
           "default_settings", "detect_experiment", "discovery_settings", "read_measured", "discover", "D2",
           "Problem", "build_problem", "fsu_variants_from_config", "idp_forward", "idp_model_table", "idp_problem",
           "in_vivo_problem", "neutral_problem", "read_segment_loads", "resolve_charset", "rom_problem",
           "solve_idp_model", "benchmark_paragraph", "REAL_DATA_COLUMNS", "real_data_summary", "run", "section_markdown", "write_outputs"]
