"""Admissibility stage: rule admissibility, the physical-admissibility criteria of the calibrated set at the
calibrated level (lumbar.experiments.admissibility), from the load-sharing curves of that set.

By hand: python workflow/scripts/admissibility.py admissibility --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

import pandas as pd  # noqa: E402

from lumbar.experiments import admissibility as ADM  # noqa: E402
from lumbar.experiments.calibration import read_prior_set  # noqa: E402
from lumbar.geometry.configured import load_configured, visible_human_path  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402

g, f = snakemake.params.geometry, snakemake.params.fsu
geo = load_configured(g, levels=[f["level"]])
published = load_characteristic_set("calibrated", data_dir=Path(_common.as_list(snakemake.input.published)[0]).parent)
cal = load_characteristic_set("calibrated", data_dir=Path(_common.as_list(snakemake.input.characteristics)[0]).parent)
on_elongation = any(getattr(law, "law_length_m", None) is not None for law in cal.ligaments.values())
prior = read_prior_set(snakemake.input.prior, published) if on_elongation else published
limits = ADM.pretension_limits(published, prior, geo, f["level"],
                               visible_human_path(g))
remus = None
if visible_human_path(g) is not None:
    from lumbar.experiments.fsu import configured_unit

    remus = ADM.remus_comparison(configured_unit(geo, cal, f), visible_human_path(g))
(remus if remus is not None else pd.DataFrame(columns=["ligament", "state", "model_n", "remus2021_n", "ratio"])).pipe(
    write_table_atomic, snakemake.output.remus)
table = ADM.criteria_table(pd.read_csv(snakemake.input.curves), pd.read_csv(snakemake.input.compression), limits,
                           f["level"], ADM.neutral_zones(f["level"], snakemake.input.yamamoto),
                           ADM.read_literature(snakemake.input.literature), ADM.force_scales(cal, prior),
                           pd.read_csv(snakemake.input.real_fit), remus=remus)
write_table_atomic(table, snakemake.output.table)
write_table_atomic(limits, snakemake.output.limits)
failed = table[~table["passed"]]
log.info("admissibility of the calibrated set at %s: %d of %d criteria pass", f["level"], len(table) - len(failed),
         len(table))
if len(failed):
    log.warning("the calibrated set fails %d admissibility criteria (%s): see %s", len(failed),
                "; ".join(f"{r.criterion} {r.direction}".strip() for r in failed.itertuples()), snakemake.output.table)
