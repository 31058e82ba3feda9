"""Virtual-experiment stage: rule stepwise_reduction_surrogate, a SURROGATE stepwise-reduction ROM table
from virtual specimens (the measured table of Heuer et al. 2007 is not available to the project).

By hand: python workflow/scripts/virtual_experiment.py stepwise_reduction_surrogate \
    --configfile config/test/config.yaml --output /tmp/surrogate.csv /tmp/generator_fit.csv /tmp/generator_targets.csv
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.geometry.configured import load_configured, visible_human_path  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.experiments.fsu import disc_shear_override  # noqa: E402
from lumbar.experiments.virtual_experiment import stepwise_reduction_table  # noqa: E402

g, f, s, sr = snakemake.params.geometry, snakemake.params.fsu, snakemake.params.solver, snakemake.params.sr
geo = load_configured(g, levels=[f["level"]])
cs = load_characteristic_set(sr["generator_set"], data_dir=snakemake.input.characteristics)
if sr.get("anchor_generator") and sr.get("real_targets"):
    import pandas as pd  # noqa: E402

    from lumbar.experiments.calibration import calibration_prior, fit_admissible, fit_real_targets  # noqa: E402
    from lumbar.experiments.stepwise_reduction import read_experiment_table  # noqa: E402

    targets = pd.concat([read_experiment_table(p) for p in sr["real_targets"]], ignore_index=True)
    if sr["ligament_transfer"] == "elongation":
        published = cs
        vh_path = visible_human_path(g)
        cs, _, spreads = calibration_prior(published, geo, f["level"], vh_path, sr["ligament_prior"])
        derived = _common.first(snakemake.input.get("derived", []))
        fit = fit_admissible(geo, cs, targets, level=f["level"], published=published, geometry_path=vh_path,
                             k_shear=disc_shear_override(f), max_iter=s["max_iter"],
                             prior_spread=spreads,
                             disc_rows=read_experiment_table(derived) if derived else None,
                             diagnostic=True)      # an anchor of the virtual specimens: its verdict is a column
    else:
        fit = fit_real_targets(geo, cs, targets, level=f["level"], k_shear=disc_shear_override(f),
                               max_iter=s["max_iter"])
    cs = fit.charset
    out = fit.parameters.assign(role="generator anchoring (force scales of the generator set)",
                                map_converged=bool(getattr(fit, "optimizer", {}).get("converged", True)))
    tg = fit.targets.rename(columns={"rom_mean_deg": "value_measured", "rom_sim_deg": "value_sim"})
    write_table_atomic(out, snakemake.output.generator_fit)
    write_table_atomic(tg, snakemake.output.generator_targets)
    log.info("generator anchored on %s: %s; rel. errors %s", sr["real_targets"],
             "; ".join(f"{r.parameter}={r.value:.4g}{' (AT BOUND)' if r.at_bound else ''}"
                       for r in fit.parameters.itertuples()), [round(v, 3) for v in fit.targets["rel_error"]])
else:
    import pandas as pd  # noqa: E402

    write_table_atomic(pd.DataFrame(columns=["parameter", "start", "value", "unit", "identifiable", "at_bound"]),
                       snakemake.output.generator_fit)
    write_table_atomic(pd.DataFrame(columns=["stage", "direction", "moment_nm", "value_measured", "value_sim"]),
                       snakemake.output.generator_targets)
effects = {k: v for k, v in sr["effects"].items() if v is not None}
log.info("SURROGATE stepwise-reduction table: %d virtual specimens, seed %d, noise %.3g deg, set %s, effects %s",
         sr["n_specimens"], snakemake.params.seed, sr["noise_sd_deg"], cs.name, effects or "none")
df = stepwise_reduction_table(geo, cs, snakemake.params.seed, n_specimens=sr["n_specimens"],
                              variation=sr["variation"], noise_sd_deg=sr["noise_sd_deg"],
                              effects={"disc_tension": effects["disc_tension_n_per_m"]}
                              if "disc_tension_n_per_m" in effects else None,
                              moments_nm=sr["moments_nm"], level=f["level"],
                              k_shear=disc_shear_override(f), max_iter=s["max_iter"])
write_table_atomic(df, snakemake.output.table)
log.info("wrote %s (%d rows, kind=surrogate)", snakemake.output.table, len(df))
