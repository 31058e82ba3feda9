"""Discrepancy stage, rule discovery_fixture_specimens_idp: one part of the virtual specimens the benchmark's IDP
fixtures are drawn from (a stream disjoint from the null bank's; lumbar.discovery.specimens.idp_bank_table).

By hand: python workflow/scripts/discovery_fixture_specimens_idp.py discovery_fixture_specimens_idp part=0 \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.discovery import jobs, power_study, specimens  # noqa: E402


def main(snakemake, log):
    cfg = jobs.job_config(snakemake.params.cfg, snakemake.input)
    first, count = power_study.fixture_part(cfg, int(snakemake.wildcards.part))
    t = specimens.idp_bank_table(cfg, count, specimens.FIXTURE_STREAM, first=first)
    t["source"] = (f"virtual specimens of the nominal L2-S1 model, seed {specimens.bank_seed(cfg, specimens.FIXTURE_STREAM)}"
                   f" (lumbar.discovery.specimens.idp_bank_table): the benchmark's TEST FIXTURES are drawn from them; "
                   f"SURROGATE, not data")
    specimens.write_bank(t, snakemake.output[0])
    log.info("IDP fixture specimens %d-%d: %d scenarios each, %d specimen-scenarios without equilibrium", first,
             first + count - 1, len(t) // max(count, 1), int((~t["converged"].astype(bool)).sum()))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
