"""L2-S1 IDP stage, rule l2s1_bands: the 90 % posterior band of every Table 5 scenario of the calibrated set (49 L4-L5
intradiscal pressures of the L2-S1 model with wire cables), by linearisation of the calibration's Laplace posterior
(lumbar.experiments.posterior.table_bands; one finite-difference step per fitted parameter).

By hand: python workflow/scripts/l2s1_bands.py l2s1_bands --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
from lumbar.experiments import l2s1  # noqa: E402
from lumbar.experiments.calibration import shift_parameter  # noqa: E402
from lumbar.experiments.fsu import unit_options  # noqa: E402
from lumbar.experiments.posterior import table_bands_from_files  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402

KEYS = ("muscle_setup", "load_case")


def main(snakemake, log):
    g, f, s, p = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.solver, snakemake.params.l2s1
    geo = load_configured(g, levels=list(l2s1.LEVELS))
    cs = load_characteristic_set("calibrated", data_dir=Path(_common.as_list(snakemake.input.characteristics)[0]).parent)
    cables = l2s1.derive_cables(snakemake.input.cables)

    def table_of(c):
        df, _ = l2s1.run_set(geo, c, cables, idp_formula=p["idp_formula"],
                             idp_kwargs={"area_m2": p["disc_area_m2"]} if p["idp_formula"] == "paper2" else None,
                             **unit_options(f),
                             load_steps=s["load_steps"], max_iter=s["max_iter"],
                             tol=min(s["tol_force_n"], s["tol_moment_nm"]), moment_nm=p["moment_nm"])
        return df

    bands, band = table_bands_from_files(snakemake.input.posterior, snakemake.input.covariance, snakemake.input.draws,
                                         table_of, "idp_mpa", KEYS, cs, shift_parameter)
    write_table_atomic(bands, snakemake.output[0])
    if not len(bands):
        log.info("the calibration has no posterior (no admissible fit): no bands")
    else:
        log.info("posterior bands of %d L2-S1 IDP scenarios; median 90 %% half-width %.3g MPa", len(bands),
                 float((bands["high90"] - bands["map"]).median()))
        log.info("how the bands were made: %s", band.summary())


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
