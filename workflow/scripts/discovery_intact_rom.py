"""Discrepancy stage, rule discovery_intact_rom: discrepancy discovery on the published intact L4-L5 ROM
(real data; config discovery.intact_rom; lumbar.discovery.jobs.run_case).

By hand: python workflow/scripts/discovery_intact_rom.py discovery_intact_rom --configfile config/test/config.yaml \
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
