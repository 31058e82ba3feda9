"""Calibration stage, rule calibrate: the backward stepwise reduction (Tables 1-3), the admissibility-constrained
final fit and its posterior, and the calibrated characteristic set (lumbar.experiments.calibration). Its diagnostic
refits from the MAP are rule calibration_influence (calibration_influence.py, which calls :func:`run`).

By hand: python workflow/scripts/calibrate.py calibrate --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import pandas as pd  # noqa: E402

from lumbar.experiments import calibration as cal  # noqa: E402
from lumbar.experiments.stepwise_reduction import read_experiment_table, reference_table  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def _reference(snakemake, log):
    """The reference table (experiment, derived disc-only rows, real targets) and its data kind."""
    exp = read_experiment_table(snakemake.input.experiment)
    derived = read_experiment_table(_common.first(snakemake.input.derived)) \
        if _common.first(snakemake.input.derived) else None
    real = [read_experiment_table(p) for p in _common.as_list(snakemake.input.real_targets)]
    real = pd.concat(real, ignore_index=True) if real else None
    ref = reference_table(exp, derived, real)
    data_kind = "surrogate" if (ref["kind"] == "surrogate").any() else "measured"
    log.info("calibrating on %s (%d rows; kinds %s)", snakemake.input.experiment, len(ref),
             dict(ref["kind"].value_counts()))
    return ref, real, data_kind


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


def run(snakemake, log, row_influence=False):
    """The calibration of the config (:func:`lumbar.experiments.calibration.calibrate`); ``row_influence``: with
    the diagnostic refits from its MAP (rule calibration_influence). Returns (result, start set, targets, data
    kind)."""
    g, f, s, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.solver, snakemake.params.sr
    ref, real, data_kind = _reference(snakemake, log)
    geo = load_configured(g, levels=[f["level"]])
    paper = load_characteristic_set("calibrated", data_dir=snakemake.input.characteristics)
    anchor = cal.read_fit_start(_common.first(snakemake.input.generator_fit))
    targets, origin = cal.admissible_fit_targets(ref, real)
    if targets is None:
        log.warning("no intact ROM rows at 10 N*m in %s nor in stepwise_reduction.real_targets: the calibration ends "
                    "at the stepwise fits, WITHOUT the admissibility constraints (results/calibration/"
                    "admissibility.csv says which criteria the set fails)", snakemake.input.experiment)
    else:
        log.info("final fit (admissibility-constrained) pinned to %s (%d rows)", origin, len(targets))
    res = cal.calibrate(geo, ref, initial=paper, level=f["level"], k_shear=f.get("disc_shear_stiffness_n_per_m"),
                        tolerance_deg=sr["outlier_tolerance_deg"], data_kind=data_kind, max_iter=s["max_iter"],
                        surrogate_weight=sr["surrogate_weight"], family=sr["calibration_family"],
                        final_surrogate_weight=sr["final_surrogate_weight"],
                        real_targets=targets,
                        transfer=sr["ligament_transfer"],
                        geometry_path=g["path"] if g["kind"] == "visible_human" else None,
                        anchor_start_values=anchor, prior=sr["ligament_prior"],
                        row_influence=row_influence)
    log.info("calibration wall time %.1f s", res.wall_time_s)
    return res, paper, targets, data_kind


def main(snakemake, log):
    res, paper, targets, data_kind = run(snakemake, log)
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
