"""Validation stage (lumbar.experiments.validation), rule validation_real_data: the scoreboard of every comparison
with real data (independent checks, calibration targets, internal loads), and the counts of trivial null models.

By hand: python workflow/scripts/validation_real_data.py validation_real_data --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.experiments import validation as V  # noqa: E402
from lumbar.experiments.stepwise_reduction import read_experiment_table  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set, resolve_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    g, f, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.sr
    geo = load_configured(g, levels=[f["level"]])
    cal_dir = Path(_common.as_list(snakemake.input.calibrated)[0]).parent
    cs = resolve_characteristic_set("calibrated", calibrated_dir=cal_dir)
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
    df = V.scoreboard(rows, pd.read_csv(snakemake.input.bands), pd.read_csv(snakemake.input.band_draws))
    write_table_atomic(df, snakemake.output.table)
    bands = pd.read_csv(snakemake.input.bands)
    own = bands[(bands["quantity"] == "rotation_deg") & np.isclose(bands["moment_nm"].astype(float), 10.0)]
    nulls = V.null_model_counts(df, pd.read_csv(snakemake.input.yamamoto), f["level"],
                                dict(zip(own["direction"], own["map"])))
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


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
