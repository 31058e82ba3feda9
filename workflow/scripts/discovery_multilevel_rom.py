"""Discrepancy stage, rule discovery_multilevel_rom: the Yamamoto et al. (1989) ROM of the levels the calibration did
not fit, posed to the discovery (lumbar.discovery.real_data), at the assumed spread and at half and double of it.

By hand: python workflow/scripts/discovery_multilevel_rom.py discovery_multilevel_rom --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402


def main(snakemake, log):
    from lumbar.discovery import real_data as RD  # noqa: PLC0415

    cfg = dict(snakemake.params.cfg) | {"adopted_effects": list(snakemake.params.adopted)}
    out_dir = Path(snakemake.output.real_case).parent
    prob = RD.multilevel_problem(cfg, snakemake.input.measured, snakemake.input.multilevel,
                                 levels=list(snakemake.params.levels))
    rec = RD.run_case("multilevel_rom", prob, cfg, out_dir, snakemake.input.measured)
    log.info("multilevel_rom: %d rows; largest miss %s (z %.2f); decision %s (half spread: %s; double: %s)",
             prob.n, rec["largest_miss"], rec["largest_z"], rec["decision"], rec["decision_half_spread"],
             rec["decision_double_spread"])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
