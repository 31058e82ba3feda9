"""Validation stage (lumbar.experiments.validation): rule validation_real_data, the scoreboard of comparisons with
real data, and rule validation_scoreboard_figure, its figure (the report's first figure).

By hand: python workflow/scripts/validation.py validation_real_data --configfile config/test/config.yaml
         python workflow/scripts/validation.py validation_scoreboard_figure --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.experiments import validation as V  # noqa: E402
from lumbar.plots import validation as VP  # noqa: E402

if snakemake.rule == "validation_scoreboard_figure":
    table = pd.read_csv(snakemake.input[0])
    VP.plot_scoreboard(table, snakemake.output[0])
    counts = V.role_counts(V.distinct_comparisons(table))
    log.info("validation scoreboard figure: %d rows, %s", len(table),
             "; ".join(f"{role}: {w} of {n} distinct comparisons within" for role, (w, n) in counts.items()))
    sys.exit(0)
from lumbar.inputs.characteristics import resolve_characteristic_set  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402

if snakemake.rule == "multilevel_validation":
    from lumbar.experiments import admissibility as ADM  # noqa: E402
    from lumbar.experiments.calibration import read_prior_set  # noqa: E402
    from lumbar.experiments import level_transfer as LT  # noqa: E402
    from lumbar.experiments.fsu import build_fsu  # noqa: E402
    from lumbar.experiments.load_sharing import moment_rotation_curves  # noqa: E402
    from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402

    g, f, ls = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.ls
    levels = [lv for lv in ls["other_levels"] if lv != f["level"]]
    geo = load_geometry(g["kind"], path=g["path"] if g["kind"] == "visible_human" else None,
                        levels=levels + [f["level"]])
    published = load_characteristic_set("calibrated",
                                    data_dir=Path(_common.as_list(snakemake.input.published)[0]).parent)
    cal = load_characteristic_set("calibrated",
                                  data_dir=Path(_common.as_list(snakemake.input.characteristics)[0]).parent)
    on_elongation = any(getattr(law, "law_length_m", None) is not None for law in cal.ligaments.values())
    prior = read_prior_set(snakemake.input.prior, published) if on_elongation else published
    lit = ADM.read_literature(snakemake.input.literature)
    moments = np.round(np.arange(0.0, ls["max_moment_nm"] + 1e-9, ls["moment_step_nm"]), 6)
    curves, adm = [], []
    for lv in levels:
        fsu = build_fsu(geo, cal, lv, facet_stiffness=f.get("facet_stiffness_n_per_m"),
                        k_shear=f.get("disc_shear_stiffness_n_per_m"), follower=True)
        cv, comp = ADM.assess(fsu, fsu, moments_nm=moments)
        cv.insert(0, "level", lv)
        curves.append(cv)
        vh_path = g["path"] if g["kind"] == "visible_human" else None
        limits = ADM.pretension_limits(published, prior, geo, lv, vh_path)
        # the force scales' sourced exception, evaluated on this level's fibres (as at the calibrated level)
        remus = None if vh_path is None else ADM.remus_comparison(
            build_fsu(geo, cal, lv, facet_stiffness=f.get("facet_stiffness_n_per_m"),
                      k_shear=f.get("disc_shear_stiffness_n_per_m")), vh_path)
        adm.append(ADM.criteria_table(cv, comp, limits, lv, ADM.neutral_zones(lv, snakemake.input.yamamoto), lit,
                                      ADM.force_scales(cal, prior), remus=remus))
    curves = pd.concat(curves, ignore_index=True)
    adm = pd.concat(adm, ignore_index=True)
    rom = V.multilevel_rom(curves, pd.read_csv(snakemake.input.yamamoto))
    # the 90 % posterior band of every level's ROM (linearisation of the calibration's posterior)
    from lumbar.experiments.calibration import shift_parameter  # noqa: E402
    from lumbar.experiments.posterior import read_posterior  # noqa: E402

    post = read_posterior(snakemake.input.posterior, snakemake.input.covariance)
    if post is not None and len(rom):
        bands = V.level_rom_bands(geo, cal, levels, post[0], post[1], shift_parameter,
                                  facet_stiffness=f.get("facet_stiffness_n_per_m"),
                                  k_shear=f.get("disc_shear_stiffness_n_per_m"))
        rom = rom.merge(bands[["level", "direction", "band_low", "band_high"]].rename(
            columns={"band_low": "sim_band_low", "band_high": "sim_band_high"}), on=["level", "direction"],
            how="left")
    write_table_atomic(curves, snakemake.output.curves)
    write_table_atomic(adm, snakemake.output.admissibility)
    write_table_atomic(rom, snakemake.output.rom)
    VP.plot_multilevel(rom, curves, snakemake.output.figure)
    # the same levels (and the calibrated one) under the other readings of the transfer (lumbar.experiments.
    # level_transfer): whether a miss comes from the transfer rule or from what the model does not have
    yam = pd.read_csv(snakemake.input.yamamoto)
    kw = dict(facet_stiffness=f.get("facet_stiffness_n_per_m"), k_shear=f.get("disc_shear_stiffness_n_per_m"))
    by_reading = {}
    for reading in LT.READINGS:
        cvs = [curves[curves["stage"] == "intact"]] if reading == "as_calibrated" else []
        for lv in ([f["level"]] if reading == "as_calibrated" else levels + [f["level"]]):
            cv = moment_rotation_curves(LT.reading_unit(reading, geo, cal, lv, geo.levels[f["level"]], build_fsu,
                                                        **kw), moments_nm=moments)
            cv.insert(0, "level", lv)
            cvs.append(cv)
        by_reading[reading] = V.multilevel_rom(pd.concat(cvs, ignore_index=True), yam)
    readings = LT.readings_table(by_reading, f["level"], ls["moment_step_nm"])
    summary = LT.readings_summary(readings)
    write_table_atomic(readings, snakemake.output.readings)
    jumps = adm[adm["criterion"].str.startswith("no snap-through") & ~adm["passed"]]
    log.info("other levels (calibrated set unchanged): %d of %d ROM values within %s; %d of %d admissibility "
             "criteria pass; snap-through at %d (level, direction) pairs; other readings of the transfer: %s",
             int(rom["within"].sum()), len(rom), rom["tolerance_rule"].iloc[0] if len(rom) else "-",
             int(adm["passed"].sum()), len(adm), len(jumps),
             ", ".join(f"{r.reading} {r.other_within} of {r.other_n}" for r in summary.itertuples()
                       if r.reading != "as_calibrated"))
    sys.exit(0)

g, f, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.sr
geo = load_geometry(g["kind"], path=g["path"] if g["kind"] == "visible_human" else None, levels=[f["level"]])
cal_dir = Path(_common.as_list(snakemake.input.calibrated)[0]).parent
cs = resolve_characteristic_set("calibrated", calibrated_dir=cal_dir)
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.experiments.stepwise_reduction import read_experiment_table  # noqa: E402

rows = V.rom_rows(pd.read_csv(snakemake.input.synopsis), sr["outlier_tolerance_deg"])
fitted = pd.read_csv(snakemake.input.fitted)
real_files = [read_experiment_table(p) for p in _common.as_list(snakemake.input.real_targets)]
for real in real_files:
    # rows the final fit was pinned to are calibration targets; the others (e.g. Yamamoto et al. 1989 when a
    # measured stepwise table brings its own intact rows) are independent checks
    is_fit = V.fitted_mask(real, fitted)
    rows += V.measured_rom_rows(geo, cs, real[is_fit], "calibrated", f["level"], role=V.TARGET)
    rows += V.measured_rom_rows(geo, cs, real[~is_fit], "calibrated", f["level"], role=V.INDEPENDENT)
    # the paper's published set on this geometry, as printed (no re-calibration): how far it is from real data
    rows += V.measured_rom_rows(geo, load_characteristic_set("calibrated"), real, "paper_table3_as_published",
                                f["level"], role=V.INDEPENDENT)
# fitted rows of no real_targets file: the measured stepwise table's own intact rows
own = fitted[~np.any([V.fitted_mask(fitted, r) for r in real_files], axis=0)] if real_files else fitted
rows += V.measured_rom_rows(geo, cs, own, "calibrated", f["level"], role=V.TARGET)
rows += V.va_artefact_rows(geo, cs, pd.read_csv(snakemake.input.va_artefact), level=f["level"])
rows += V.in_vivo_rows(pd.read_csv(snakemake.input.in_vivo))
# a measured in-vitro IDP table (l2s1.measured_table): independent, no fit uses it
idp_table = snakemake.params.idp_table
rows += V.idp_in_vitro_rows(pd.read_csv(snakemake.input.idp_synopsis), pd.read_csv(idp_table) if idp_table else None)
rows += V.anatomy_rows(geo, pd.read_csv(snakemake.input.anatomy), level=f["level"])
rows += V.multilevel_rows(pd.read_csv(snakemake.input.multilevel))
# the calibrated unit's internal loads against sourced ranges (judged, never fitted; rows the admissible fit also holds
# as penalties are marked as fit constraints)
rows += V.internal_load_rows(pd.read_csv(snakemake.input.curves), pd.read_csv(snakemake.input.compression),
                             pd.read_csv(snakemake.input.literature))
df = V.scoreboard(rows, pd.read_csv(snakemake.input.bands))
write_table_atomic(df, snakemake.output.table)
nulls = V.null_model_counts(df, pd.read_csv(snakemake.input.yamamoto), f["level"])
write_table_atomic(nulls, snakemake.output.null_models)
for r in nulls.itertuples(index=False):
    log.info("%s: the model %d of %d within, a trivial model (%s) %d", r.quantity, r.model_within, r.n_rows,
             r.null_model, r.null_within)
ind = df[df["role"] == V.INDEPENDENT]
tgt = df[df["role"] == V.TARGET]
log.info("real-data scoreboard: independent comparisons %d of %d within; calibration targets %d of %d met",
         int(ind["within"].sum()), len(ind), int(tgt["within"].sum()), len(tgt))
for r in df[~df["within"].astype(bool)].itertuples(index=False):
    log.info("outside: %s %s (%s): sim %.4g vs measured %.4g %s", r.quantity, r.condition, r.set, r.sim, r.measured,
             r.unit)
