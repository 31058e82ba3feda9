"""Benchmark: reading a user's specimen (lumbar.geometry.specimen_io), wall and CPU seconds.

Rows: the embedded Visible Human meshes read as a user's folder (``pattern="{level}_vertebra.obj"``, six vertebrae,
units m, axes project) with an empty geometry cache (parsing the OBJ files) and again with the cache filled; the
neighbour checks alone (gap, overlap, order: five pairs); the three embedded TotalSegmentator masks (3 mm voxels)
meshed into STL files and read back. Best of ``--repeat``; the load average is recorded before and after (the
machine may be shared). Usage::

    python benchmarks/bench_specimen_io.py [--repeat 3]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from lumbar.geometry import specimen_io as S

ROOT = Path(__file__).resolve().parents[1]
VH_MESHES = ROOT / "data" / "geometry" / "visible_human_lss" / "meshes"
TS_MASKS = ROOT / "tests" / "data" / "totalsegmentator_example"


def best(fn, repeat):
    w, c = float("inf"), float("inf")
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        w, c = min(w, time.perf_counter() - t0), min(c, time.process_time() - c0)
    return {"wall_s": round(w, 3), "cpu_s": round(c, 3)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    out = {"load_average_1_5_15_min_start": [round(v, 2) for v in os.getloadavg()]}
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["LUMBAR_CACHE_DIR"] = str(Path(tmp) / "cache")   # read at each parse: an empty cache

        def vh():
            return S.read_specimen(VH_MESHES, units="m", axes="project", pattern="{level}_vertebra.obj")

        t0, c0 = time.perf_counter(), time.process_time()
        sp = vh()
        out["visible_human_cold_cache"] = {"wall_s": round(time.perf_counter() - t0, 3),
                                           "cpu_s": round(time.process_time() - c0, 3)}
        out["visible_human_warm_cache"] = best(vh, a.repeat)
        out["visible_human_neighbour_checks"] = best(lambda: S.check_neighbours(sp.meshes, sp.files), a.repeat)
        out["visible_human_triangles"] = {k: len(m.faces) for k, m in sp.meshes.items()}

        def ts():
            d = Path(tempfile.mkdtemp(dir=tmp))
            S.label_volume_to_meshes(TS_MASKS, d)
            return S.read_specimen(d, units="mm", axes="RAS")
        out["totalsegmentator_3_masks_mesh_and_read"] = best(ts, a.repeat)
    out["load_average_1_5_15_min_end"] = [round(v, 2) for v in os.getloadavg()]
    print(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
