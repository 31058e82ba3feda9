"""Discrepancy stage, rule discovery_benchmark_job: one job of the discrepancy benchmark (one hidden effect, "null"
or "out_of_library"; lumbar.discovery.power_study).

By hand: python workflow/scripts/discovery_benchmark_job.py discovery_benchmark_job job=ligament_prestrain \
    --configfile config/test/config.yaml --output /tmp/bench/ligament_prestrain.csv /tmp/bench/fixtures
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar import discovery as discover  # noqa: E402
from lumbar.discovery import jobs  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    cfg = jobs.job_config(snakemake.params.cfg, snakemake.input)
    fixture_idp = jobs.fixture_idp_paths(snakemake.input)
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


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
