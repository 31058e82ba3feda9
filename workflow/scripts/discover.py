"""Discrepancy stage: rules discovery_idp_model, discovery_specimen_bank (rom | idp),
discovery_fixture_specimens_idp, discovery_default, discovery_va_artefact, discovery_intact_rom, discovery_in_vivo,
discovery_real_data_summary, discovery_benchmark_job (one hidden effect, "null" or "out_of_library"),
discovery_benchmark.

By hand: python workflow/scripts/discover.py discovery_va_artefact --configfile config/test/config.yaml \
    --output /tmp/va/discovery.json /tmp/va/disagreement_map.png /tmp/va/ranking.png \
             /tmp/va/before_after.png /tmp/va/section.md /tmp/va/scenarios.csv
         python workflow/scripts/discover.py discovery_benchmark_job job=ligament_prestrain \
    --configfile config/test/config.yaml --output /tmp/bench/ligament_prestrain.csv /tmp/bench/fixtures
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

import copy  # noqa: E402
import time  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar import discovery as discover  # noqa: E402
from lumbar.discovery import power_study  # noqa: E402
from lumbar.discovery import specimens  # noqa: E402
from lumbar.plots.discovery import plot_benchmark  # noqa: E402
from lumbar.inputs.io import write_json_atomic, write_table_atomic, write_text_atomic  # noqa: E402

rule = snakemake.rule
cfg = copy.deepcopy(dict(snakemake.params.cfg))
idp_model = _common.first(snakemake.input.get("idp_model", []))   # discovery_benchmark_job only
if idp_model and Path(idp_model).is_file():
    cfg["discovery"]["idp_model_table"] = str(idp_model)
# the null banks of virtual specimens (rule discovery_specimen_bank) and the IDP fixture specimens, when given
inputs = [str(p) for k in ("bank", "banks") for p in snakemake.input.get(k, [])]
for p in inputs:
    for name in ("rom", "idp"):
        if Path(p).name == f"specimen_bank_{name}.csv":
            cfg["discovery"][f"specimen_bank_{name}"] = p
fixture_idp = sorted(p for p in inputs if Path(p).name.startswith("fixture_specimens_idp_"))
# the calibrated unit's posterior band, part of the model's spread on real data (rule discovery_intact_rom)
model_bands = _common.first(snakemake.input.get("model_bands", []))
if model_bands:
    cfg["discovery"]["model_bands"] = str(model_bands)
t0 = time.perf_counter()

if rule == "discovery_idp_model":
    sim = discover.solve_idp_model(cfg)
    write_table_atomic(sim, snakemake.output[0], float_format="%.9g")
    log.info("nominal L2-S1 model (set %s): %d scenarios, %d converged", cfg["discovery"]["characteristic_set"],
             len(sim), int(sim["converged"].sum()))
elif rule == "discovery_specimen_bank":
    experiment = {"rom": "stepwise_rom", "idp": "idp_invitro"}[snakemake.wildcards.experiment]
    K = int(cfg["discovery"]["null_specimens"])
    bank = specimens.bank_table(cfg, experiment, K)
    specimens.write_bank(bank, snakemake.output[0])
    v = bank.iloc[:, list(bank.columns).index("rom_deg" if experiment == "stepwise_rom" else "idp_mpa")]
    log.info("null bank %s: %d virtual specimens x %d scenarios, %d without equilibrium", experiment, K,
             len(bank) // max(K, 1), int(v.isna().sum()))
elif rule == "discovery_fixture_specimens_idp":
    first, count = power_study.fixture_part(cfg, int(snakemake.wildcards.part))
    t = specimens.idp_bank_table(cfg, count, specimens.FIXTURE_STREAM, first=first)
    t["source"] = (f"virtual specimens of the nominal L2-S1 model, seed {specimens.bank_seed(cfg, specimens.FIXTURE_STREAM)}"
                   f" (lumbar.discovery.specimens.idp_bank_table): the benchmark's TEST FIXTURES are drawn from them; "
                   f"SURROGATE, not data")
    specimens.write_bank(t, snakemake.output[0])
    log.info("IDP fixture specimens %d-%d: %d scenarios each, %d specimen-scenarios without equilibrium", first,
             first + count - 1, len(t) // max(count, 1), int((~t["converged"].astype(bool)).sum()))
elif rule in ("discovery_default", "discovery_va_artefact", "discovery_in_vivo", "discovery_intact_rom"):
    if rule == "discovery_in_vivo":
        cfg["discovery"]["in_vivo_segment_loads"] = str(snakemake.input.segment_loads)
    out_dir = Path(snakemake.output.discovery).parent   # lumbar.discovery.run writes the case's files there
    r = discover.run(cfg, snakemake.input.measured, out_dir)
    log.info("%s on %s: named %s (estimate %s), gap %.2f -> %.2f; %s", rule, snakemake.input.measured,
             r["named_effect"], r["parameter_estimate"], r["gap_before"], r["gap_after"], r["decision"])
    for p in snakemake.output:
        if not Path(p).is_file():
            raise RuntimeError(f"{rule}: expected output {p} was not written (outputs go to {out_dir})")
elif rule == "discovery_real_data_summary":
    from lumbar.discovery.real_data import real_misses_summary  # noqa: E402
    table = real_misses_summary([Path(p) for p in snakemake.input.runs],
                                [Path(p) for p in snakemake.input.get("cases", [])],
                                cfg | {"adopted_effects": list(snakemake.params.get("adopted", []))})
    write_table_atomic(table, snakemake.output[0], float_format="%.6g")
    log.info("real-data summary: %d dataset(s); named: %s", len(table), table["named_effect"].tolist())
elif rule == "discovery_benchmark_job":
    job = snakemake.wildcards.job
    cases = discover.benchmark_cases(cfg)
    sel = discover.job_cases(cases, job)
    if sel.empty:
        raise ValueError(f"benchmark job {job!r} has no case; hidden effects: {sorted(set(cases['hidden_effect']))}")
    fixture_table = pd.concat([pd.read_csv(p) for p in fixture_idp], ignore_index=True) if fixture_idp else None
    bench = discover.run_benchmark_cases(cfg, sel, snakemake.output.fixtures, worked_cases=1,
                                         fixture_idp=fixture_table)
    log.info("seconds per discovery: %s", bench.pop("seconds").round(2).tolist())   # timings only in the log
    write_table_atomic(bench, snakemake.output.table, float_format="%.6g")
    log.info("benchmark job %s: %d case(s), %d named correctly", job, len(bench), int(bench["correct"].sum()))
elif rule == "discovery_benchmark":
    bench = pd.concat([pd.read_csv(p) for p in snakemake.input.jobs], ignore_index=True)
    bench = bench.sort_values("case", kind="stable").reset_index(drop=True)
    summary = discover.summarise_benchmark(bench, discover.benchmark_settings(cfg)["generator"])
    cols = ["case", "experiment", "category", "hidden_effect", "magnitude_label", "magnitude", "named_effect",
            "correct", "decision", "p_value", "p_vs_nuisance", "p_fit_specimen_mean", "best_candidate",
            "best_nuisance", "param_true", "param_est", "at_bound", "gap_before", "gap_specimen_mean", "gap_after",
            "confidence", "fixture"]
    summary["paragraph"] = discover.benchmark_paragraph(summary)
    write_table_atomic(bench[cols], snakemake.output.table, float_format="%.6g")
    write_json_atomic(summary, snakemake.output.summary, allow_nan=True)
    write_text_atomic("## Discrepancy benchmark\n\n" + summary["paragraph"] + "\n", snakemake.output.paragraph)
    plot_benchmark(bench, summary, snakemake.output.figure)
    log.info("benchmark: %d nulls, false-positive rate %s (95%% CI %s); library at m1/m2 named %s; out of library "
             "unnamed %s; null p-values KS p %s; all targets met: %s", summary["n_null"],
             summary["false_positive_rate"], summary["false_positive_rate_95ci"],
             summary["library_at_benchmark_magnitudes"]["rate"], summary["out_of_library_unnamed"]["rate"],
             summary["null_p_values"]["ks_p"], summary["all_pass"])
else:
    raise ValueError(f"unknown rule {rule!r}")
log.info("%s done in %.1f s", rule, time.perf_counter() - t0)
