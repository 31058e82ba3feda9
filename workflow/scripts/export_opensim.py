"""OpenSim export stage, rule export_opensim: the calibrated units of every level as .osim models, the calibration's
90 % intervals beside them, and the OpenSim check (lumbar.experiments.export_opensim).

By hand: python workflow/scripts/export_opensim.py export_opensim --configfile config/test/config.yaml
"""
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import pandas as pd  # noqa: E402

from lumbar.experiments.export_opensim import check_table, export_set, parameter_intervals  # noqa: E402
from lumbar.plots.export_opensim import check_figure  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import resolve_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    e = snakemake.params.export
    geo = load_configured(snakemake.params.geometry)
    cal = _common.as_list(snakemake.input.calibrated)
    cs = resolve_characteristic_set("calibrated", calibrated_dir=Path(cal[0]).parent)
    out = Path(snakemake.output.models)
    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    files, fits = export_set(geo, cs, {"fsu": snakemake.params.fsu}, "calibrated", tmp, levels=e.get("levels"))
    write_table_atomic(fits, tmp / "reduced_joints.csv")
    write_table_atomic(parameter_intervals(pd.read_csv(snakemake.input.posterior)), tmp / "parameter_intervals.csv")
    log.info("wrote %d models of %s (levels %s) to %s", int((files["variant"] == "detailed").sum()), geo.name,
             sorted(set(files["level"])), out)
    table = check_table(files, "calibrated", e["moments_nm"], e["directions"])
    table["model_file"] = [f"check/{f}" if v == "detailed_no_facets" else f
                           for f, v in zip(table["model_file"], table["variant"])]
    shutil.rmtree(out, ignore_errors=True)
    tmp.replace(out)
    write_table_atomic(table, snakemake.output.check)
    check_figure(table, snakemake.output.figure)
    bad = table[table["status"] != "ok"]
    if len(bad) and bad["status"].str.startswith("opensim not available").all():
        log.info("OpenSim check not run: %s", bad["status"].iloc[0])
    elif len(bad):
        log.warning("OpenSim check: %d of %d scenarios not solved by both engines (status column of %s)", len(bad),
                    len(table), snakemake.output.check)
    ok = table[table["status"] == "ok"]
    for v, g in ok.groupby("variant"):
        log.info("OpenSim check, %s: largest |difference| %.2g deg (%.1f %%) over %d scenarios", v,
                 g["difference_deg"].abs().max(), 100 * g["relative_difference"].abs().max(), len(g))


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
