"""Discrepancy stage, rule discovery_facet_share: the facets' share of a compressive load (Adams and Hutton 1980)
posed (lumbar.discovery.real_data): one row, too few to name anything; its z at half, the assumed and double spread.

By hand: python workflow/scripts/discovery_facet_share.py discovery_facet_share --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402


def main(snakemake, log):
    from lumbar.discovery import real_data as RD  # noqa: PLC0415

    cfg = dict(snakemake.params.cfg) | {"adopted_effects": list(snakemake.params.adopted)}
    rec = RD.facet_share_case(snakemake.input.literature, snakemake.input.compression,
                              Path(snakemake.output.real_case).parent, cfg)
    log.info("facet_share: %s", rec["note"])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
