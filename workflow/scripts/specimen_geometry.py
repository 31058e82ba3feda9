"""Geometry stage, rule specimen_geometry: a user's specimen (geometry.kind meshes or label_volume) built once, its
landmarks, per-level table, transform, skipped stages and one QA figure per level written, its geometry cached for
the other jobs (lumbar.geometry.configured).

By hand: python workflow/scripts/specimen_geometry.py specimen_geometry --configfile my_specimen.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.geometry import configured  # noqa: E402
from lumbar.plots.specimen import render_landmarks  # noqa: E402


def main(snakemake, log):
    g = snakemake.params.geometry
    out = Path(snakemake.output.landmarks).parent
    mesh_dir = Path(snakemake.output.meshes[0]).parent if snakemake.output.meshes else None
    b = configured.build(g, mesh_dir=mesh_dir)
    det = b.specimen.alignment.detected
    log.info("specimen %s (%s): vertebrae %s, units %s", b.inputs.path, b.inputs.kind, ", ".join(b.read.files),
             ", ".join(b.specimen.geometry.levels))
    log.info("alignment: superior from the %s; anterior votes %s; %s deg from the declared axes %s",
             det["superior_rule"], det["anterior_votes"], det.get("angle_to_declared_deg", "n/a"), b.inputs.axes)
    for r in b.read.repairs:
        log.info("repair: %s", r)
    for f, why in b.read.ignored:
        log.info("not read: %s (%s)", f, why)
    ok, why = configured.facet_numbers_supported(b)
    if not ok:
        log.warning("facet numbers not supported: %s", why)
    skipped = [tuple(s) for s in snakemake.params.skipped]
    for stage, reason in skipped:
        log.info("skipped stage %s: %s", stage, reason)
    paths = configured.write_outputs(b, out, skipped)
    for key, p in paths.items():
        log.info("wrote %s: %s", key, p)
    for fig in snakemake.output.qa:
        level = Path(fig).stem.removeprefix("qa_")
        used = render_landmarks(b.specimen.geometry, level, fig, backend=snakemake.params.backend)
        log.info("wrote %s (%s)", fig, used)


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
