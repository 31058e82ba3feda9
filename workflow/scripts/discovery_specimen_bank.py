"""Discrepancy stage, rule discovery_specimen_bank (rom | idp): the null bank of virtual specimens of the nominal
model in every compared scenario (lumbar.discovery.specimens).

By hand: python workflow/scripts/discovery_specimen_bank.py discovery_specimen_bank experiment=rom \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.discovery import jobs, specimens  # noqa: E402


def main(snakemake, log):
    cfg = jobs.job_config(snakemake.params.cfg, snakemake.input)
    experiment = {"rom": "stepwise_rom", "idp": "idp_invitro"}[snakemake.wildcards.experiment]
    K = int(cfg["discovery"]["null_specimens"])
    bank = specimens.bank_table(cfg, experiment, K)
    specimens.write_bank(bank, snakemake.output[0])
    v = bank.iloc[:, list(bank.columns).index("rom_deg" if experiment == "stepwise_rom" else "idp_mpa")]
    log.info("null bank %s: %d virtual specimens x %d scenarios, %d without equilibrium", experiment, K,
             len(bank) // max(K, 1), int(v.isna().sum()))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
