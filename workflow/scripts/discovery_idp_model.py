"""Discrepancy stage, rule discovery_idp_model: the nominal L2-S1 model in every in-vitro IDP scenario
(lumbar.discovery.problems.solve_idp_model).

By hand: python workflow/scripts/discovery_idp_model.py discovery_idp_model --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar import discovery as discover  # noqa: E402
from lumbar.discovery import jobs  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    cfg = jobs.job_config(snakemake.params.cfg, snakemake.input)
    sim = discover.solve_idp_model(cfg)
    write_table_atomic(sim, snakemake.output[0], float_format="%.9g")
    log.info("nominal L2-S1 model (set %s): %d scenarios, %d converged", cfg["discovery"]["characteristic_set"],
             len(sim), int(sim["converged"].sum()))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
