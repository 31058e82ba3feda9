"""Virtual experiment (virtual_experiment.smk), rule idp_surrogate: the SURROGATE L4-L5 IDP table of the L2-S1
scenarios, from virtual specimens of the generator set (lumbar.experiments.virtual_experiment; not measured).

By hand: python workflow/scripts/idp_surrogate.py idp_surrogate --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.experiments import l2s1  # noqa: E402
from lumbar.experiments.fsu import disc_shear_override  # noqa: E402
from lumbar.experiments.virtual_experiment import idp_table  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import resolve_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    p = snakemake.params.l2s1
    cal = _common.as_list(snakemake.input.calibrated)
    cs = resolve_characteristic_set(p["generator_set"], data_dir=snakemake.input.characteristics,
                                    calibrated_dir=Path(cal[0]).parent if cal else None)
    log.info("generator set %s from %s", p["generator_set"],
             Path(cal[0]).parent if cal and p["generator_set"] == "calibrated" else snakemake.input.characteristics)
    g = snakemake.params.geometry
    geo = load_configured(g, levels=list(l2s1.LEVELS))
    df = idp_table(geo, cs, snakemake.params.seed, n_specimens=p["n_specimens"], variation=p["variation"],
                   noise_sd_mpa=p["noise_sd_mpa"], cables=l2s1.derive_cables(snakemake.input.cables),
                   idp_formula=p["idp_formula"], k_shear=disc_shear_override(snakemake.params.fsu),
                   max_iter=snakemake.params.solver["max_iter"])
    log.info("SURROGATE IDP table: %d rows from %d virtual specimens of set %s", len(df), p["n_specimens"],
             p["generator_set"])
    write_table_atomic(df, snakemake.output[0])
    log.info("done: %s", ", ".join(map(str, snakemake.output)))

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
