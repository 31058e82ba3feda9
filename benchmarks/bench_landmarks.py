"""Benchmark: seconds per vertebra of a specimen's landmark path (lumbar.geometry.specimen_build.build_specimen), on
one core.

The specimen is the embedded Visible Human set's L1-L5 + S1 meshes moved into a CT-like LPS pose
(lumbar.geometry.specimen_accuracy.ct_pose), given in memory (no file reading): alignment to the project frame, the
atlas registration of every vertebra and role, the snapping, the discs and the facet contact points. The atlas
(the Visible Human set's landmarks, read once per process) is timed apart (``atlas_build_s``). Rates are per wall
second and per CPU second of this process (the one-core figure when other jobs share the machine; the load average
is recorded before and after). Target: < 3 s per vertebra. Usage::

    python benchmarks/bench_landmarks.py [--repeat 1] [--vertebrae L1,L2,L3,L4,L5,S1]
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.geometry.specimen_accuracy import ct_pose  # noqa: E402
from lumbar.geometry.specimen_build import build_specimen  # noqa: E402
from lumbar.geometry.specimen_landmarks import default_atlas  # noqa: E402

TARGET_S_PER_VERTEBRA = 3.0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--vertebrae", default="L1,L2,L3,L4,L5,S1")
    a = p.parse_args(argv)
    verts = a.vertebrae.split(",")
    load0 = os.getloadavg()[0]
    geo = load_geometry("visible_human")
    t0, c0 = time.perf_counter(), time.process_time()
    default_atlas()
    atlas_s, atlas_cpu = time.perf_counter() - t0, time.process_time() - c0
    pose = ct_pose(0)
    meshes = {v: geo.vertebrae[v].mesh.copy().apply_transform(pose) for v in verts}
    wall, cpu = [], []
    for _ in range(a.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        sp = build_specimen(meshes, axes="LPS")
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    n = len(verts)
    out = dict(benchmark="landmarks", vertebrae=verts, levels=list(sp.geometry.levels), repeat=a.repeat,
               seconds_per_vertebra=min(wall) / n, cpu_seconds_per_vertebra=min(cpu) / n,
               specimen_wall_s=min(wall), specimen_cpu_s=min(cpu), atlas_build_s=atlas_s, atlas_build_cpu_s=atlas_cpu,
               target_seconds_per_vertebra=TARGET_S_PER_VERTEBRA,
               within_target=bool(min(cpu) / n < TARGET_S_PER_VERTEBRA),
               load_average_before=load0, load_average_after=os.getloadavg()[0],
               threads="OMP/OPENBLAS/MKL_NUM_THREADS=1")
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
