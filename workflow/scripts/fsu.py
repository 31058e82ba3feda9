"""FSU stage: rule fsu_rom, the range of motion of the intact L4-L5 unit for every characteristic set.

By hand: python workflow/scripts/fsu.py fsu_rom --configfile config/test/config.yaml --output /tmp/rom.csv
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import pandas as pd  # noqa: E402

snakemake, log = _common.start(globals())

from lumbar.inputs.characteristics import resolve_characteristic_set  # noqa: E402
from lumbar.experiments.fsu import configured_unit, range_of_motion  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402

g, f, s = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.solver
geo = load_configured(g, levels=[f["level"]])
tables = []
for name in snakemake.params.sets:
    cal = _common.as_list(snakemake.input.calibrated)
    cs = resolve_characteristic_set(name, data_dir=snakemake.input.characteristics,
                                    calibrated_dir=Path(cal[0]).parent if cal else None)
    fsu = configured_unit(geo, cs, f)
    df = range_of_motion(fsu, f["moments_nm"], f["directions"], stages=["intact"], load_steps=s["load_steps"],
                         max_iter=s["max_iter"], tol=min(s["tol_force_n"], s["tol_moment_nm"]))
    df.insert(0, "set", name)
    df.insert(1, "geometry", geo.name)
    n_bad = int((~df["converged"]).sum())
    log.info("set %s: %d scenarios, %d not converged", name, len(df), n_bad)
    if n_bad:
        log.warning("set %s: %d scenario(s) did not converge; rom_deg is NaN there", name, n_bad)
    tables.append(df)
write_table_atomic(pd.concat(tables, ignore_index=True), snakemake.output[0])
log.info("wrote %s", snakemake.output[0])
