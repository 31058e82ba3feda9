"""Discrepancy discovery: where do model and measurement disagree, and which missing effect explains it?

``python -m lumbar.discovery --config CONFIG --measured FILE.csv --out DIR``

1. The experiment is detected from the table's columns (:data:`lumbar.inputs.tables.MEASURED`): stepwise-reduction ROM
   (``stage, direction, moment_nm, rom_mean_deg, ...``), L2-S1 IDP (``muscle_setup, load_case,
   idp_mean_mpa, idp_sd_mpa, ...``), in-vivo validation (``activity, idp_sim_mpa, idp_in_vivo_mpa, ...``;
   moments from the muscle model's segment loads) or the neutral lordotic angle per reduction stage
   (``stage, lordosis_deg, ...``: the vertebral-arch artefact). Bad files and columns are rejected before
   any computation.
2. Residuals ``z = (model - measured) / sigma`` per scenario, sigma = the uncertainty of the measured mean (the
   variance of the specimen mean): ROM: (max - min) / d2(n) / sqrt(n) (range -> SD with the expected range of n
   normal samples), rows without a range ``no_range_sd_deg``; IDP: SD / sqrt(n); in vivo and neutral angle:
   configured SDs (none published). ``gap`` = RMS of z against the nominal model. Disagreement map: z by stage x
   (direction, moment), set-up x load case, activity, or stage.
3. The null hypothesis has specimens in it (:mod:`.specimens`): "the table's n virtual specimens of the nominal
   model (the configured SpecimenVariation) plus measurement noise". Its prediction r is the mean of a bank of
   ``null_specimens`` virtual specimens (nominal model + the specimen-mean shift of a nonlinear model); its null
   tables are drawn from the bank (n specimens per table, the table's noise fitted from its spread, corrections
   for the bank's size), summarised as the table is. Experiments without specimens (in vivo, neutral angle) keep
   the nominal model plus Gaussian noise.
4. Every candidate effect of :mod:`lumbar.experiments.effects` acting on the experiment is fitted on top of r (one
   bounded parameter): one batched forward solve on a coarse grid (denser near 0) for all candidates together, a
   cubic spline per scenario, ``scipy.optimize.minimize_scalar`` (bounded), and one exact solve at the best
   candidate's estimate. Beside them, the nuisance explanations of :mod:`.nuisance` (uniform scale and offset of
   the measured quantity; per direction for ROM) are fitted in closed form.
5. Tests, all by the parametric bootstrap on the same null tables: the LR statistic of each candidate against r,
   ``T_c = (chi2_r - chi2_c) / c`` with ``c = max(1, chi2_r / (n - 1))``, p-value = single-step max-T over the
   candidates; the best candidate against the best nuisance explanation it is not equivalent to (tables of the
   nuisance hypothesis: the null tables scaled or offset by its refit); the adequacy of each explanation (its
   residual chi2 against its own tables).
6. Decision: ``named: <effect>`` only if the data have at least ``min_rows`` compared scenarios, gap_before >
   ``min_gap``, p < ``alpha``, the effect beats the best nuisance at ``alpha``, its refit is adequate and explains at least
   ``min_gap_reduction`` of the discrepancy beyond what the null tables give (its chi-square drop, in the metric of
   the tests, over the excess of the observed chi-square above the null tables' mean; without an excess the directed
   tests decide and the refit must not fit worse). Otherwise ``named_effect`` is null and the decision says what the table is:
   ``nothing named`` (consistent with the nominal model and specimen variation; ``nuisance: specimen-mean shift``
   when its gap to the nominal model is what varied specimens give), ``nuisance: uniform scale 0.82`` (a nuisance
   explains it), or ``unexplained`` (something is missing that the library does not hold). A candidate whose effect
   on the experiment is a nuisance family (multiple correlation >= ``max_correlation``, e.g. an axial preload and a
   uniform IDP offset) is named with that equivalence stated. Estimates on a bound are flagged.
7. Identifiability: the correlation of every pair of candidates' sensitivity vectors on the experiment; a
   pair with |r| >= ``max_correlation`` is reported as not separable, with the ``n_next`` load cases of the
   experiment's design space that separate it best ("measure next"); and each candidate's multiple correlation
   with each nuisance family.

Outputs in DIR: discovery.json, scenarios.csv, disagreement_map.png, ranking.png, before_after.png,
section.md. The benchmark, a power study (test fixtures from other virtual specimens: nulls, library effects,
out-of-library causes) is :func:`make_hidden_effect_dataset` / :func:`run_benchmark_cases` /
:func:`summarise_benchmark`.

Modules: :mod:`.detect` (settings, reading and recognising a measured table), :mod:`.problems` (measured data +
batched forward model per experiment), :mod:`.specimens` (the banks of virtual specimens and the null tables),
:mod:`.nuisance` (nuisance explanations), :mod:`.fit` (:func:`discover`: fit, test, name, identifiability),
:mod:`.decision` (the naming rule and the result record),
:mod:`.outputs` (output files, :func:`run`, the summary of the real-data discoveries), :mod:`.power_study`
(the discrepancy benchmark: the discovery's power and false-positive rate on hidden-effect fixtures), :mod:`.jobs`
(what the workflow's discovery rules share), :mod:`.cli`
(``python -m lumbar.discovery``); the candidate effects are
:mod:`lumbar.experiments.effects`, the figures :mod:`lumbar.plots.discovery`. This package re-exports the public names.
"""
from __future__ import annotations

from .power_study import (
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
from .outputs import REAL_DATA_COLUMNS, benchmark_paragraph, real_data_summary, run, section_markdown, write_outputs

__all__ = ["OUT_OF_LIBRARY", "FixtureSpecimens", "job_cases", "TARGETS", "benchmark_cases", "benchmark_magnitudes", "benchmark_settings", "make_hidden_effect_dataset",
           "run_benchmark_cases", "summarise_benchmark", "main", "INTERNAL_SETTINGS", "DiscoveryInputError",
           "default_settings", "detect_experiment", "discovery_settings", "read_measured", "discover", "D2",
           "Problem", "build_problem", "fsu_variants_from_config", "idp_forward", "idp_model_table", "idp_problem",
           "in_vivo_problem", "neutral_problem", "read_segment_loads", "resolve_charset", "rom_problem",
           "solve_idp_model", "benchmark_paragraph", "REAL_DATA_COLUMNS", "real_data_summary", "run", "section_markdown", "write_outputs"]
