"""Geometry stage, rule landmark_accuracy: the automatic landmarks scored where the truth is known (the Visible Human
meshes given as a user gives them, leave one out; lumbar.geometry.specimen_accuracy) and what their error does to the
calibrated unit (lumbar.experiments.landmark_accuracy).

By hand: python workflow/scripts/landmark_accuracy.py landmark_accuracy --configfile config/config.yaml
"""
import logging
import sys
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
from lumbar.experiments.landmark_accuracy import landmark_error_effect  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.geometry.specimen_accuracy import (visible_human_accuracy, voxelised_accuracy,  # noqa: E402
                                               voxelised_tables)
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


@contextmanager
def _builder_quiet():
    """The accuracy runs' own facet-gap remarks (the reference meshes, not a user's) are results, not warnings: the
    builder's log is held at ERROR during a run and the gaps are logged by main."""
    builder = logging.getLogger("lumbar.geometry.specimen_build")
    level_before = builder.level
    builder.setLevel(logging.ERROR)
    try:
        yield
    finally:
        builder.setLevel(level_before)


def main(snakemake, log):
    p = snakemake.params.accuracy
    with _builder_quiet():
        res = visible_human_accuracy(seed=int(p["seed"]), folder=None)
    log.info("facet bone gaps of the automatic landmarks (expected on bone surfaces; the sourced joint space is "
             "for cartilage-covered CT faces): %s", ", ".join(
                 f"{lv} {side} {1e3 * g:.2f} mm" for (lv, side), g in sorted(res["specimen"].facet_gaps.items())))
    write_table_atomic(res["summary"], snakemake.output.summary)
    write_table_atomic(res["groups"], snakemake.output.groups)
    write_table_atomic(res["lengths"], snakemake.output.lengths)
    write_table_atomic(res["facets"], snakemake.output.facets)
    s = res["summary"].set_index("structure")
    runs = {}
    for h in p.get("voxel_mm", []):
        with _builder_quiet():
            runs[float(h)] = voxelised_accuracy(float(h), seed=int(p["seed"]))
        v = runs[float(h)]["summary"].set_index("structure")
        log.info("label volume at %s mm voxels (%d voxels inside two meshes given to the deeper one): insertion-group "
                 "centroids median %.2f mm, largest %.2f mm; facet faces vs their bone points median %.2f mm, vs "
                 "cartilage nodes %.2f mm", h, runs[float(h)]["contested_voxels"],
                 v.loc["all ligament groups", "median_mm"], v.loc["all ligament groups", "max_mm"],
                 v.loc["facet faces vs their bone points", "median_mm"], v.loc["facet faces vs cartilage nodes",
                                                                                "median_mm"])
    vox, vox_facets = voxelised_tables(res["summary"], runs)
    write_table_atomic(vox, snakemake.output.voxelised)
    write_table_atomic(vox_facets, snakemake.output.voxelised_facets)
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
