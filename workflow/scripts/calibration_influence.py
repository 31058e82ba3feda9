"""Calibration stage, rule calibration_influence: the calibration's diagnostic refits from its MAP (leave one real
row out, the facet stiffness held, the disc-only rows at a wider spread; lumbar.experiments.calibration.influence).

The calibration is run again (lumbar.experiments.calibration.calibrate_configured, as rule calibrate runs it;
deterministic) with the refits, in a job of its own so
that every stage reading the calibrated set starts while they run. The MAP it refits from must be the one rule
calibrate shipped (``posterior.csv``): a difference is an error, never a table about another fit.
With ``stepwise_reduction.row_influence: false`` the table is its header alone.

By hand: python workflow/scripts/calibration_influence.py calibration_influence --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.experiments import calibration as cal  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    if not bool(snakemake.params.sr.get("row_influence", True)):
        log.info("stepwise_reduction.row_influence is false: %s holds the header alone", snakemake.output.row_influence)
        write_table_atomic(pd.DataFrame(columns=list(cal.INFLUENCE_COLUMNS)), snakemake.output.row_influence)
        return
    p, i = snakemake.params, snakemake.input
    res = cal.calibrate_configured(p.geometry, p.fsu, p.solver, p.sr, i.experiment, _common.first(i.derived),
                                   _common.as_list(i.real_targets), i.characteristics, _common.first(i.generator_fit),
                                   row_influence=True).result
    post, _ = cal.posterior_tables(res.info.get("final_fit"), res.info.get("prior_name", ""))
    cal.check_same_map(pd.read_csv(snakemake.input.posterior), post, snakemake.input.posterior)
    infl = res.info.get("row_influence")
    infl = infl if infl is not None else pd.DataFrame(columns=list(cal.INFLUENCE_COLUMNS))
    write_table_atomic(infl, snakemake.output.row_influence)
    log.info("wrote %s (%d refits from the MAP; %d converged)", snakemake.output.row_influence, len(infl),
             int(np.sum(infl["converged"].astype(bool))) if "converged" in infl else len(infl))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
