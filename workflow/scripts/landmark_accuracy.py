"""Geometry stage, rule landmark_accuracy: the automatic landmarks scored where the truth is known (the Visible Human
meshes given as a user gives them, leave one out; lumbar.geometry.specimen_accuracy) and what their error does to the
calibrated unit (lumbar.experiments.landmark_accuracy).

By hand: python workflow/scripts/landmark_accuracy.py landmark_accuracy --configfile config/config.yaml
"""
import logging
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
from lumbar.experiments.landmark_accuracy import landmark_error_effect  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.geometry.specimen_accuracy import visible_human_accuracy  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    p = snakemake.params.accuracy
    # the accuracy run's own facet-gap remarks (the reference meshes, not a user's) are results, not warnings: the
    # builder's log is held at ERROR during the run and the gaps are logged below
    builder = logging.getLogger("lumbar.geometry.specimen_build")
    level_before = builder.level
    builder.setLevel(logging.ERROR)
    try:
        res = visible_human_accuracy(seed=int(p["seed"]), folder=None)
    finally:
        builder.setLevel(level_before)
    log.info("facet bone gaps of the automatic landmarks (expected on bone surfaces; the sourced joint space is "
             "for cartilage-covered CT faces): %s", ", ".join(
                 f"{lv} {side} {1e3 * g:.2f} mm" for (lv, side), g in sorted(res["specimen"].facet_gaps.items())))
    write_table_atomic(res["summary"], snakemake.output.summary)
    write_table_atomic(res["groups"], snakemake.output.groups)
    write_table_atomic(res["lengths"], snakemake.output.lengths)
    write_table_atomic(res["facets"], snakemake.output.facets)
    s = res["summary"].set_index("structure")
    log.info("automatic landmarks (leave one out, seed %s): insertion-group centroids median %.2f mm, largest %.2f "
             "mm; facet faces vs cartilage nodes median %.2f mm", p["seed"],
             s.loc["all ligament groups", "median_mm"], s.loc["all ligament groups", "max_mm"],
             s.loc["facet faces vs cartilage nodes", "median_mm"])
    level = snakemake.params.level
    reference = load_geometry("visible_human", levels=[level])     # the embedded set: the truth
    charset = load_characteristic_set("calibrated", data_dir=Path(snakemake.input.characteristics[0]).parent)
    effect = landmark_error_effect(reference, res["specimen"].geometry, charset, level)
    write_table_atomic(effect, snakemake.output.effect)
    log.info("the calibrated %s unit on the automatic landmarks: %s", level, "; ".join(
        f"{r.quantity} {_short(r.reference_landmarks)} -> {_short(r.automatic_landmarks)}" for r in effect.itertuples()))


def _short(v):
    return f"{v:.3g}" if isinstance(v, float) else str(v)


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
