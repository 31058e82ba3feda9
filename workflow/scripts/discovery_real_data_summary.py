"""Discrepancy stage, rule discovery_real_data_summary: every discovery on real measurements in one table
(lumbar.discovery.real_data.real_misses_summary: the real misses posed, decided, with what would decide them).

By hand: python workflow/scripts/discovery_real_data_summary.py discovery_real_data_summary \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.discovery import jobs  # noqa: E402
from lumbar.discovery.real_data import real_misses_summary  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    cfg = jobs.job_config(snakemake.params.cfg, snakemake.input)
    table = real_misses_summary([Path(p) for p in snakemake.input.runs],
                                [Path(p) for p in snakemake.input.get("cases", [])],
                                cfg | {"adopted_effects": list(snakemake.params.get("adopted", []))})
    write_table_atomic(table, snakemake.output[0], float_format="%.6g")
    log.info("real-data summary: %d dataset(s); named: %s", len(table), table["named_effect"].tolist())


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
