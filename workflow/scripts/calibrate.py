"""Calibration stage, rule calibrate: the backward stepwise reduction (Tables 1-3), the admissibility-constrained
final fit and its posterior, and the calibrated characteristic set (lumbar.experiments.calibration; the configured
run: lumbar.experiments.calibration.configured, shared with rule calibration_influence).

By hand: python workflow/scripts/calibrate.py calibrate --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import calibration as cal  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def _write_fit_tables(snakemake, log, res, targets):
    """The final fit's tables: targets, real-target fit, prior, penalties, posterior and its covariance."""
    (targets if targets is not None else pd.DataFrame(columns=list(cal.TARGET_COLUMNS)))[
        list(cal.TARGET_COLUMNS)].pipe(write_table_atomic, snakemake.output.targets)
    rf = res.info.get("real_fit")
    (rf if rf is not None else pd.DataFrame(columns=["parameter", "start", "value", "unit", "identifiable",
                                                     "at_bound"])).pipe(write_table_atomic, snakemake.output.real_fit)
    prior = res.info.get("prior")
    (prior if prior is not None else pd.DataFrame(columns=["ligament", "a_n", "b_pct", "c_n", "d_pct"])).pipe(
        write_table_atomic, snakemake.output.prior)
    ff = res.info.get("final_fit")
    (ff.penalties if ff is not None else pd.DataFrame(columns=["penalty", "value"])).pipe(
        write_table_atomic, snakemake.output.penalties)
    post_tab, cov_tab = cal.posterior_tables(ff, res.info.get("prior_name", ""))
    write_table_atomic(post_tab, snakemake.output.posterior)
    write_table_atomic(cov_tab, snakemake.output.covariance)
    if ff is not None and ff.posterior is not None:
        moved = post_tab[post_tab["data_moved_it"]]
        log.info("posterior: the data moved %d of %d parameters (%s); the others stay at their prior (%s)",
                 len(moved), len(post_tab), ", ".join(moved["parameter"]),
                 ", ".join(post_tab.loc[~post_tab["data_moved_it"], "parameter"]) or "none")
    return rf


def _log_bounds(snakemake, log, res, rf):
    """Which steps end with a parameter at a bound or unidentifiable, and bounds without a documented reason."""
    bound = [r for r in res.summary.itertuples() if getattr(r, "at_bound", False)]
    unidentifiable = [r for r in res.summary.itertuples() if not getattr(r, "identifiable", True)]
    log.info("calibration: %d of %d steps with a parameter at a bound (%s), %d not identifiable from their stage "
             "(kept at the start value: %s); see %s", len(bound), len(res.summary),
             "; ".join(f"{r.structure}: {r.at_bound_parameters}" for r in bound) or "none", len(unidentifiable),
             ", ".join(str(r.structure) for r in unidentifiable) or "none", snakemake.output.summary)
    if rf is not None and "bound_reason" in rf:
        unexplained = rf[rf["at_bound"].astype(bool) & (rf["bound_reason"].fillna("") == "")]
        if len(unexplained):
            log.warning("final calibration: parameter(s) %s end at a bound with no documented reason: check the fit "
                        "(%s)", ", ".join(unexplained["parameter"]), snakemake.output.real_fit)


def main(snakemake, log):
    p, i = snakemake.params, snakemake.input
    c = cal.calibrate_configured(p.geometry, p.fsu, p.solver, p.sr, i.experiment, _common.first(i.derived),
                                 _common.as_list(i.real_targets), i.characteristics, _common.first(i.generator_fit))
    res, paper, targets, data_kind = c.result, c.start_set, c.targets, c.data_kind
    out_dir = Path(snakemake.output.characteristics[0]).parent
    cal.write_characteristics(res, snakemake.input.characteristics, out_dir,
                              reference_source=f"{snakemake.input.experiment} ({data_kind})")
    load_characteristic_set("calibrated", data_dir=out_dir)   # round trip through the validated loader
    res.summary.assign(data_kind=data_kind).pipe(write_table_atomic, snakemake.output.summary)
    rf = _write_fit_tables(snakemake, log, res, targets)
    _log_bounds(snakemake, log, res, rf)
    res.rom_fit.assign(data_kind=data_kind).pipe(write_table_atomic, snakemake.output.rom_fit)
    res.disc_points.assign(data_kind=data_kind).pipe(write_table_atomic, snakemake.output.disc_points)
    res.ligament_points.assign(data_kind=data_kind).pipe(write_table_atomic, snakemake.output.ligament_points)
    write_table_atomic(cal.table1(res, paper), snakemake.output.table1)
    write_table_atomic(cal.table2(res, paper), snakemake.output.table2)
    write_table_atomic(cal.table3(res, paper), snakemake.output.table3)
    log.info("wrote %s and tables 1-3", out_dir)


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
