"""Validation stage: rule validation_real_data, the scoreboard of comparisons with real data
(lumbar.validation).

By hand: python workflow/scripts/validation.py validation_real_data --configfile config/test/config.yaml
"""
import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("_common", Path(__file__).resolve().parent / "_common.py")
_common = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_common)

RULES = {
    "validation_real_data": lambda c: dict(
        input=dict(synopsis="results/tables/table4_rom_synopsis.csv",
                   real_targets=c["stepwise_reduction"]["real_targets"],
                   calibrated=["results/calibration/characteristics/disc.csv"],
                   va_artefact=c["discovery"]["va_artefact"],
                   anatomy="data/anatomy/l4l5_magnitudes_original_text.csv",
                   in_vivo="results/tables/in_vivo_validation.csv"),
        output=["results/tables/validation_real_data.csv"],
        params=dict(geometry=c["geometry"], fsu=c["fsu"], sr=c["stepwise_reduction"])),
}

if "snakemake" not in globals():
    snakemake = _common.stand_in(RULES, __doc__)

log = _common.setup_logging(snakemake)

import pandas as pd  # noqa: E402

from lumbar import validation as V  # noqa: E402
from lumbar.characteristics import resolve_characteristic_set  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.io import write_table_atomic  # noqa: E402

g, f, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.sr
geo = load_geometry(g["kind"], path=g["path"] if g["kind"] == "visible_human" else None, levels=[f["level"]])
cal_dir = Path(_common.as_list(snakemake.input.calibrated)[0]).parent
cs = resolve_characteristic_set("calibrated", calibrated_dir=cal_dir)
from lumbar.characteristics import load_characteristic_set  # noqa: E402
from lumbar.stepwise_reduction import read_experiment_table  # noqa: E402

rows = V.rom_rows(pd.read_csv(snakemake.input.synopsis), sr["outlier_tolerance_deg"])
for p in _common.as_list(snakemake.input.real_targets):
    real = read_experiment_table(p)
    rows += V.measured_rom_rows(geo, cs, real, "calibrated", f["level"], role=V.TARGET)
    # the paper's published set on this geometry, as printed (no re-calibration): how far it is from real data
    rows += V.measured_rom_rows(geo, load_characteristic_set("calibrated"), real, "paper_table3_as_published",
                                f["level"], role=V.INDEPENDENT)
rows += V.va_artefact_rows(geo, cs, pd.read_csv(snakemake.input.va_artefact), level=f["level"])
rows += V.in_vivo_rows(pd.read_csv(snakemake.input.in_vivo))
rows += V.anatomy_rows(geo, pd.read_csv(snakemake.input.anatomy), level=f["level"])
df = V.scoreboard(rows)
write_table_atomic(df, snakemake.output[0])
ind = df[df["role"] == V.INDEPENDENT]
tgt = df[df["role"] == V.TARGET]
log.info("real-data scoreboard: independent comparisons %d of %d within; calibration targets %d of %d met",
         int(ind["within"].sum()), len(ind), int(tgt["within"].sum()), len(tgt))
for r in df[~df["within"].astype(bool)].itertuples(index=False):
    log.info("outside: %s %s (%s): sim %.4g vs measured %.4g %s", r.quantity, r.condition, r.set, r.sim, r.measured,
             r.unit)
