"""Validation stage, rule multilevel_validation: the calibrated L4-L5 characteristics applied unchanged at the other
levels (as paper 1 does for L2-S1): their curves, admissibility, ROM against Yamamoto et al. 1989 with the 90 %
posterior band, the figure (lumbar.plots.validation), and the other readings of the level transfer
(lumbar.experiments.level_transfer).

By hand: python workflow/scripts/multilevel_validation.py multilevel_validation --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.experiments import admissibility as ADM  # noqa: E402
from lumbar.experiments import level_transfer as LT  # noqa: E402
from lumbar.experiments.calibration import read_prior_set, shift_parameter  # noqa: E402
from lumbar.experiments import validation as V  # noqa: E402
from lumbar.experiments.fsu import build_fsu, configured_unit, unit_options  # noqa: E402
from lumbar.experiments.load_sharing import moment_rotation_curves  # noqa: E402
from lumbar.experiments.posterior import read_draw_offsets, read_posterior  # noqa: E402
from lumbar.geometry.configured import load_configured, visible_human_path  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots.validation import plot_multilevel  # noqa: E402


def main(snakemake, log):
    g, f, ls = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.ls
    levels = [lv for lv in ls["other_levels"] if lv != f["level"]]
    geo = load_configured(g,
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
        fsu = configured_unit(geo, cal, f, lv, follower=True)
        cv, comp = ADM.assess(fsu, fsu, moments_nm=moments)
        cv.insert(0, "level", lv)
        curves.append(cv)
        vh_path = visible_human_path(g)
        limits = ADM.pretension_limits(published, prior, geo, lv, vh_path)
        # the force scales' sourced exception, evaluated on this level's fibres (as at the calibrated level)
        remus = None if vh_path is None else ADM.remus_comparison(
            configured_unit(geo, cal, f, lv), vh_path)
        adm.append(ADM.criteria_table(cv, comp, limits, lv, ADM.neutral_zones(lv, snakemake.input.yamamoto), lit,
                                      ADM.force_scales(cal, prior), remus=remus))
    curves = pd.concat(curves, ignore_index=True)
    adm = pd.concat(adm, ignore_index=True)
    rom = V.multilevel_rom(curves, pd.read_csv(snakemake.input.yamamoto))
    # the 90 % posterior band of every level's ROM (linearisation of the calibration's posterior)
    post = read_posterior(snakemake.input.posterior, snakemake.input.covariance)
    if post is not None and len(rom):
        bands = V.level_rom_bands(geo, cal, levels, post[0], post[1], shift_parameter,
                                  offsets=read_draw_offsets(snakemake.input.posterior, snakemake.input.draws, post[0]),
                                  **unit_options(f))
        rom = rom.merge(bands[["level", "direction", "band_low", "band_high"]].rename(
            columns={"band_low": "sim_band_low", "band_high": "sim_band_high"}), on=["level", "direction"],
            how="left")
    write_table_atomic(curves, snakemake.output.curves)
    write_table_atomic(adm, snakemake.output.admissibility)
    write_table_atomic(rom, snakemake.output.rom)
    plot_multilevel(rom, curves, snakemake.output.figure)
    # the same levels (and the calibrated one) under the other readings of the transfer (lumbar.experiments.
    # level_transfer): whether a miss comes from the transfer rule or from what the model does not have
    yam = pd.read_csv(snakemake.input.yamamoto)
    kw = unit_options(f)
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


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
