"""Stepwise-reduction stage, rule stepwise_reduction_bands: the 90 % posterior band of every Table 4 scenario of the
calibrated set (160 ROM values), by linearisation of the calibration's Laplace posterior
(lumbar.experiments.posterior.table_bands; one finite-difference step per fitted parameter).

By hand: python workflow/scripts/stepwise_reduction_bands.py stepwise_reduction_bands --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
from lumbar.experiments import stepwise_reduction as sr_mod  # noqa: E402
from lumbar.experiments.calibration import shift_parameter  # noqa: E402
from lumbar.experiments.fsu import configured_unit  # noqa: E402
from lumbar.experiments.posterior import table_bands_from_files  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402

KEYS = ("stage", "direction", "moment_nm")


def main(snakemake, log):
    g, f, s, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.solver, snakemake.params.sr
    geo = load_configured(g, levels=[f["level"]])
    cs = load_characteristic_set("calibrated", data_dir=Path(_common.as_list(snakemake.input.characteristics)[0]).parent)

    def table_of(c):
        fsu = configured_unit(geo, c, f)
        return sr_mod.simulate_stepwise_reduction(fsu, moments_nm=sr["moments_nm"], max_iter=s["max_iter"],
                                                  tol=min(s["tol_force_n"], s["tol_moment_nm"]),
                                                  load_steps=s["load_steps"])

    bands, band = table_bands_from_files(snakemake.input.posterior, snakemake.input.covariance, snakemake.input.draws,
                                         table_of, "rom_deg", KEYS, cs, shift_parameter)
    write_table_atomic(bands, snakemake.output[0])
    if not len(bands):
        log.info("the calibration has no posterior (no admissible fit): no bands")
    else:
        log.info("posterior bands of %d stepwise-reduction scenarios; median 90 %% half-width %.3g deg", len(bands),
                 float((bands["high90"] - bands["map"]).median()))
        log.info("how the bands were made: %s", band.summary())


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
