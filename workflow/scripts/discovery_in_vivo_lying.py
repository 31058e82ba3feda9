"""Discrepancy stage, rule discovery_in_vivo_lying: the in-vivo L4-L5 IDP with the lying postures (the passive unit at
rest as the lying state) posed to the discovery (lumbar.discovery.real_data), at the assumed spread and at half and
double of it.

By hand: python workflow/scripts/discovery_in_vivo_lying.py discovery_in_vivo_lying --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402


def main(snakemake, log):
    from lumbar.discovery import real_data as RD  # noqa: PLC0415

    cfg = dict(snakemake.params.cfg) | {"adopted_effects": list(snakemake.params.adopted)}
    out_dir = Path(snakemake.output.real_case).parent
    prob = RD.in_vivo_lying_problem(cfg, snakemake.input.measured, snakemake.input.segment_loads,
                                    snakemake.input.lying, snakemake.input.compression)
    rec = RD.run_case("in_vivo_lying", prob, cfg, out_dir, f"{snakemake.input.measured} + {snakemake.input.lying}")
    log.info("in_vivo_lying: %d rows (lying: the unit at rest, disc force %.4g N); largest miss %s (z %.2f); decision "
             "%s (half spread: %s; double: %s)", prob.n, prob.meta["rest_disc_force_n"], rec["largest_miss"],
             rec["largest_z"], rec["decision"], rec["decision_half_spread"], rec["decision_double_spread"])


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
