"""Benchmark: seconds per vertebra of a specimen's landmark path (lumbar.geometry.specimen_build.build_specimen), on
one core.

The specimen is the embedded Visible Human set's L1-L5 + S1 meshes moved into a CT-like LPS pose
(lumbar.geometry.specimen_accuracy.ct_pose), given in memory (no file reading): alignment to the project frame, the
atlas registration of every vertebra and role, the snapping, the discs and the facet contact points. The atlas
(the Visible Human set's landmarks, read once per process) is timed apart (``atlas_build_s``). Rates are per wall
second and per CPU second of this process (the one-core figure when other jobs share the machine; the load average
is recorded before and after). Target: < 3 s per vertebra. Usage::

    python benchmarks/bench_landmarks.py [--repeat 1] [--vertebrae L1,L2,L3,L4,L5,S1]

``--dense K`` times what a CT surface exported at fine resolution costs instead: the same posed meshes, each
triangle split into four K times (trimesh.remesh.subdivide; K = 2 gives 16x the triangles, 129,000-425,000 per
vertebra, as a 0.3-0.5 mm export has), written as STL in millimetres, then read (``read_specimen``: the checks and
the decimation to ``MAX_WORKING_FACES``) and built; beside it, in the same run, the same files with the decimation
switched off (the baseline), and the landmarks' distance between the two in the input's coordinates (what the
bone carries) and the difference of the two project frames found from the anatomy. Its committed result is
``benchmarks/results/landmarks_dense.json``::

    python benchmarks/bench_landmarks.py --dense 2 > benchmarks/results/landmarks_dense.json

``--ct VOXEL_MM`` times a CT export instead: the posed meshes voxelised as a segmentation would label them
(lumbar.geometry.specimen_accuracy.voxelise, NIfTI RAS world), meshed by marching cubes and smoothed as the
label-volume path does but not decimated (a user's export of such a segmentation: 0.5 mm voxels give 170,000-190,000
triangles per lumbar vertebra), written as STL in millimetres and given to ``lumbar landmarks`` as surfaces
(``read_specimen`` and ``build_specimen``; the parse is done once before the timing, as the file cache does on a
second run). Its committed result is ``benchmarks/results/landmarks_ct.json``::

    python benchmarks/bench_landmarks.py --ct 0.5 --vertebrae L3,L4,L5 > benchmarks/results/landmarks_ct.json
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")   # one core

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.geometry.specimen_accuracy import ct_pose  # noqa: E402
from lumbar.geometry.specimen_build import build_specimen  # noqa: E402
from lumbar.geometry.specimen_landmarks import default_atlas  # noqa: E402

TARGET_S_PER_VERTEBRA = 3.0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--vertebrae", default="L1,L2,L3,L4,L5,S1")
    p.add_argument("--dense", type=int, default=0, help="subdivide K times and time reading + building (module doc)")
    p.add_argument("--ct", type=float, default=0.0, help="voxel edge [mm]: time a CT export's surfaces (module doc)")
    a = p.parse_args(argv)
    verts = a.vertebrae.split(",")
    if a.ct:
        print(json.dumps(ct_export(verts, a.ct, a.repeat), indent=2))
        return 0
    if a.dense:
        print(json.dumps(dense(verts, a.dense), indent=2))
        return 0
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


def _to_input(P, T):
    Ti = np.linalg.inv(T)
    return P @ Ti[:3, :3].T + Ti[:3, 3]


def dense(verts, k):
    """Reading + building a finely exported specimen, with and without the decimation (module doc)."""
    import tempfile  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    import trimesh  # noqa: PLC0415

    from lumbar.geometry.specimen_io import MAX_WORKING_FACES, read_specimen  # noqa: PLC0415
    load0 = os.getloadavg()[0]
    geo = load_geometry("visible_human")
    default_atlas()
    pose = ct_pose(0)
    faces = {}
    with tempfile.TemporaryDirectory() as tmp:
        for v in verts:
            m = geo.vertebrae[v].mesh.copy().apply_transform(pose)
            vv, ff = m.vertices * 1e3, m.faces
            for _ in range(k):
                vv, ff = trimesh.remesh.subdivide(vv, ff)
            trimesh.Trimesh(vv, ff).export(Path(tmp) / f"{v}.stl")
            faces[v] = int(len(ff))
        runs = {}
        for name, cap in (("decimated", MAX_WORKING_FACES), ("baseline_full_surface", 10**9)):
            t0, c0 = time.perf_counter(), time.process_time()
            read = read_specimen(tmp, units="mm", axes="LPS", max_faces=cap)
            sp = build_specimen(read.meshes, axes="LPS")
            runs[name] = dict(wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0,
                              cpu_seconds_per_vertebra=(time.process_time() - c0) / len(verts),
                              repairs=[str(r) for r in read.repairs],
                              transform=sp.alignment.transform,
                              points=np.vstack([np.asarray(lm["ligaments"][n][e]).reshape(-1, 3)
                                                for lv, lm in sorted(sp.landmarks.items())
                                                for n in sorted(lm["ligaments"]) for e in (0, 1)]))
    # the points in the input's coordinates (the files'): what the bone carries, apart from the frame found
    T = {k: r.pop("transform") for k, r in runs.items()}
    P = {k: _to_input(r.pop("points"), T[k]) for k, r in runs.items()}
    d = np.linalg.norm(P["decimated"] - P["baseline_full_surface"], axis=1) * 1e3
    M = T["decimated"] @ np.linalg.inv(T["baseline_full_surface"])
    frame = dict(turn_deg=float(np.degrees(np.arccos(np.clip((np.trace(M[:3, :3]) - 1) / 2, -1, 1)))),
                 origin_shift_mm=float(np.linalg.norm(M[:3, 3]) * 1e3))
    dec = runs["decimated"]
    return dict(benchmark="landmarks_dense", subdivisions=k, vertebrae=verts, triangles_per_vertebra=faces,
                max_working_faces=MAX_WORKING_FACES, runs=runs,
                cpu_ratio_decimated_over_baseline=dec["cpu_s"] / runs["baseline_full_surface"]["cpu_s"],
                ligament_points_moved_by_decimation_mm=dict(median=float(np.median(d)), p95=float(np.quantile(d, 0.95)),
                                                            max=float(d.max()), coordinates="input"),
                project_frame_moved_by_decimation=frame,
                target_seconds_per_vertebra=TARGET_S_PER_VERTEBRA,
                within_target=bool(dec["cpu_seconds_per_vertebra"] < TARGET_S_PER_VERTEBRA),
                load_average_before=load0, load_average_after=os.getloadavg()[0],
                threads="OMP/OPENBLAS/MKL_NUM_THREADS=1")


def ct_export(verts, voxel_mm, repeat=1):
    """Reading + building the surfaces of a CT segmentation exported without decimation (module doc)."""
    import tempfile  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    import nibabel  # noqa: PLC0415
    import trimesh  # noqa: PLC0415

    from lumbar.geometry.specimen_accuracy import RAS_FROM_LPS, voxelise  # noqa: PLC0415
    from lumbar.geometry.specimen_io import label_volume_to_meshes, read_specimen  # noqa: PLC0415
    load0 = os.getloadavg()[0]
    geo = load_geometry("visible_human")
    t0, c0 = time.perf_counter(), time.process_time()
    default_atlas()
    atlas_s, atlas_cpu = time.perf_counter() - t0, time.process_time() - c0
    pose = RAS_FROM_LPS @ ct_pose(0)
    meshes = {v: geo.vertebrae[v].mesh.copy().apply_transform(pose).apply_scale(1e3) for v in verts}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        lab, aff, values, _ = voxelise(meshes, voxel_mm)
        nibabel.save(nibabel.Nifti1Image(lab, aff), tmp / "labels.nii.gz")
        (tmp / "labels.csv").write_text("label,value\n" + "".join(f"{v},{k}\n" for v, k in values.items()))
        label_volume_to_meshes(tmp / "labels.nii.gz", tmp / "stl", label_table=tmp / "labels.csv", max_faces=10**9)
        for f in ("meshing_report.csv", "resolution_limits.csv"):
            (tmp / "stl" / f).unlink()
        faces = {v: len(trimesh.load(tmp / "stl" / f"{v}.stl").faces) for v in verts}
        read_specimen(tmp / "stl", units="mm", axes="RAS")           # the parse, cached as a second run has it
        wall, cpu = [], []
        for _ in range(repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            read = read_specimen(tmp / "stl", units="mm", axes="RAS")
            build_specimen(read.meshes, axes="RAS", turned=read.turned)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    # the baseline in the same run: the same vertebrae as the shipped surfaces (in memory, posed alike)
    c0 = time.process_time()
    build_specimen({v: m.copy().apply_scale(1e-3) for v, m in meshes.items()}, axes="RAS")
    shipped = (time.process_time() - c0) / len(verts)
    n = len(verts)
    return dict(benchmark="landmarks_ct_export", voxel_mm=voxel_mm, vertebrae=verts, triangles_per_vertebra=faces,
                repeat=repeat, seconds_per_vertebra=min(wall) / n, cpu_seconds_per_vertebra=min(cpu) / n,
                shipped_surfaces_cpu_seconds_per_vertebra=shipped,
                cpu_ratio_ct_export_over_shipped=min(cpu) / n / shipped,
                atlas_build_s=atlas_s, atlas_build_cpu_s=atlas_cpu, repairs=[str(r) for r in read.repairs],
                target_seconds_per_vertebra=TARGET_S_PER_VERTEBRA,
                within_target=bool(min(cpu) / n < TARGET_S_PER_VERTEBRA),
                load_average_before=load0, load_average_after=os.getloadavg()[0],
                threads="OMP/OPENBLAS/MKL_NUM_THREADS=1")


if __name__ == "__main__":
    raise SystemExit(main())
