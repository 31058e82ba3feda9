"""Discrepancy stage, rule discovery_va_artefact: discrepancy discovery on the published vertebral-arch artefact
(neutral lordotic angle per reduction stage; lumbar.discovery.jobs.run_case).

By hand: python workflow/scripts/discovery_va_artefact.py discovery_va_artefact --configfile config/test/config.yaml \
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
