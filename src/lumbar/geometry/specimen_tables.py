"""The tables of a specimen (:mod:`lumbar.geometry.specimen_build`): write them, and read a corrected landmark table
back into a geometry.

* ``landmarks.csv``: the columns of ``data/landmarks/myo_sim_landmarks.csv`` (``level, structure, side, point_index,
  x_m, y_m, z_m, body, vertex_index, rule, source, kind``; project frame, metres) plus ``extra_length_m`` (the
  via-point path of an ALL/PLL fibre within its bodies, 0 for straight fibres; on the upper-end row, repeated on the
  lower) and ``x_input, y_input, z_input`` (the same point in the input's own axes and units);
* ``levels.csv``: per level the disc centre, normal, height and cross-section, and per facet joint the contact rule,
  the bone gap and the Eq. 4 surface fit coefficients (mean, superior and inferior fits, their frame);
* ``transform.json``: the 4x4 input -> project transform (metres), the input units and axes, what the alignment
  detected, per vertebra its file and every repair the reader made (``inputs``), and the files of the input folder
  not read with the reason (``ignored_files``).

:func:`read_landmark_table` validates an edited copy (every error names the file, the 1-based data row and the
column) and :func:`geometry_from_table` rebuilds the geometry from it.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..inputs.io import atomic_writer
from ..mechanics.elements.facet import fit_surface
from .core import LEVEL_NAMES, LIGAMENT_NAMES, GeometryError, SpineGeometry, Vertebra, level_vertebrae
from .landmarks import COLUMNS

TABLE_COLUMNS = COLUMNS + ["extra_length_m", "x_input", "y_input", "z_input"]
FACET_STRUCTURES = ("facet_superior", "facet_inferior")
STRUCTURES = LIGAMENT_NAMES + FACET_STRUCTURES
SIDES = ("left", "medial", "right")
UNIT_FACTORS = {"m": 1.0, "mm": 1e-3}
ON_BONE_TOL_M = 1e-3          # an edited insertion on the bone: within 1 mm of its body's surface
VIA_POINT_TOL_M = 0.010       # an ALL/PLL via point (extra_length > 0): within 10 mm (lumbar.geometry.checks)
CAPSULE_TOL_M = 0.005         # a capsule fibre end (CL, placed across the joint's rim, not snapped): within 5 mm
CONSISTENCY_TOL_M = 1e-5      # project and input columns of one row must describe the same point


def _side(name, p):
    if name.endswith("_L"):
        return "left"
    if name.endswith("_R"):
        return "right"
    return "medial" if abs(p[1]) < 2e-3 else ("left" if p[1] > 0 else "right")


def _rule(structure, body, templates, snapped, anchor=None):
    how = ("closest point on the surface" if snapped else
           "fibre centred on the carried midpoint with the atlas's fibre vector, not snapped (docs/specimen.md)")
    moved = ("" if not anchor else
             f", moved per template by the warp's miss at the bone feature '{anchor}' of {body} "
             "(lumbar.geometry.bone_features)")
    return (f"{structure} on {body}: the Visible Human atlas point (Remus et al. 2021) carried by surface "
            f"registration (similarity ICP, affine ICP, smooth non-rigid field) from template(s) "
            f"{'+'.join(templates)}{moved}, median over templates, {how}")


def landmark_table(sp, units: str | None = None) -> pd.DataFrame:
    """The landmark rows of a :class:`~lumbar.geometry.specimen_build.Specimen` (module doc)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    units = sp.units if units is None else units
    f = UNIT_FACTORS[units]
    rows = []
    trees = {v: cKDTree(np.asarray(m.vertices)) for v, m in sp.meshes.items()}
    for lv, lm in sp.landmarks.items():
        U, L = level_vertebrae(lv)
        src = {v: f"{sp.sources.get(v, v + ' mesh')}; atlas: Visible Human (Remus et al. 2021, BSD-3-Clause)"
               for v in (U, L)}
        items = []
        for name, (up, lo, extra) in lm["ligaments"].items():
            for k in range(len(up)):
                for body, p in ((U, up[k]), (L, lo[k])):
                    items.append((name, _side(name, 0.5 * (up[k] + lo[k])), k, body, p, float(extra[k])))
        for side, (sup, inf) in lm["facets"].items():
            for k in range(len(sup)):
                items.append(("facet_superior", side, k, L, sup[k], 0.0))
            for k in range(len(inf)):
                items.append(("facet_inferior", side, k, U, inf[k], 0.0))
        tmpl = lm.get("templates", {})
        for name, side, k, body, p, extra in items:
            d, vi = trees[body].query(p)
            role = "upper" if body == U else "lower"
            rows.append(dict(level=lv, structure=name, side=side, point_index=k, x_m=p[0], y_m=p[1], z_m=p[2],
                             body=body, vertex_index=int(vi),
                             rule=_rule(name, body, tmpl.get(role, []), extra == 0.0 and not name.startswith("CL"),
                                        lm.get("anchors", {}).get((name, role))),
                             source=src[body], kind="derived_from_geometry", extra_length_m=extra))
    df = pd.DataFrame(rows, columns=COLUMNS + ["extra_length_m"])
    P_in = sp.alignment.inverse(df[["x_m", "y_m", "z_m"]].to_numpy(float)) / f if len(df) else np.zeros((0, 3))
    for i, c in enumerate(("x_input", "y_input", "z_input")):
        df[c] = P_in[:, i] if len(df) else []
    return df[TABLE_COLUMNS]


def level_table(geo: SpineGeometry, gaps: dict | None = None) -> pd.DataFrame:
    """Per level: disc centre/normal/height/cross-section; per facet joint its contact rule, bone gap and the Eq. 4
    fit (``lumbar.mechanics.elements.facet.fit_surface``: coefficients p30, p03, p20, p02, p00 in metres of the
    local frame u, v, w, whose origin and axes are given; mean, superior and inferior fits)."""
    rows = []
    for name, lev in geo.levels.items():
        r = dict(level=name, upper=lev.upper, lower=lev.lower)
        for ax, c, n in zip("xyz", lev.disc_centre, lev.disc_normal):
            r[f"disc_centre_{ax}_mm"] = 1e3 * float(c)
            r[f"disc_normal_{ax}"] = float(n)
        r["disc_height_mm"] = 1e3 * lev.disc_height
        r["disc_csa_mm2"] = 1e6 * lev.disc_csa
        for side, f in sorted(lev.facets.items()):
            medial = np.array([0.0, -1.0 if side == "left" else 1.0, 0.0])
            s = fit_surface(f.superior, f.inferior, medial_hint=medial, contact=f.contact,
                            contact_points=f.contact_points)
            p = f"facet_{side}_"
            r[p + "contact"] = f.contact
            if gaps and (name, side) in gaps:
                r[p + "bone_gap_mm"] = 1e3 * gaps[(name, side)]
            r[p + "fit_rms_mm"] = 1e3 * s.rms_m
            for ax, o in zip("xyz", s.origin):
                r[p + f"origin_{ax}_mm"] = 1e3 * float(o)
            for a, vec in zip("uvw", s.axes):
                for ax, c in zip("xyz", vec):
                    r[p + f"axis_{a}_{ax}"] = float(c)
            for which, coef in (("mean", s.coef), ("superior", s.coef_superior), ("inferior", s.coef_inferior)):
                for cn, c in zip(("p30", "p03", "p20", "p02", "p00"), coef):
                    r[p + f"{which}_{cn}"] = float(c)
        rows.append(r)
    return pd.DataFrame(rows)


def transform_record(sp) -> dict:
    T = np.asarray(sp.alignment.transform, float)
    return dict(input_to_project_m=T.tolist(), input_units=sp.units, input_scale_to_m=UNIT_FACTORS[sp.units],
                input_axes=sp.alignment.axes,
                how="p_project_m = T[:3,:3] @ (p_input * input_scale_to_m) + T[:3,3]; project frame: x anterior, "
                    "y left, z superior (docs/specimen.md)",
                detected=sp.alignment.detected,
                inputs=getattr(sp, "input_log", {}).get("files", {}),
                ignored_files=getattr(sp, "input_log", {}).get("ignored_files", []))


def write_tables(sp, out_dir) -> dict:
    """Write landmarks.csv, levels.csv and transform.json into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = dict(landmarks=out / "landmarks.csv", levels=out / "levels.csv", transform=out / "transform.json")
    for key, df in (("landmarks", landmark_table(sp)), ("levels", level_table(sp.geometry, sp.facet_gaps))):
        with atomic_writer(paths[key], "w") as fh:
            df.to_csv(fh, index=False, float_format="%.6g" if key == "levels" else "%.7f")
    with atomic_writer(paths["transform"], "w") as fh:
        json.dump(transform_record(sp), fh, indent=2, default=float)
    return paths


def _err(path, row, col, what):
    return GeometryError(f"{path}: data row {row} column {col}: {what}")


def read_landmark_table(path, meshes: dict, alignment=None, units: str = "m") -> pd.DataFrame:
    """Read and validate a (corrected) landmark table against the specimen's meshes (project frame, metres).

    Checks: the columns ``TABLE_COLUMNS`` (``extra_length_m`` and the input columns may be left empty); level,
    structure, side and body from their vocabularies, the body one of the level's two vertebrae (the upper one
    for ``facet_inferior``, the lower one for ``facet_superior``); finite coordinates; every point within 1 mm of
    its body's surface (5 mm for a capsule fibre end, 10 mm for a via point, ``extra_length_m`` > 0; a
    ``facet_inferior`` point: of either vertebra of its level, the faces of a joint may touch); where both the project (``x_m``..) and the
    input (``x_input``..) coordinates of a row are given and ``alignment`` is, they describe the same point (edit
    both, or empty one set: it is computed from the other); fibres pair up by point_index; 9 points per facet face.
    """
    from scipy.spatial import cKDTree  # noqa: PLC0415
    p = Path(path)
    if not p.is_file():
        raise GeometryError(f"{p}: landmark table missing (expected the landmarks.csv written by `lumbar landmarks`)")
    try:
        df = pd.read_csv(p)
    except Exception as exc:
        raise GeometryError(f"{p}: not readable as CSV ({exc})") from exc
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        raise GeometryError(f"{p}: missing column(s) {missing}; expected the columns {TABLE_COLUMNS}")
    for c in ("extra_length_m", "x_input", "y_input", "z_input"):
        if c not in df.columns:
            df[c] = np.nan
    df["extra_length_m"] = pd.to_numeric(df["extra_length_m"], errors="coerce").fillna(0.0)
    f = UNIT_FACTORS.get(units)
    if f is None:
        raise GeometryError(f"{p}: units {units!r}; expected one of {sorted(UNIT_FACTORS)}")
    for i, r in df.iterrows():
        row = i + 1
        if r["level"] not in LEVEL_NAMES:
            raise _err(p, row, "level", f"{r['level']!r}; expected one of {list(LEVEL_NAMES)}")
        if r["structure"] not in STRUCTURES:
            raise _err(p, row, "structure", f"{r['structure']!r}; expected one of {list(STRUCTURES)}")
        if r["side"] not in SIDES:
            raise _err(p, row, "side", f"{r['side']!r}; expected one of {list(SIDES)}")
        U, L = level_vertebrae(r["level"])
        allowed = {"facet_inferior": (U,), "facet_superior": (L,)}.get(r["structure"], (U, L))
        if r["body"] not in allowed:
            raise _err(p, row, "body", f"{r['body']!r}; expected {' or '.join(allowed)} for {r['structure']} at "
                                       f"{r['level']}")
        if r["body"] not in meshes:
            raise _err(p, row, "body", f"{r['body']!r} has no mesh in this specimen ({sorted(meshes)})")
        if not float(r["extra_length_m"]) >= 0:
            raise _err(p, row, "extra_length_m", f"{r['extra_length_m']!r}; expected a length >= 0 in metres")
        proj = pd.to_numeric(pd.Series([r["x_m"], r["y_m"], r["z_m"]]), errors="coerce").to_numpy(float)
        inp = pd.to_numeric(pd.Series([r["x_input"], r["y_input"], r["z_input"]]), errors="coerce").to_numpy(float)
        have_p, have_i = np.isfinite(proj).all(), np.isfinite(inp).all() and alignment is not None
        if not have_p and not have_i:
            raise _err(p, row, "x_m,y_m,z_m", "no finite point; expected x_m, y_m, z_m in metres (project frame) "
                                              "or x_input, y_input, z_input in the input's axes and units")
        if have_i:
            from_in = alignment.apply(inp * f)[0]
            if have_p and np.linalg.norm(from_in - proj) > CONSISTENCY_TOL_M:
                raise _err(p, row, "x_input,y_input,z_input",
                           f"describes a point {np.linalg.norm(from_in - proj) * 1e3:.2f} mm from x_m,y_m,z_m; edit "
                           "both sets consistently, or empty one of them (it is then computed from the other)")
            proj = from_in
        df.loc[i, ["x_m", "y_m", "z_m"]] = proj
    df[["x_m", "y_m", "z_m"]] = df[["x_m", "y_m", "z_m"]].astype(float)
    for body, sub in df.groupby("body"):
        d = cKDTree(np.asarray(meshes[body].vertices)).query(sub[["x_m", "y_m", "z_m"]].to_numpy())[0]
        # the inferior face of a joint whose bone surfaces interpenetrate is the lower vertebra's superior face
        # (the faces touch: lumbar.geometry.specimen_landmarks._facing_face): on either vertebra of its level
        for lv, rows in sub[sub["structure"] == "facet_inferior"].groupby("level"):
            lower = level_vertebrae(lv)[1]
            if lower in meshes:
                k = sub.index.get_indexer(rows.index)
                d[k] = np.minimum(d[k], cKDTree(np.asarray(meshes[lower].vertices)).query(
                    rows[["x_m", "y_m", "z_m"]].to_numpy())[0])
        tol = np.where(sub["extra_length_m"].to_numpy() > 0, VIA_POINT_TOL_M,
                       np.where(sub["structure"].str.startswith("CL").to_numpy(), CAPSULE_TOL_M, ON_BONE_TOL_M))
        # the nearest vertex over-estimates the surface distance by up to half an edge: a 0.5 mm allowance
        bad = d > tol + 0.5e-3
        if bad.any():
            j = int(np.argmax(bad))
            r = sub.iloc[j]
            raise _err(p, int(sub.index[j]) + 1, "x_m,y_m,z_m",
                       f"{r['structure']} point ({r['level']}) is {d[j] * 1e3:.2f} mm from the {body} surface; "
                       f"expected within {tol[j] * 1e3:.0f} mm (metres, project frame)")
    _check_pairs(df, p)
    return df


def _check_pairs(df, p):
    for (lv, s), sub in df.groupby(["level", "structure"]):
        U, L = level_vertebrae(lv)
        if s in FACET_STRUCTURES:
            for side, ss in sub.groupby("side"):
                if sorted(ss["point_index"]) != list(range(9)):
                    raise GeometryError(f"{p}: {lv} {s} {side}: point_index {sorted(ss['point_index'])}; expected "
                                        "the 9 grid nodes 0..8")
            continue
        iu = sorted(sub.loc[sub["body"] == U, "point_index"])
        il = sorted(sub.loc[sub["body"] == L, "point_index"])
        if iu != il or len(set(iu)) != len(iu):
            raise GeometryError(f"{p}: {lv} {s}: the fibre ends on {U} (point_index {iu}) and on {L} ({il}) do not "
                                "pair up; expected one row per fibre end, the same point_index on both bodies")


def geometry_from_table(df: pd.DataFrame, sp) -> SpineGeometry:
    """The specimen's geometry rebuilt from a validated landmark table (:func:`read_landmark_table`): the discs and
    reference points from the meshes, every fibre and facet face from the table."""
    from .specimen_build import assemble_level, centroids_of  # noqa: PLC0415 - the assembly imports this module
    cents, x_post = centroids_of(sp.meshes)
    levels, gaps = {}, {}
    for lv in [lv for lv in LEVEL_NAMES if lv in set(df["level"])]:
        U, L = level_vertebrae(lv)
        sub = df[df["level"] == lv]
        ligs, facets = {}, {}
        for name in LIGAMENT_NAMES:
            s = sub[sub["structure"] == name]
            if s.empty:
                continue
            up = s[s["body"] == U].sort_values("point_index")
            lo = s[s["body"] == L].sort_values("point_index")
            ligs[name] = (up[["x_m", "y_m", "z_m"]].to_numpy(float), lo[["x_m", "y_m", "z_m"]].to_numpy(float),
                          up["extra_length_m"].to_numpy(float))
        for side in ("left", "right"):
            s = sub[sub["side"] == side]
            sup = s[s["structure"] == "facet_superior"].sort_values("point_index")[["x_m", "y_m", "z_m"]].to_numpy()
            inf = s[s["structure"] == "facet_inferior"].sort_values("point_index")[["x_m", "y_m", "z_m"]].to_numpy()
            if len(sup) and len(inf):
                facets[side] = (sup, inf)
        levels[lv], _ = assemble_level(lv, sp.meshes, dict(ligaments=ligs, facets=facets), cents, x_post, gaps)
    verts = {v: Vertebra(v, sp.meshes[v], np.asarray(cents[v], float)) for v in sp.meshes}
    return SpineGeometry(name=sp.geometry.name, source=sp.geometry.source + "; landmarks from an edited table",
                         vertebrae=verts, levels=levels)
