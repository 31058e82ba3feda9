"""Stepwise-reduction stage, rule stepwise_reduction_sim: one characteristic set, 160 scenarios (stage x direction x
moment; lumbar.experiments.stepwise_reduction).

By hand: python workflow/scripts/stepwise_reduction_sim.py stepwise_reduction_sim set=chazal1985 \
    --configfile config/test/config.yaml --output /tmp/rom_chazal1985.csv
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.experiments import stepwise_reduction as sr_mod  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    s, sr = snakemake.params.solver, snakemake.params.sr
    set_name, data_dir, fsu = _common.set_fsu(snakemake)
    sim = sr_mod.simulate_stepwise_reduction(fsu, moments_nm=sr["moments_nm"], max_iter=s["max_iter"],
                                             tol=min(s["tol_force_n"], s["tol_moment_nm"]), load_steps=s["load_steps"])
    sim.insert(0, "set", set_name)
    bad = sim.loc[~sim["converged"]]
    where = ", ".join(f"{st} ({n})" for st, n in bad.groupby("stage", sort=False).size().items())
    saddle = sorted(set(sim.loc[~sim["rest_state_stable"].astype(bool), "stage"]))
    log.info("set %s (characteristics from %s): %d scenarios, %d not converged%s; ROM measured from an unstable "
             "0 N*m state (rest_state_stable=False): %s", set_name, data_dir, len(sim), len(bad),
             f" (by stage: {where})" if len(bad) else "", ", ".join(saddle) or "none")
    write_table_atomic(sim, snakemake.output[0])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
