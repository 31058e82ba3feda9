"""Discrepancy stage, rule discovery_in_vivo: discrepancy discovery on the in-vivo validation of the muscle model
(its segment loads give the moments; lumbar.discovery.jobs.run_case).

By hand: python workflow/scripts/discovery_in_vivo.py discovery_in_vivo --configfile config/test/config.yaml \
    --output /tmp/d/discovery.json /tmp/d/disagreement_map.png /tmp/d/ranking.png /tmp/d/before_after.png \
             /tmp/d/section.md /tmp/d/scenarios.csv
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.discovery import jobs  # noqa: E402


def main(snakemake, log):
    jobs.run_case_job(snakemake, log)


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
