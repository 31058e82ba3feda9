"""Load-sharing stage, rule load_sharing_bands: the 90 % posterior bands of the calibrated unit's intact
moment-rotation curves and internal loads, by linearisation, checked, and from posterior draws where the check
fails (the calibration's Laplace posterior, role calibration.covariance of the stage manifests;
lumbar.experiments.posterior.curve_bands).

By hand: python workflow/scripts/load_sharing_bands.py load_sharing_bands --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from lumbar.experiments import load_sharing as LS  # noqa: E402
from lumbar.experiments.calibration import shift_parameter  # noqa: E402
from lumbar.experiments.fsu import configured_unit  # noqa: E402
from lumbar.experiments.posterior import (BAND_COLUMNS, DRAW_VALUE_COLUMNS, curve_bands, curve_draws_table,  # noqa: E402
                                         read_draw_offsets, read_posterior)
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    g, f, s, ls = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.solver, snakemake.params.ls
    post = read_posterior(snakemake.input.posterior, snakemake.input.covariance)
    if post is None:
        log.info("the calibration has no posterior (no admissible fit): no bands")
        write_table_atomic(pd.DataFrame(columns=list(BAND_COLUMNS)), snakemake.output.bands)
        write_table_atomic(pd.DataFrame(columns=list(DRAW_VALUE_COLUMNS)), snakemake.output.band_draws)
        return
    names, cov = post
    geo = load_configured(g, levels=[f["level"]])
    cs = load_characteristic_set("calibrated", data_dir=Path(_common.as_list(snakemake.input.characteristics)[0]).parent)
    moments = np.round(np.arange(0.0, ls["max_moment_nm"] + 1e-9, ls["moment_step_nm"]), 6)

    def build(c):
        return configured_unit(geo, c, f)

    def curves_of(fsu):
        return LS.moment_rotation_curves(fsu, moments_nm=moments, stages=("intact",), max_iter=s["max_iter"])

    offsets = read_draw_offsets(snakemake.input.posterior, snakemake.input.draws, names)
    bands, band = curve_bands(build, cs, names, cov, shift_parameter, curves_of, list(LS.CURVE_DIRECTIONS), moments,
                              offsets=offsets)
    write_table_atomic(bands, snakemake.output.bands)
    write_table_atomic(curve_draws_table(bands, band), snakemake.output.band_draws)
    top = bands[np.isclose(bands["moment_nm"], moments[-1]) & (bands["quantity"] == "rotation_deg")]
    log.info("posterior bands of the intact curves (%d parameters, %d values); rotation at %g N*m: %s", len(names),
             len(bands), moments[-1], "; ".join(f"{r.direction} {r.map:.2f} +- {1.645 * r.sd:.2f} deg"
                                               for r in top.itertuples()))
    log.info("how the bands were made: %s", band.summary())


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
