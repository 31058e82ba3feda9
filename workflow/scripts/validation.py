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

import pandas as pd  # noqa: E402

from lumbar.experiments import validation as V  # noqa: E402

if snakemake.rule == "validation_scoreboard_figure":
    table = pd.read_csv(snakemake.input[0])
    V.plot_scoreboard(table, snakemake.output[0])
    counts = V.role_counts(V.distinct_comparisons(table))
    log.info("validation scoreboard figure: %d rows, %s", len(table),
             "; ".join(f"{role}: {w} of {n} distinct comparisons within" for role, (w, n) in counts.items()))
    sys.exit(0)
from lumbar.inputs.characteristics import resolve_characteristic_set  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402

g, f, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.sr
geo = load_geometry(g["kind"], path=g["path"] if g["kind"] == "visible_human" else None, levels=[f["level"]])
cal_dir = Path(_common.as_list(snakemake.input.calibrated)[0]).parent
cs = resolve_characteristic_set("calibrated", calibrated_dir=cal_dir)
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.experiments.stepwise_reduction import read_experiment_table  # noqa: E402

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
