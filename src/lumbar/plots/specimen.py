"""A user's specimen: the QA figure of each level's landmarks, and the command ``lumbar landmarks``.

``render_landmarks(geometry, level, path)`` draws both vertebrae of one level (semi-transparent) with every landmark
coloured by structure (ALL, PLL, FL, ISL, SSL, ITL, CL fibre ends joined by their fibres; the two facet faces; the
disc centre), in a sagittal and an oblique view: pyvista off-screen, matplotlib fallback, as
:mod:`lumbar.plots.render` (fixed cameras, millimetres, PNG without time metadata).

``lumbar landmarks MESH_DIR --units mm --axes LPS --out OUT_DIR`` reads a folder of vertebra surfaces
(``lumbar.geometry.specimen_io.read_specimen``; or a CT label volume, meshed into ``OUT_DIR/meshes`` first as the
workflow's ``label_volume`` geometry is, :func:`lumbar.geometry.configured.build`), aligns them to the project frame from the anatomy, places the
landmarks of every level present (any subset of L1-L5, S1, at least two neighbours) and writes ``landmarks.csv``,
``levels.csv``, ``transform.json`` and one ``qa_<level>.png`` per level (docs/specimen.md). The output folder is
checked before any work (:func:`check_output`); the run writes into a fresh folder beside it, moved into place
only when the run succeeds (a previous output replaced as a whole; on a refusal, removed), so that no stale or
partial file is left beside new ones. Every repair of the input and every file of the folder not read is printed
and recorded in ``transform.json``.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ..geometry.core import GeometryError
from .render import MM, camera_views, WINDOW_SIZE, check_backend, mpl_view, pyvista_views, render_with, save_png_closing

__all__ = ["render_landmarks", "main", "STRUCTURE_COLOURS"]

STRUCTURE_COLOURS = {"ALL": "#1f77b4", "PLL": "#17becf", "FL": "#2ca02c", "ISL": "#9467bd", "SSL": "#8c564b",
                     "ITL": "#e377c2", "CL": "#ff7f0e", "facet_superior": "#d62728", "facet_inferior": "#0a3d91"}
BONE = ("#d9c7a3", "#bfb8ad")


def _items(geometry, level):
    if level not in geometry.levels:
        raise KeyError(f"level {level!r} not in geometry {geometry.name!r}; available: {sorted(geometry.levels)}")
    lev = geometry.levels[level]
    meshes = [(v, np.asarray(geometry.vertebrae[v].mesh.vertices, float) * MM,
               np.asarray(geometry.vertebrae[v].mesh.faces, np.int64), c)
              for v, c in zip((lev.upper, lev.lower), BONE)]
    groups = {}
    for lig in lev.ligaments:
        g = groups.setdefault(lig.kind, dict(points=[], fibres=[]))
        g["points"] += [np.asarray(lig.upper) * MM, np.asarray(lig.lower) * MM]
        g["fibres"] += list(zip(np.asarray(lig.upper) * MM, np.asarray(lig.lower) * MM))
    for f in lev.facets.values():
        groups.setdefault("facet_superior", dict(points=[], fibres=[]))["points"].append(np.asarray(f.superior) * MM)
        groups.setdefault("facet_inferior", dict(points=[], fibres=[]))["points"].append(np.asarray(f.inferior) * MM)
    for g in groups.values():
        g["points"] = np.vstack(g["points"])
    return dict(meshes=meshes, groups=groups, centre=np.asarray(lev.disc_centre) * MM,
                title=f"{geometry.name} {level}")


def _views(items):
    return camera_views(np.vstack([v for _, v, _, _ in items["meshes"]]))


def _render_pyvista(items, path):
    import pyvista as pv  # noqa: PLC0415 - optional engine; without GL the module imports, matplotlib draws

    def draw(p):
        for _, v, f, colour in items["meshes"]:
            faces = np.hstack([np.full((len(f), 1), 3, np.int64), f]).ravel()
            p.add_mesh(pv.PolyData(v, faces), color=colour, opacity=0.3)
        p.add_mesh(pv.Sphere(radius=1.5, center=items["centre"]), color="black")
        for kind, g in items["groups"].items():
            colour = STRUCTURE_COLOURS.get(kind, "black")
            p.add_points(g["points"], color=colour, point_size=10, render_points_as_spheres=True)
            if g["fibres"]:
                n = len(g["fibres"])
                pts = np.empty((2 * n, 3))
                pts[0::2] = [a for a, _ in g["fibres"]]
                pts[1::2] = [b for _, b in g["fibres"]]
                lines = np.hstack([np.full((n, 1), 2), np.arange(2 * n).reshape(n, 2)]).ravel()
                p.add_mesh(pv.PolyData(pts, lines=lines), color=colour, line_width=2)
        p.add_legend([[k, STRUCTURE_COLOURS.get(k, "black")] for k in items["groups"]], bcolor="white",
                     size=(0.18, 0.3))

    pyvista_views(path, items["title"], _views(items), draw)


def _render_matplotlib(items, path):
    fig = Figure(figsize=(WINDOW_SIZE[0] / 100, WINDOW_SIZE[1] / 100), dpi=100)
    allv = np.vstack([v for _, v, _, _ in items["meshes"]])
    lo, hi = allv.min(0), allv.max(0)
    half, mid = 0.5 * float(np.max(hi - lo)), 0.5 * (lo + hi)
    for col, (label, (pos, focal, _)) in enumerate(_views(items)):
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        for _, v, f, colour in items["meshes"]:
            step = max(1, len(f) // 4000)
            ax.add_collection3d(Poly3DCollection(v[f[::step]], facecolor=colour, edgecolor="none", alpha=0.25))
        ax.scatter(*items["centre"], color="black", s=40)
        for kind, g in items["groups"].items():
            colour = STRUCTURE_COLOURS.get(kind, "black")
            ax.scatter(*g["points"].T, color=colour, s=14, label=kind)
            for a, b in g["fibres"]:
                ax.plot(*np.vstack([a, b]).T, color=colour, lw=1.0)
        mpl_view(ax, mid, half, pos, focal, f"{items['title']}: {label}")
        if col == 0:
            ax.legend(loc="upper left", fontsize=7)
    save_png_closing(fig, path)


def render_landmarks(geometry, level: str, path, backend: str = "auto") -> str:
    """QA figure of one level's landmarks (module doc); returns the backend used."""
    check_backend(backend)
    return render_with(backend, _items(geometry, level), Path(path), _render_pyvista, _render_matplotlib)


#: what the command writes into OUT (and nothing else): a folder holding anything else is not replaced
OUTPUT_FILES = ("landmarks.csv", "levels.csv", "transform.json")
OUTPUT_MESH_FILES = tuple(f"{v}.stl" for v in ("L1", "L2", "L3", "L4", "L5", "S1")) + (
    "meshing_report.csv", "resolution_limits.csv")


def _ours(p: Path) -> bool:
    """Whether ``p`` (an entry of OUT) is something this command writes."""
    if p.is_symlink():
        return False
    if p.is_dir():
        return p.name == "meshes" and all(q.is_file() and q.name in OUTPUT_MESH_FILES for q in p.iterdir())
    return p.is_file() and (p.name in OUTPUT_FILES or (p.name.startswith("qa_") and p.name.endswith(".png")))


def check_output(out, inputs=()) -> Path:
    """The output folder, checked before any work (:class:`GeometryError` naming it): not a file, not the input or a
    folder holding it, and either new or holding only what this command writes (a previous run's output, which a
    successful run replaces as a whole). Returns it resolved."""
    out = Path(out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise GeometryError(f"--out {out}: a file is there; expected a folder (new, empty, or a previous output of "
                            "this command)")
    for i in inputs:
        i = Path(i).expanduser().resolve()
        if i == out or out in i.parents:
            raise GeometryError(f"--out {out}: holds the input {i}; expected a folder of its own for the output")
    cwd = Path.cwd().resolve()
    if cwd == out or out in cwd.parents:
        raise GeometryError(f"--out {out}: the current folder or one holding it (a run replaces the output folder as "
                            "a whole); expected a folder of its own, e.g. --out landmarks_out")
    if out.is_dir():
        foreign = sorted(q.name + ("/" if q.is_dir() else "") for q in out.iterdir() if not _ours(q))
        if foreign:
            raise GeometryError(f"--out {out}: holds {', '.join(foreign[:6])}{' ...' if len(foreign) > 6 else ''}, "
                                "which this command does not write; expected a new or empty folder, or a previous "
                                f"output of it (only {', '.join(OUTPUT_FILES)}, qa_<level>.png and meshes/ with the "
                                "meshed label volume), which a run replaces as a whole")
    return out


def _staging(out: Path) -> Path:
    """A fresh temporary folder beside ``out`` (the same file system, so that it can be moved into place)."""
    import os  # noqa: PLC0415
    import tempfile  # noqa: PLC0415
    parent = out.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=parent))
        umask = os.umask(0)
        os.umask(umask)
        tmp.chmod(0o777 & ~umask)            # a folder as mkdir makes it (mkdtemp's is private)
        return tmp
    except OSError as exc:
        raise GeometryError(f"--out {out}: cannot write in {parent} ({exc.strerror or exc}); expected a folder "
                            "the command may create and write") from None


def _commit(tmp: Path, out: Path) -> None:
    """Move the finished output ``tmp`` into place: a previous output in ``out`` is replaced as a whole."""
    import shutil  # noqa: PLC0415
    import uuid  # noqa: PLC0415
    if out.exists():
        old = out.with_name(f".{out.name}.old-{uuid.uuid4().hex[:8]}")
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(out)


def _run(a, tmp: Path, out: Path) -> tuple:
    """The command's work into the staging folder ``tmp``, every check of the inputs first; returns (specimen, the
    axes as printed, a note on the facet numbers, the tables' final paths, the figures' (final path, engine), the
    reader's record)."""
    from ..geometry import configured  # noqa: PLC0415 - the command's work, not the figure's
    from ..geometry.specimen_build import build_specimen  # noqa: PLC0415
    from ..geometry.specimen_io import (buildable_units, check_units_axes, find_level_files,  # noqa: PLC0415
                                        input_kind, read_specimen, volume_files)
    from ..geometry.specimen_tables import write_tables  # noqa: PLC0415
    kind = input_kind(a.mesh_dir, a.pattern)
    if kind == "label_volume":
        for flag, given, only in (("--axes", a.axes, "RAS"), ("--units", a.units, "mm")):
            if given not in (None, only):
                raise GeometryError(f"{a.mesh_dir}: {flag} {given} with a label volume: its meshes are in the "
                                    f"NIfTI header's world frame (RAS, millimetres); leave {flag} out")
        files = volume_files(a.mesh_dir, a.label_table, a.pattern)
    else:
        if a.label_table:
            raise GeometryError(f"{a.mesh_dir}: --label-table names the vertebrae of a multi-label NIfTI file; "
                                "the input holds surface files")
        check_units_axes(a.units or "mm", a.axes or "LPS")
        files = find_level_files(a.mesh_dir, a.pattern)
    if not buildable_units(files):
        raise GeometryError(f"{a.mesh_dir}: one vertebra ({', '.join(f'{v}: {Path(f).name}' for v, f in files.items())})"
                            "; expected at least two neighbouring vertebrae (a motion segment), e.g. L4 and L5")
    note = ""
    if kind == "label_volume":
        g = {"kind": kind, "path": a.mesh_dir, "pattern": a.pattern, "label_table": a.label_table}
        b = configured.build({k: v for k, v in g.items() if v is not None}, mesh_dir=tmp / "meshes")
        sp, axes, read = b.specimen, "RAS (NIfTI world, mm)", b.read
        paths = configured.write_specimen_tables(b, tmp)
        ok, why = configured.facet_numbers_supported(b)
        note = "" if ok else f"# facet numbers of levels.csv left empty: {why}"
    else:
        axes = a.axes or "LPS"
        read = read_specimen(a.mesh_dir, units=a.units or "mm", axes=axes, pattern=a.pattern,
                             turn_inside_out=a.turn_inside_out)
        sources = {v: str(f) for v, f in read.files.items()}
        sp = build_specimen(read.meshes, axes=axes, sources=sources, units=a.units or "mm",
                            name=Path(a.mesh_dir).name, turned=read.turned, input_log=read.log())
        paths = write_tables(sp, tmp)
    figures = []
    if a.backend != "none":
        for lv in sp.geometry.levels:
            used = render_landmarks(sp.geometry, lv, tmp / f"qa_{lv}.png", backend=a.backend)
            figures.append((out / f"qa_{lv}.png", used))
    paths = {k: out / Path(v).name for k, v in paths.items()}
    return sp, axes, note, paths, figures, read


def main(argv=None, prog: str = "lumbar landmarks") -> int:
    import shutil  # noqa: PLC0415
    p = argparse.ArgumentParser(prog=prog, description="Landmarks of a specimen: align a folder of vertebra surfaces "
                                "(or a CT label volume, meshed first) to the project frame from the anatomy and place "
                                "every ligament insertion, facet face and disc of each level present "
                                "(docs/specimen.md).")
    p.add_argument("mesh_dir", help="folder with one surface per vertebra (L1..L5, S1 in the file names); or a CT "
                   "label volume: a folder of NIfTI masks (TotalSegmentator's vertebrae_L1.nii.gz .. sacrum.nii.gz) "
                   "or one multi-label NIfTI file with --label-table")
    p.add_argument("--units", default=None, choices=("mm", "m"),
                   help="units of the mesh coordinates (default mm; a label volume: the NIfTI header's, in mm)")
    p.add_argument("--axes", default=None, help="axes of the mesh coordinates: LPS (3D Slicer, DICOM; the default), "
                   "RAS (NIfTI world), project (x anterior, y left, z superior), any (right-handed, at any angle: "
                   "the orientation from the anatomy alone); a label volume is in NIfTI's RAS world")
    p.add_argument("--pattern", default=None, help="file pattern with {level}, e.g. '{level}_vertebra.obj', where "
                   "a folder holds several surfaces (or masks) per level")
    p.add_argument("--label-table", default=None, help="CSV with columns label,value (e.g. 'L4,24') naming the "
                   "vertebrae of a multi-label NIfTI file")
    p.add_argument("--turn-inside-out", action="store_true",
                   help="with --axes any: turn a surface whose faces all wind inwards instead of refusing it (the "
                        "coordinates are not mirrored). With declared axes such surfaces are turned anyway and "
                        "their anatomy checked against the axes (docs/specimen.md)")
    p.add_argument("--out", required=True, help="output folder, new or a previous output of this command (replaced "
                   "as a whole when the run succeeds, removed when it is refused); a label volume's meshes go to "
                   "OUT/meshes")
    p.add_argument("--backend", default="auto", choices=("auto", "pyvista", "matplotlib", "none"),
                   help="QA figure engine ('none': no figures)")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        out = check_output(a.out, [a.mesh_dir] + ([a.label_table] if a.label_table else []))
        tmp = _staging(out)
    except GeometryError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        sp, axes, note, paths, figures, read = _run(a, tmp, out)
        _commit(tmp, out)
    except (GeometryError, OSError) as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        msg = str(exc) if isinstance(exc, GeometryError) else f"{type(exc).__name__}: {exc}"
        print(f"error: {msg}", file=sys.stderr)
        if out.exists():
            shutil.rmtree(out, ignore_errors=True)
            print(f"error: the previous output in {out} was removed (it described an earlier run)", file=sys.stderr)
        return 2
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    det = sp.alignment.detected
    print(f"# {a.mesh_dir}: vertebrae {', '.join(sp.meshes)}; levels {', '.join(sp.geometry.levels) or 'none'}")
    print(f"# alignment: superior from the {det['superior_rule']}; anterior votes {det['anterior_votes']}; "
          f"{det.get('angle_to_declared_deg', 'n/a')} deg from the declared axes {axes}")
    for r in read.repairs:
        print(f"# repair: {r}")
    for f, why in read.ignored:
        print(f"# not read: {f} ({why})")
    if note:
        print(note)
    for key, path in paths.items():
        print(f"{key}: {path}")
    for fig, used in figures:
        print(f"figure: {fig} ({used})")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(prog="python -m lumbar.plots.specimen"))
