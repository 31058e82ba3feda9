"""Calibrated units as OpenSim 4.6 models: the detailed unit of a level written as an ``.osim`` file.

What is written (:func:`unit_document`, :func:`write_unit`): the unit the workflow builds
(:func:`lumbar.experiments.fsu.configured_unit`, the one way from a configuration to a model), element by element,
from the finalized :class:`lumbar.mechanics.model.SpineModel` itself, so that the file holds the model the tables
were computed with and not a second reading of the configuration:

* **bodies**: the two vertebrae, each with its body frame at its centroid (the project's reference point) and its
  surface mesh beside the model as an STL file in that frame; the lower vertebra welded to ground;
* **joint**: one ``FreeJoint`` from the lower to the upper vertebra, both joint frames at the disc centre with the
  project axes, so that its six coordinates read as the project's: ``<level>_lateral_bending`` (rotation about the
  anterior axis; positive = bending to the right), ``<level>_flexion`` (about the left axis; positive = flexion),
  ``<level>_axial_rotation`` (about the superior axis; positive = rotation to the left), body-fixed X-Y-Z, then the
  displacement of the upper vertebra's disc-centre point anterior, left and superior [m];
* **disc**: two ``ExpressionBasedBushingForce`` at the disc centre: the rotation bushing applies Eq. 3 to the
  project's rotation vector (computed from the bushing's X-Y-Z angles, so the two engines share one law exactly), the
  translation bushing the compression-only axial law and the linear shear in the disc frame;
* **ligaments**: one ``ExpressionBasedPointToPointForce`` per fibre, the softplus law (Eq. 7) on the fibre's strain
  from its slack length (prestrain included), tension only with the project's C1 slack ramp, the ligament's force
  shared by its fibres;
* **facet joints**: one ``ExpressionBasedBushingForce`` per contact point: frame 1 is the contact surface's own
  frame (u, v, w) fixed to the lower vertebra, frame 2 the contact point on the upper vertebra, so that the bushing's
  deflection ``(delta_x, delta_y, delta_z)`` is the point's (u, v, w) and its gap to the Eq. 4 surface is
  ``delta_z - f(delta_x, delta_y)``: the project's smoothed penalty (Eq. 5) along the surface gradient, no moment.
  This is the Eq. 4 surface itself, not a sphere or a mesh approximation.

Frames and units: SI (m, N, N*m, kg). OpenSim's ground has Y superior: ground X = project x (anterior), ground Y =
project z (superior), ground Z = -project y (right); every point is written as ``Q_OSIM @ p``. Gravity is 0: the unit
is the in-vitro specimen. Body masses and inertias are placeholders (they do not enter a static equilibrium) and the
bushing and fibre damping are numerical (they shape a forward simulation's transient, not its rest state); both are
stated in the file.

Writing needs no OpenSim (plain XML); :func:`static_rom` (used by the workflow's check and the tests) imports
``opensim`` when called, in a process that has not imported CasADi (the two wheels ship one library under the same
name, ``tests/test_bench_opensim.py``).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..mechanics.elements.ligament import LAW_RUPP, LAW_SOFTPLUS

#: project frame (x anterior, y left, z superior) -> OpenSim ground (X anterior, Y superior, Z right): a rotation
#: about x by -90 deg
Q_OSIM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: placeholder mass [kg] and principal inertia [kg m^2] of a vertebra (statics do not depend on them)
VERTEBRA_MASS_KG = 0.1
VERTEBRA_INERTIA_KGM2 = 1e-4
#: numerical damping (statics do not depend on it): disc rotation [N*m*s/rad], disc translation [N*s/m], per fibre
#: [N*s/m, shared by the ligament's fibres], per facet point [N*s/m]
DAMPING = {"disc_rotation": 0.05, "disc_translation": 300.0, "fibre": 5.0, "facet_point": 5.0}
#: the joint coordinates, in FreeJoint order (rotations X-Y-Z body-fixed of the upper disc frame in the lower one)
COORDINATES = ("lateral_bending", "flexion", "axial_rotation", "anterior", "left", "superior")
#: the project's loading directions -> (project axis, sign) (lumbar.experiments.fsu.DIRECTIONS)
#: the OpenSim static solve: largest generalised residual [N, N*m] of an equilibrium, and how often a moment step
#: that the root finder fails is halved before the scenario is reported as not converged
RESIDUAL_TOL = 1e-6
MAX_HALVINGS = 6
DIRECTION_AXES = {
    "flexion": (1, 1.0), "extension": (1, -1.0),
    "lateral_bending": (0, 1.0), "lateral_bending_right": (0, 1.0), "lateral_bending_left": (0, -1.0),
    "axial_rotation": (2, 1.0), "axial_rotation_left": (2, 1.0), "axial_rotation_right": (2, -1.0),
}


class ExportError(ValueError):
    """A request the export cannot carry out (unknown set or level, a law OpenSim is not given here)."""


def _vec(a) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(a))


def _num(v) -> str:
    return repr(float(v))


def _orientation(R_body_frame) -> np.ndarray:
    """OpenSim's frame orientation (body-fixed X-Y-Z angles) of a frame whose axes are the columns of
    ``R_body_frame`` (in the body frame)."""
    return Rotation.from_matrix(R_body_frame).as_euler("XYZ")


def _sub(parent, tag, text=None, **attrib):
    e = ET.SubElement(parent, tag, attrib)
    if text is not None:
        e.text = text
    return e


def _offset_frame(parent, name, body_path, translation, R_project):
    """A PhysicalOffsetFrame on ``body_path`` at ``translation`` (project frame, relative to the body's centroid)
    whose axes are the columns of ``R_project`` (project frame)."""
    f = _sub(parent, "PhysicalOffsetFrame", name=name)
    _sub(f, "socket_parent", body_path)
    _sub(f, "translation", _vec(Q_OSIM @ np.asarray(translation, float)))
    _sub(f, "orientation", _vec(_orientation(Q_OSIM @ np.asarray(R_project, float))))
    return f


# ------------------------------------------------------------------ force laws as Lepton expressions
def eq3_expression(phi, p) -> str:
    p1, p2, p3 = (_num(v) for v in p)
    return f"({p1}*tanh(({phi})^3/{p2})+{p3}*({phi}))"


def pwl_expression(var, phi, moment) -> str:
    """A piecewise-linear torque [N*m] through the points (``phi`` [rad] > 0, ``moment`` [N*m] > 0, increasing) and
    the origin, the last slope continued beyond: ``s0 var + sum_i (s_i - s_(i-1)) max(var - phi_i, 0)``."""
    x = np.concatenate([[0.0], np.asarray(phi, float)])
    y = np.concatenate([[0.0], np.asarray(moment, float)])
    s = np.diff(y) / np.diff(x)
    terms = [f"{_num(s[0])}*({var})"]
    terms += [f"{_num(s[i] - s[i - 1])}*max(({var})-{_num(x[i])},0)" for i in range(1, len(s))]
    return "(" + "+".join(terms) + ")"


def law_expression(var, law, negative=False) -> str:
    """Lepton text of a torque law at angle ``var``: Eq. 3 parameters (p1, p2, p3) (odd in the angle), or a
    piecewise-linear law ``{"phi": ..., "moment": ...}`` of the positive side (``negative``: applied to the negative
    side as ``-T(-var)``)."""
    if isinstance(law, dict):
        if negative:
            return "(-" + pwl_expression(f"-({var})", law["phi"], law["moment"]) + ")"
        return pwl_expression(var, law["phi"], law["moment"])
    return eq3_expression(var, law)


def _sided(var, pos, neg) -> str:
    """A torque law with its own parameters on each side of 0 (``pos`` for ``var >= 0``)."""
    if not isinstance(pos, dict) and not isinstance(neg, dict) and tuple(pos) == tuple(neg):
        return eq3_expression(var, pos)
    return (f"step({var})*{law_expression(var, pos)}+(1-step({var}))*{law_expression(var, neg, negative=True)}")


def disc_moment_expressions(torque) -> tuple[str, str, str]:
    """(Mx, My, Mz) of the rotation bushing: Eq. 3 on the project's rotation vector ``phi = log(R_FM)``, mapped to the
    generalised forces of the bushing's X-Y-Z angles (``M = (R_FM N^-1)^T T``; OpenSim applies ``-R_GM N M`` to frame
    2), so the torque is the project's exactly. ``theta/(2 sin theta)`` by its series (no 0/0 at rest). ``torque``:
    Eq. 3 parameters by direction (the disc's ``flexion``, ``extension``, ``lateral_bending``, ``axial_rotation``);
    ``lateral_bending_left`` and ``axial_rotation_right`` give the negative sides their own (a reduced joint)."""
    lb, fl, ex, ar = (torque[k] for k in ("lateral_bending", "flexion", "extension", "axial_rotation"))
    lb_neg, ar_neg = torque.get("lateral_bending_left", lb), torque.get("axial_rotation_right", ar)
    defs = [
        "Tx=" + _sided("px", lb, lb_neg),
        "Ty=" + _sided("py", fl, ex),
        "Tz=" + _sided("pz", ar, ar_neg),
        "px=k*(r32-r23)", "py=k*(r13-r31)", "pz=k*(r21-r12)",
        "k=0.5*(1+a^2/6+7*a^4/360+31*a^6/15120+127*a^8/604800)",
        "a=acos(min(max((r11+r22+r33-1)/2,-1),1))",
        "r11=c2*c3", "r12=-c2*s3", "r13=s2",
        "r21=c1*s3+s1*s2*c3", "r22=c1*c3-s1*s2*s3", "r23=-s1*c2",
        "r31=s1*s3-c1*s2*c3", "r32=s1*c3+c1*s2*s3", "r33=c1*c2",
        "c1=cos(theta_x)", "s1=sin(theta_x)", "c2=cos(theta_y)", "s2=sin(theta_y)",
        "c3=cos(theta_z)", "s3=sin(theta_z)",
    ]
    tail = "; " + "; ".join(defs)
    return "Tx" + tail, "c1*Ty+s1*Tz" + tail, "s2*Tx-s1*c2*Ty+c1*c2*Tz" + tail


def disc_force_expressions(k_quadratic, k_linear, k_shear, k_tension=0.0, k_shear_lateral=None):
    """(Fx, Fy, Fz) of the translation bushing in the disc frame (OpenSim applies ``-F`` to frame 2)."""
    ks, k1, k2, kt = (_num(v) for v in (k_shear, k_linear, k_quadratic, k_tension))
    ksl = ks if k_shear_lateral is None else _num(k_shear_lateral)
    fz = f"({k1}*delta_z-{k2}*delta_z^2)*(1-step(delta_z))+{kt}*delta_z*step(delta_z)"
    return f"{ks}*delta_x", f"{ksl}*delta_y", fz


def fibre_expression(a, b, c, d, l0, extra, scale, slack_width_pct, damping) -> str:
    """Tension [N] of one softplus fibre (positive pulls its two points together), Eq. 7 on the strain in percent
    from the slack length ``l0`` [m] (``extra``: the fibre's constant extra path length [m])."""
    a, b, c, d = (_num(v) for v in (a, b, c, d))
    return (f"{_num(scale)}*max(F,0)*t*t*(3-2*t)+{_num(damping)}*ddot; "
            f"F={a}*(max(z,0)+log(1+exp(-abs(z))))+{c}; z=(e+{b})/{d}; "
            f"t=min(max(e/{_num(slack_width_pct)},0),1); e=(d+{_num(extra)})/{_num(l0)}*100-100")


def rupp_expression(l_a, dF0, nu, K_nl, K_l, l0, extra, scale, damping) -> str:
    """Tension [N] of one Rupp et al. (2015) strand (:func:`lumbar.mechanics.elements.ligament.rupp_force`): a power
    toe ``K_nl dl^nu`` up to ``l_a``, linear beyond, on the elongation ``dl`` [m] beyond the slack length ``l0``."""
    la, f0, n, knl, kl = (_num(v) for v in (l_a, dF0, nu, K_nl, K_l))
    return (f"{_num(scale)}*(step(x)*(1-step(x-{la}))*{knl}*max(x,1e-300)^{n}+step(x-{la})*({f0}+{kl}*(x-{la})))"
            f"+{_num(damping)}*ddot; x=d+{_num(extra)}-{_num(l0)}")


def facet_force_expressions(coef, k_point, eps) -> tuple[str, str, str]:
    """(Fx, Fy, Fz) of one facet contact point's bushing, in the contact surface's frame (u, v, w): gap
    ``g = delta_z - f(delta_x, delta_y)`` to the Eq. 4 surface, the smoothed penalty of the project
    (:func:`lumbar.mechanics.elements.facet.contact_penalty`) on the penetration ``-g``, along the surface gradient
    ``(-f_u, -f_v, 1)`` on the upper vertebra's point (OpenSim applies ``-F`` to frame 2)."""
    p30, p03, p20, p02, p00 = (_num(v) for v in coef)
    k, e = _num(k_point), _num(eps)
    defs = (f"; N={k}*(step(dl-{e})*(dl-{e}/2)+(1-step(dl-{e}))*step(dl)*dl^2/(2*{e})); "
            f"dl=({p30}*delta_x^3+{p03}*delta_y^3+{p20}*delta_x^2+{p02}*delta_y^2+{p00})-delta_z; "
            f"fu=3*{p30}*delta_x^2+2*{p20}*delta_x; fv=3*{p03}*delta_y^2+2*{p02}*delta_y")
    return "N*fu" + defs, "N*fv" + defs, "-N" + defs


# ------------------------------------------------------------------ the document
def _bushing(forces, name, frames, mexpr, fexpr, rot_damping, trans_damping):
    b = _sub(forces, "ExpressionBasedBushingForce", name=name)
    _sub(b, "socket_frame1", frames[0][0])
    _sub(b, "socket_frame2", frames[1][0])
    fr = _sub(b, "frames")
    for fname, body, trans, R in frames:
        _offset_frame(fr, fname, body, trans, R)
    for tag, text in zip(("Mx", "My", "Mz"), mexpr):
        _sub(b, f"{tag}_expression", text)
    for tag, text in zip(("Fx", "Fy", "Fz"), fexpr):
        _sub(b, f"{tag}_expression", text)
    _sub(b, "rotational_damping", _vec([rot_damping] * 3))
    _sub(b, "translational_damping", _vec([trans_damping] * 3))
    return b


def level_key(level_name: str) -> str:
    """An OpenSim-safe name of a level: ``L4-L5`` -> ``L4_L5``."""
    return level_name.replace("-", "_")


def _bodies_and_joint(model, lev, up, lo, c_up, c_lo, mesh_files):
    """The two vertebrae (meshes attached where given), the lower welded to ground, the upper on a FreeJoint whose
    frames sit at the disc centre with the project axes (coordinates :data:`COORDINATES`)."""
    key = level_key(lev.name)
    bodies = _sub(_sub(model, "BodySet", name="bodyset"), "objects")
    for vname in (lo, up):
        b = _sub(bodies, "Body", name=vname)
        if mesh_files and vname in mesh_files:
            ag = _sub(b, "attached_geometry")
            mesh = _sub(ag, "Mesh", name=f"{vname}_geometry")
            _sub(mesh, "socket_frame", "..")
            _sub(mesh, "mesh_file", mesh_files[vname])
        _sub(b, "mass", _num(VERTEBRA_MASS_KG))
        _sub(b, "mass_center", "0 0 0")
        _sub(b, "inertia", _vec([VERTEBRA_INERTIA_KGM2] * 3 + [0, 0, 0]))
    joints = _sub(_sub(model, "JointSet", name="jointset"), "objects")
    weld = _sub(joints, "WeldJoint", name=f"{lo}_to_ground")
    _sub(weld, "socket_parent_frame", "ground_offset")
    _sub(weld, "socket_child_frame", f"{lo}_offset")
    fr = _sub(weld, "frames")
    _offset_frame(fr, "ground_offset", "/ground", c_lo, np.eye(3))
    _offset_frame(fr, f"{lo}_offset", f"/bodyset/{lo}", np.zeros(3), np.eye(3))
    centre = np.asarray(lev.disc_centre, float)
    free = _sub(joints, "FreeJoint", name=f"{key}_joint")
    _sub(free, "socket_parent_frame", f"{lo}_disc_centre")
    _sub(free, "socket_child_frame", f"{up}_disc_centre")
    coords = _sub(free, "coordinates")
    for cname in COORDINATES:
        c = _sub(coords, "Coordinate", name=f"{key}_{cname}")
        _sub(c, "default_value", "0")
        rng = "-1.5707963267948966 1.5707963267948966" if COORDINATES.index(cname) < 3 else "-0.05 0.05"
        _sub(c, "range", rng)
    fr = _sub(free, "frames")
    _offset_frame(fr, f"{lo}_disc_centre", f"/bodyset/{lo}", centre - c_lo, np.eye(3))
    _offset_frame(fr, f"{up}_disc_centre", f"/bodyset/{up}", centre - c_up, np.eye(3))


def unit_document(fsu, name, mesh_files=None, include_facets=True, provenance="") -> ET.ElementTree:
    """The ``.osim`` document of a unit (a :class:`lumbar.experiments.fsu.FSU`: the finalized model of
    :func:`lumbar.experiments.fsu.configured_unit`). ``mesh_files``: {vertebra: file name beside the model} (None:
    no geometry). ``include_facets=False`` leaves the facet joints out (the disc and ligaments alone)."""
    m, lev = fsu.model, fsu.level
    if m.nb != 1 or len(m.fixed_names) != 1:
        raise ExportError(f"the export writes a unit of one free and one fixed vertebra; got free {m.body_names}, "
                          f"fixed {m.fixed_names}")
    up, lo = m.body_names[0], m.fixed_names[0]
    c_up, c_lo = np.asarray(m.centroids[0], float), np.asarray(m.fixed_centroids[0], float)
    if fsu.follower_group is not None:
        raise ExportError("the export writes a unit without the follower cable (build it with follower=False)")
    bad = sorted({m.fibre_groups[g][0] for g, law in zip(m.f_group, m.f_law) if law not in (LAW_SOFTPLUS, LAW_RUPP)})
    if bad:
        raise ExportError(f"the export writes softplus (Eq. 7) and Rupp ligaments; {', '.join(bad)} at {lev.name} "
                          "use another law (a cable: build the unit without its follower load)")
    if len(m.discs) != 1 or m.discs[0].law != "eq3":
        raise ExportError(f"the export writes one disc with the Eq. 3 torque law; {lev.name} has "
                          f"{[d.law for d in m.discs]}")
    key = level_key(lev.name)
    doc = ET.Element("OpenSimDocument", Version="40600")
    model = _sub(doc, "Model", name=name)
    doc.insert(0, ET.Comment(provenance))
    _sub(model, "credits", "lumbar (https://github.com/): calibrated lumbar functional spinal unit")
    _sub(model, "publications", provenance)
    _sub(model, "length_units", "meters")
    _sub(model, "force_units", "N")
    _sub(model, "gravity", "0 0 0")
    _bodies_and_joint(model, lev, up, lo, c_up, c_lo, mesh_files)
    forces = _sub(_sub(model, "ForceSet", name="forceset"), "objects")
    disc = m.discs[0]
    dcentre = np.asarray(disc.centre, float)
    _bushing(forces, f"{key}_disc_rotation",
             [(f"{lo}_disc", f"/bodyset/{lo}", dcentre - c_lo, np.eye(3)),
              (f"{up}_disc", f"/bodyset/{up}", dcentre - c_up, np.eye(3))],
             disc_moment_expressions(disc.torque), ("0", "0", "0"), DAMPING["disc_rotation"], 0.0)
    E = np.asarray(disc.frame, float).T               # columns e1, e2, e3 (= disc normal), project frame
    _bushing(forces, f"{key}_disc_translation",
             [(f"{lo}_disc_frame", f"/bodyset/{lo}", dcentre - c_lo, E),
              (f"{up}_disc_frame", f"/bodyset/{up}", dcentre - c_up, E)],
             ("0", "0", "0"), disc_force_expressions(disc.k_quadratic, disc.k_linear, disc.k_shear,
                                                    disc.k_tension, disc.k_shear_lateral),
             0.0, DAMPING["disc_translation"])
    counts = {}
    counts_total = {}
    for g in m.f_group:
        counts_total[m.fibre_groups[g][0]] = counts_total.get(m.fibre_groups[g][0], 0) + 1
    for i in range(m.nf):
        gname = m.fibre_groups[m.f_group[i]][0]
        j = counts.get(gname, 0)
        counts[gname] = j + 1
        a, b_, c, d = m.f_par[i, :4]
        ends = [(m.f_a[i], m.f_sa[i]), (m.f_b[i], m.f_sb[i])]
        names = [(up if k >= 0 else lo, s - (c_up if k >= 0 else c_lo)) for k, s in ends]
        f = _sub(forces, "ExpressionBasedPointToPointForce", name=f"{key}_{gname}_{j}")
        _sub(f, "body1", names[0][0])
        _sub(f, "body2", names[1][0])
        _sub(f, "point1", _vec(Q_OSIM @ names[0][1]))
        _sub(f, "point2", _vec(Q_OSIM @ names[1][1]))
        damp = DAMPING["fibre"] / max(counts_total[gname], 1)
        if m.f_law[i] == LAW_RUPP:
            expr = rupp_expression(*m.f_par[i, :5], m.f_l0[i], m.f_extra[i], m.f_scale[i], damp)
        else:
            expr = fibre_expression(a, b_, c, d, m.f_l0[i], m.f_extra[i], m.f_scale[i], m.slack_width_pct, damp)
        _sub(f, "expression", expr)
    if include_facets:
        for i in range(m.nc):
            sid = int(m.k_surf[i])
            surf = m.surfaces[sid]
            side = fsu.surface_side[sid]
            if m.k_a[i] < 0 or m.k_b[i] >= 0:
                raise ExportError("facet contact points must sit on the free (upper) vertebra against a surface on "
                                  "the fixed (lower) one")
            n_side = int(np.sum(m.k_surf[:i] == sid))
            axes = np.asarray(surf.axes, float).T          # columns u, v, w in the project frame
            _bushing(forces, f"{key}_facet_{side}_{n_side}",
                     [(f"{lo}_facet_{side}_{n_side}_surface", f"/bodyset/{lo}", np.asarray(surf.origin) - c_lo, axes),
                      (f"{up}_facet_{side}_{n_side}_point", f"/bodyset/{up}", np.asarray(m.k_s[i]) - c_up, axes)],
                     ("0", "0", "0"), facet_force_expressions(surf.coef, m.k_stiff[i], m.contact_eps),
                     0.0, DAMPING["facet_point"])
    ET.indent(doc, "\t")
    return ET.ElementTree(doc)


def provenance_text(level, set_name, geometry_name, include_facets) -> str:
    return (f" lumbar export: {geometry_name} {level}, characteristic set '{set_name}'"
            f"{'' if include_facets else ', facet joints left out'}. SI units (m, N, N*m, kg). Ground: X anterior, "
            "Y superior, Z right (project x anterior, y left, z superior rotated by -90 deg about x). Coordinates "
            "(FreeJoint, joint frames at the disc centre with the project axes): rotations of the upper vertebra "
            "about the anterior (lateral bending; positive = to the right), left (positive = flexion) and superior "
            "(positive = axial rotation to the left) axes, body-fixed X-Y-Z; then the displacement of its disc-centre "
            "point anterior, left and superior [m] (docs/opensim_export.md). Masses, inertias and damping are placeholders: "
            "they shape a forward simulation's transient, not a static equilibrium. Gravity 0 (the in-vitro unit). ")


def write_unit(fsu, out_dir, stem, set_name, geometry_name, include_facets=True, meshes=None, torque=None) -> Path:
    """Write ``<out_dir>/<stem>.osim`` and the vertebra meshes beside it (``<stem>_<vertebra>.stl`` in the body
    frames, ground axes); returns the model's path. ``meshes``: {vertebra: trimesh (project frame) or the name of a
    mesh file already beside the model} or None.
    ``torque``: write the reduced joint with these Eq. 3 parameters (:func:`reduced_joint`) instead of the detailed
    unit."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    m = fsu.model
    mesh_files = {}
    cents = {m.body_names[0]: m.centroids[0], m.fixed_names[0]: m.fixed_centroids[0]}
    for vname, mesh in (meshes or {}).items():
        if vname not in cents:
            continue
        if isinstance(mesh, str):            # a file already written beside the model
            mesh_files[vname] = mesh
            continue
        fname = f"{stem}_{vname}.stl"
        _write_stl(out_dir / fname, (np.asarray(mesh.vertices, float) - cents[vname]) @ Q_OSIM.T,
                   np.asarray(mesh.faces, int))
        mesh_files[vname] = fname
    text = provenance_text(fsu.level.name, set_name, geometry_name, include_facets)
    if torque is not None:
        doc = reduced_document(fsu, stem, torque, mesh_files, text.replace(
            "lumbar export:", "lumbar export, reduced joint (one bushing fitted to the unit's moment-rotation curves):"))
    else:
        doc = unit_document(fsu, stem, mesh_files, include_facets, text)
    path = out_dir / f"{stem}.osim"
    tmp = path.with_suffix(".osim.tmp")
    doc.write(tmp, encoding="UTF-8", xml_declaration=True)
    tmp.replace(path)
    return path


def _write_stl(path, vertices, faces):
    """A binary STL (deterministic bytes: no timestamp in the header)."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)
    rec = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"], rec["v"] = n, tri
    with open(path, "wb") as fh:
        fh.write(b"lumbar vertebra, metres, OpenSim ground axes".ljust(80, b" "))
        fh.write(np.uint32(len(faces)).tobytes())
        fh.write(rec.tobytes())


# ------------------------------------------------------------------ the project's side and OpenSim's
def lumbar_rom(fsu, moments_nm, directions, include_facets=True) -> pd.DataFrame:
    """The project's ROM [deg] of the unit (its own Newton solver) for the pure moments: direction, moment_nm,
    rom_deg, converged; ``include_facets=False`` with the facet stiffness set to 0 (the model's one setter, on a
    copy)."""
    import copy  # noqa: PLC0415

    from .fsu import range_of_motion  # noqa: PLC0415
    if not include_facets:
        fsu = copy.deepcopy(fsu)
        fsu.model.set_facet_stiffness(0.0)
    df = range_of_motion(fsu, tuple(moments_nm), tuple(directions), stages=("intact",))
    return df[["direction", "moment_nm", "rom_deg", "converged"]].reset_index(drop=True)


def _quiet(osim):
    """OpenSim's log at warnings only and no opensim.log in the working directory."""
    osim.Logger.removeFileSink()          # first: setting the level logs a line, which would open the file
    osim.Logger.setLevelString("warn")


def static_rom(osim_path, moments_nm, directions, tol=1e-9):
    """ROM [deg] of an exported unit in OpenSim: the equilibrium of its FreeJoint under each pure moment, found as
    the root of OpenSim's own generalised residual forces (``InverseDynamicsSolver`` at zero speed and acceleration:
    every force element of the file evaluated by OpenSim) with SciPy's hybrid Powell method, moment steps of at most
    2.5 N*m from the rest state; ROM = the rotation vector of the upper vertebra relative to its rest pose, component
    about the loading axis (as :func:`lumbar.experiments.fsu.range_of_motion`). Returns a DataFrame (direction,
    moment_nm, rom_deg, converged, residual). Imports ``opensim``: call it in a process without CasADi."""
    import opensim as osim  # noqa: PLC0415 - optional engine of the check
    from scipy.optimize import root  # noqa: PLC0415

    from ..mechanics import so3  # noqa: PLC0415
    _quiet(osim)
    model = osim.Model(str(osim_path))
    model.finalizeConnections()
    free = [model.getJointSet().get(i) for i in range(model.getJointSet().getSize())
            if model.getJointSet().get(i).getConcreteClassName() == "FreeJoint"]
    if len(free) != 1:
        raise ExportError(f"{osim_path}: expected one FreeJoint (the unit's upper vertebra), found {len(free)}")
    body = model.getBodySet().get(free[0].getChildFrame().findBaseFrame().getName())
    pf = osim.PrescribedForce("pure_moment", body)
    pf.setForceIsInGlobalFrame(True)
    pf.setTorqueFunctions(osim.Constant(0.0), osim.Constant(0.0), osim.Constant(0.0))
    model.addForce(pf)
    state = model.initSystem()
    torque = [osim.Constant.safeDownCast(pf.get_torqueFunctions().get(i)) for i in range(3)]
    ids = osim.InverseDynamicsSolver(model)
    coords = [free[0].get_coordinates(i) for i in range(free[0].numCoordinates())]
    nq = len(coords)
    udot = osim.Vector(state.getNU(), 0.0)
    scale = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])        # rad, m: Newton variables of similar size

    def residual(z):
        for c, v, s in zip(coords, z, scale):
            c.setValue(state, float(v * s), False)
        model.realizeVelocity(state)
        tau = ids.solve(state, udot)
        return np.array([tau.get(i) for i in range(tau.size())])

    def pose(z):
        residual(z)
        R = body.getTransformInGround(state).R().asMat33()
        return np.array([[R.get(i, j) for j in range(3)] for i in range(3)])

    def set_moment(M_project):
        for c, v in zip(torque, Q_OSIM @ np.asarray(M_project, float)):
            c.setValue(float(v))

    def equilibrium(z0):
        best = None
        for method in ("hybr", "lm"):
            sol = root(residual, z0, method=method, options={"xtol": tol})
            r = float(np.abs(residual(sol.x)).max())
            if best is None or r < best[2]:
                best = (sol.x, r < RESIDUAL_TOL, r)
            if r < RESIDUAL_TOL:
                break
        return best

    def advance(z, axis, sign, m_from, m_to, depth=0):
        """Equilibrium at m_to from the one at m_from; the step halved where the root finder fails."""
        Mv = np.zeros(3)
        Mv[axis] = sign * m_to
        set_moment(Mv)
        z1, ok, r = equilibrium(z)
        if ok or depth >= MAX_HALVINGS:
            return z1, ok, r
        zm, ok, r = advance(z, axis, sign, m_from, 0.5 * (m_from + m_to), depth + 1)
        if not ok:
            return zm, ok, r
        return advance(zm, axis, sign, 0.5 * (m_from + m_to), m_to, depth + 1)

    set_moment(np.zeros(3))
    z_rest, ok_rest, _ = equilibrium(np.zeros(nq))
    R0 = pose(z_rest)
    rows = []
    for d in directions:
        ax, sg = DIRECTION_AXES[d]
        z, done, ok = z_rest.copy(), 0.0, ok_rest
        for M in sorted(moments_nm):
            res = 0.0
            while ok and done < M - 1e-12:
                step = min(M, done + 2.5)
                z, ok, res = advance(z, ax, sg, done, step)
                done = step
            rot = Q_OSIM.T @ so3.log(pose(z) @ R0.T)          # OpenSim ground -> project axes
            rows.append({"direction": d, "moment_nm": float(M),
                         "rom_deg": float(np.degrees(rot[ax] * sg)) if ok else np.nan,
                         "converged": bool(ok), "residual": res})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ the reduced joint
#: the reduced joint's torque laws (Eq. 3 per project axis and side: the keys of
#: :func:`disc_moment_expressions`) and the unit's curve each is fitted to
REDUCED_AXES = {"lateral_bending": "lateral_bending_right", "lateral_bending_left": "lateral_bending_left",
                "flexion": "flexion", "extension": "extension",
                "axial_rotation": "axial_rotation_left", "axial_rotation_right": "axial_rotation_right"}
#: the largest relative ROM error at 2.5-10 N*m of a direction's Eq. 3 fit beyond which the reduced joint takes the
#: unit's curve itself (piecewise linear through its solved points): a curve with steps (a facet engaging, a
#: ligament tightening) that one smooth law cannot follow
EQ3_MAX_RELATIVE_ERROR = 0.05
#: the moments [N*m] of the unit's curves the reduced joint is fitted to
REDUCED_FIT_MOMENTS_NM = tuple(np.round(np.arange(0.5, 10.01, 0.5), 2))


def eq3_inverse(M, p1, p2, p3, hi=np.pi / 2):
    """The rotation [rad] at which a monotone Eq. 3 law (p1, p3 >= 0, p2 > 0) carries the moments ``M`` [N*m]
    (bisection, to 1e-12 rad)."""
    M = np.asarray(M, float)
    lo_, hi_ = np.zeros_like(M), np.full_like(M, hi)
    for _ in range(60):
        mid = 0.5 * (lo_ + hi_)
        below = p1 * np.tanh(mid**3 / p2) + p3 * mid < M
        lo_, hi_ = np.where(below, mid, lo_), np.where(below, hi_, mid)
    return 0.5 * (lo_ + hi_)


def fit_eq3(phi, moment):
    """Eq. 3 parameters (p1 [N*m], p2 [rad^3], p3 [N*m/rad]) whose rotation under ``moment`` [N*m] best matches
    ``phi`` [rad] (> 0) in relative terms (the ROM error the reduced joint is judged by), with p1, p3 >= 0 and p2 > 0
    (a monotone law: no snap-through in the reduced joint). Returns (params, rms relative error of the rotation)."""
    from scipy.optimize import least_squares  # noqa: PLC0415
    phi, M = np.asarray(phi, float), np.asarray(moment, float)
    ok = np.isfinite(phi) & (phi > 0) & (M > 0)
    phi, M = phi[ok], M[ok]
    if len(phi) < 3:
        raise ExportError(f"the reduced joint needs at least 3 solved points of a curve, got {len(phi)}")
    hi = np.argsort(phi)
    phi, M = phi[hi], M[hi]
    k_top = max((M[-1] - M[len(M) // 2]) / max(phi[-1] - phi[len(M) // 2], 1e-9), 1e-3)
    x0 = np.array([np.log(max(M[-1] - k_top * phi[-1], 0.1)), np.log(phi[len(M) // 2] ** 3), np.log(k_top)])

    def res(x):
        p1, p2, p3 = np.exp(x)
        return eq3_inverse(M, p1, p2, p3) / phi - 1.0

    sol = least_squares(res, x0, bounds=([np.log(1e-6), np.log(1e-9), np.log(1e-3)], [np.log(1e4), 0.0, np.log(1e4)]))
    p1, p2, p3 = np.exp(sol.x)
    return (float(p1), float(p2), float(p3)), float(np.sqrt(np.mean(sol.fun**2)))


def reduced_joint(fsu, moments_nm=REDUCED_FIT_MOMENTS_NM) -> tuple[dict, pd.DataFrame]:
    """The unit's whole response (disc, ligaments and facets together, solved by the project) reduced to one 6-DOF
    joint: Eq. 3 per project axis and side fitted to the unit's moment-rotation curves (``moments_nm``; where it
    misses by more than :data:`EQ3_MAX_RELATIVE_ERROR` at 2.5-10 N*m, the curve itself, piecewise linear), linear
    translational springs from the disc (its shear stiffness and its axial stiffness at rest; a pure moment hardly
    loads them), no coupling between the axes. Returns (torque parameters by direction, a table of the fit:
    direction, p1_nm, p2_rad3, p3_nm_per_rad, rms_relative_error (of the rotation), points, the unit's largest coupled
    rotation at the largest moment [deg], which the reduced joint leaves out)."""
    from .fsu import range_of_motion  # noqa: PLC0415
    df = range_of_motion(fsu, tuple(moments_nm), tuple(REDUCED_AXES.values()), stages=("intact",))
    torque, rows = {}, []
    for law, d in REDUCED_AXES.items():
        sub = df[(df["direction"] == d) & df["converged"]].sort_values("moment_nm")
        phi, M = np.radians(sub["rom_deg"].to_numpy()), sub["moment_nm"].to_numpy()
        params, err = fit_eq3(phi, M)
        worst = float(np.max(np.abs(eq3_inverse(M, *params) / phi - 1.0)[M >= 2.5 - 1e-9]))
        form = "eq3"
        if worst > EQ3_MAX_RELATIVE_ERROR:
            if not (np.all(np.diff(phi) > 0) and phi[0] > 0):
                raise ExportError(f"{fsu.level.name} {d}: the unit's moment-rotation curve is not increasing, so no "
                                  "monotone reduced joint reproduces it")
            form, err = "piecewise_linear", 0.0
            torque[law] = {"phi": phi.tolist(), "moment": M.tolist()}
        else:
            torque[law] = params
        top = sub[sub["moment_nm"] == sub["moment_nm"].max()]
        axis = DIRECTION_AXES[d][0]
        others = [c for k, c in enumerate(("rot_x_deg", "rot_y_deg", "rot_z_deg")) if k != axis]
        # phi_max^3 / p2 well below 1: the tanh stays in its linear range, the law is a cubic (p1/p2) phi^3 + p3 phi
        # and p1, p2 are determined only as their ratio (the fit then stops at p2's bound of 1 rad^3)
        sat = float(np.radians(sub["rom_deg"].max()) ** 3 / params[1])
        rows.append({"direction": d, "law": law, "form": form, "p1_nm": params[0], "p2_rad3": params[1],
                     "p3_nm_per_rad": params[2], "tanh_argument_at_max": sat,
                     "eq3_max_relative_error_2p5_10nm": worst, "rms_relative_error": err, "points": len(sub),
                     "unit_coupled_rotation_deg_at_max_moment": float(np.abs(top[others].to_numpy()).max())})
    return torque, pd.DataFrame(rows)


def reduced_document(fsu, name, torque, mesh_files=None, provenance="") -> ET.ElementTree:
    """The reduced joint of a unit as an ``.osim`` model: the two vertebrae, the same FreeJoint as the detailed
    model, and one ``ExpressionBasedBushingForce`` at the disc centre with the project axes (``torque``: Eq. 3
    parameters by direction, :func:`reduced_joint`; linear translational springs from the disc)."""
    m, lev = fsu.model, fsu.level
    key = level_key(lev.name)
    doc = ET.Element("OpenSimDocument", Version="40600")
    doc.insert(0, ET.Comment(provenance))
    model = _sub(doc, "Model", name=name)
    _sub(model, "credits", "lumbar: reduced joint of a calibrated lumbar functional spinal unit")
    _sub(model, "publications", provenance)
    _sub(model, "length_units", "meters")
    _sub(model, "force_units", "N")
    _sub(model, "gravity", "0 0 0")
    up, lo = m.body_names[0], m.fixed_names[0]
    c_up, c_lo = np.asarray(m.centroids[0], float), np.asarray(m.fixed_centroids[0], float)
    _bodies_and_joint(model, lev, up, lo, c_up, c_lo, mesh_files)
    forces = _sub(_sub(model, "ForceSet", name="forceset"), "objects")
    disc = m.discs[0]
    dcentre = np.asarray(disc.centre, float)
    ks, ka = _num(disc.k_shear), _num(disc.k_linear)
    _bushing(forces, f"{key}_reduced_joint",
             [(f"{lo}_joint", f"/bodyset/{lo}", dcentre - c_lo, np.eye(3)),
              (f"{up}_joint", f"/bodyset/{up}", dcentre - c_up, np.eye(3))],
             disc_moment_expressions(torque), (f"{ks}*delta_x", f"{ks}*delta_y", f"{ka}*delta_z"),
             DAMPING["disc_rotation"], DAMPING["disc_translation"])
    ET.indent(doc, "\t")
    return ET.ElementTree(doc)


# ------------------------------------------------------------------ a set, every level, and the check
#: the check's moments [N*m] and directions (the 2.5-10 N*m of the export's acceptance; lumbar.experiments.fsu)
CHECK_MOMENTS_NM = (2.5, 5.0, 7.5, 10.0)
CHECK_DIRECTIONS = ("flexion", "extension", "lateral_bending", "axial_rotation")
#: what each check variant models
VARIANTS = {"detailed": "disc, ligaments and facet joints (the exported model)",
            "detailed_no_facets": "disc and ligaments (the exported model without its facet bushings)",
            "reduced": "one bushing fitted to the detailed unit's curves (compared with the detailed unit)"}
CHECK_COLUMNS = ["set", "level", "variant", "direction", "moment_nm", "lumbar_deg", "opensim_deg", "difference_deg",
                 "relative_difference", "lumbar_converged", "opensim_converged", "status", "model_file"]


def specimen_stem(geometry_name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in geometry_name)


def export_set(geometry, charset, config, set_name, out_dir, levels=None, check_dir=None):
    """Write the detailed unit of every level (``levels``, default all of ``geometry``) of ``charset`` to
    ``out_dir`` (``<specimen>_<level>.osim`` with its meshes) and, under ``check_dir`` (default ``out_dir/check``),
    the same units without facets for the check, and each unit's reduced joint (``<specimen>_<level>_reduced.osim``,
    :func:`reduced_joint`). Returns (a DataFrame (level, variant, path, unit) of the files, the reduced joints' fit
    table). A level the geometry lacks is refused with its name before anything is written."""
    from .fsu import configured_unit  # noqa: PLC0415
    levels = list(levels or sorted(geometry.levels))
    missing = [lv for lv in levels if lv not in geometry.levels]
    if missing:
        raise ExportError(f"export levels {missing}: not in geometry {geometry.name!r} (has "
                          f"{sorted(geometry.levels)}); expected level names such as 'L4-L5'")
    out_dir = Path(out_dir)
    check_dir = Path(check_dir) if check_dir is not None else out_dir / "check"
    stem0 = specimen_stem(geometry.name)
    rows, fits = [], []
    written = {}                               # vertebra -> its mesh file (one per vertebra, shared by the levels)
    for lv in levels:
        fsu = configured_unit(geometry, charset, config, lv)
        lev = geometry.levels[lv]
        meshes = {}
        for v in (lev.upper, lev.lower):
            if v not in written:
                c = geometry.vertebrae[v].centroid
                written[v] = f"{stem0}_{v}.stl"
                out_dir.mkdir(parents=True, exist_ok=True)
                _write_stl(out_dir / written[v], (np.asarray(geometry.vertebrae[v].mesh.vertices, float) - c)
                           @ Q_OSIM.T, np.asarray(geometry.vertebrae[v].mesh.faces, int))
            meshes[v] = written[v]
        stem = f"{stem0}_{lv}"
        p = write_unit(fsu, out_dir, stem, set_name, geometry.name, include_facets=True, meshes=meshes)
        rows.append({"level": lv, "variant": "detailed", "path": str(p), "unit": fsu})
        p = write_unit(fsu, check_dir, f"{stem}_no_facets", set_name, geometry.name, include_facets=False)
        rows.append({"level": lv, "variant": "detailed_no_facets", "path": str(p), "unit": fsu})
        torque, fit = reduced_joint(fsu)
        p = write_unit(fsu, out_dir, f"{stem}_reduced", set_name, geometry.name, meshes=meshes, torque=torque)
        rows.append({"level": lv, "variant": "reduced", "path": str(p), "unit": fsu})
        fit.insert(0, "level", lv)
        fits.append(fit)
    return pd.DataFrame(rows), pd.concat(fits, ignore_index=True)


def check_table(files, set_name, moments_nm=CHECK_MOMENTS_NM, directions=CHECK_DIRECTIONS) -> pd.DataFrame:
    """The exported models' ROM in OpenSim beside the project's (:data:`CHECK_COLUMNS`), one row per file, direction
    and moment: ``files`` from :func:`export_set`. Where OpenSim cannot be imported every row says so in
    ``status`` (``opensim not available: ...``) and ``opensim_deg`` is empty; a scenario either engine did not
    solve says so too."""
    try:
        os_rom = static_rom_subprocess(files["path"], moments_nm, directions)
        why = None
    except OpenSimUnavailable as e:
        os_rom, why = {}, f"opensim not available: {e}"
    rows = []
    for _, f in files.iterrows():
        lum = lumbar_rom(f["unit"], moments_nm, directions, include_facets=f["variant"] != "detailed_no_facets")
        ops = os_rom.get(str(f["path"]))
        for i, r in lum.iterrows():
            o = ops.iloc[i] if ops is not None else None
            val = float(o["rom_deg"]) if o is not None and bool(o["converged"]) else np.nan
            ok_l = bool(r["converged"])
            status = why or ("ok" if ok_l and np.isfinite(val) else
                             "lumbar did not converge" if not ok_l else "OpenSim static solve did not converge")
            diff = val - float(r["rom_deg"]) if ok_l else np.nan
            rows.append({"set": set_name, "level": f["level"], "variant": f["variant"], "direction": r["direction"],
                         "moment_nm": float(r["moment_nm"]), "lumbar_deg": float(r["rom_deg"]), "opensim_deg": val,
                         "difference_deg": diff,
                         "relative_difference": diff / float(r["rom_deg"]) if ok_l and r["rom_deg"] else np.nan,
                         "lumbar_converged": ok_l, "opensim_converged": bool(o["converged"]) if o is not None else False,
                         "status": status, "model_file": Path(f["path"]).name})
    return pd.DataFrame(rows, columns=CHECK_COLUMNS)


def parameter_intervals(posterior: pd.DataFrame) -> pd.DataFrame:
    """The calibration's parameters with their MAP and 90 % posterior interval (``calibration/posterior.csv``), the
    table that travels with the exported MAP set: parameter, unit, map, posterior_90_low, posterior_90_high,
    prior_90_low, prior_90_high, at_bound."""
    need = ["parameter", "unit", "map", "posterior_90_low", "posterior_90_high", "prior_90_low", "prior_90_high",
            "at_bound"]
    miss = [c for c in need if c not in posterior.columns]
    if miss:
        raise ExportError(f"posterior table: missing column(s) {miss}; expected the calibration's posterior.csv")
    return posterior[need].copy()


def attach_reduced_joint(model_path, joint_name, reduced_path, out_path, force_name=None,
                         orientation=(-np.pi / 2, 0.0, 0.0)):
    """Put an exported reduced joint into an existing OpenSim model (run where ``opensim`` imports): a new
    ``ExpressionBasedBushingForce`` with the reduced joint's expressions and damping between the two bodies of the
    model's joint ``joint_name``, at that joint's parent and child frame locations, with the project's axes
    (``orientation``: body-fixed X-Y-Z angles of the project axes in the bodies' frames; the default assumes body
    frames with OpenSim's axes, X anterior, Y superior, Z right). Writes ``out_path``; the model's own joint
    stiffness (coordinate limit forces, other bushings) is left as it is: remove it where the bushing replaces it.
    docs/opensim_export.md."""
    import opensim as osim  # noqa: PLC0415

    _quiet(osim)
    model = osim.Model(str(model_path))
    model.finalizeConnections()
    frag = osim.Model(str(reduced_path))
    srcs = [frag.getForceSet().get(i) for i in range(frag.getForceSet().getSize())
            if frag.getForceSet().get(i).getConcreteClassName() == "ExpressionBasedBushingForce"]
    if len(srcs) != 1:
        raise ExportError(f"{reduced_path}: expected one ExpressionBasedBushingForce (a reduced joint), found "
                          f"{len(srcs)}")
    src = osim.ExpressionBasedBushingForce.safeDownCast(srcs[0])
    if not model.getJointSet().contains(joint_name):
        names = [model.getJointSet().get(i).getName() for i in range(model.getJointSet().getSize())]
        raise ExportError(f"{model_path}: no joint {joint_name!r}; joints: {names}")
    joint = model.getJointSet().get(joint_name)
    ends = []
    for frame in (joint.getParentFrame(), joint.getChildFrame()):
        off = osim.PhysicalOffsetFrame.safeDownCast(frame)
        where = off.get_translation() if off is not None else osim.Vec3(0)
        ends += [model.getBodySet().get(frame.findBaseFrame().getName()), where, osim.Vec3(*map(float, orientation))]
    b = osim.ExpressionBasedBushingForce(force_name or f"{joint_name}_lumbar_reduced_joint", *ends)
    for ax in "xyz":
        for kind in "MF":
            getattr(b, f"set{kind}{ax}Expression")(getattr(src, f"get{kind}{ax}Expression")())
    b.set_rotational_damping(src.get_rotational_damping())
    b.set_translational_damping(src.get_translational_damping())
    model.addForce(b)
    model.finalizeConnections()
    model.printToXML(str(out_path))
    return Path(out_path)


# ------------------------------------------------------------------ the check, in a process of its own
def static_rom_subprocess(paths, moments_nm, directions, timeout_s=600) -> dict:
    """{path: DataFrame of :func:`static_rom`} computed by a fresh interpreter (``python -m lumbar.experiments.export_opensim``):
    OpenSim and CasADi cannot share a process. Raises :class:`OpenSimUnavailable` when ``opensim`` cannot be
    imported there (with the reason)."""
    import json  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415
    spec = {"paths": [str(p) for p in paths], "moments_nm": list(map(float, moments_nm)),
            "directions": list(directions)}
    r = subprocess.run([sys.executable, "-m", "lumbar.experiments.export_opensim"], input=json.dumps(spec), text=True,
                       capture_output=True, timeout=timeout_s)
    if r.returncode == 3:
        raise OpenSimUnavailable(r.stderr.strip().splitlines()[-1] if r.stderr.strip() else "opensim not importable")
    if r.returncode != 0:
        raise RuntimeError(f"the OpenSim check failed (exit {r.returncode}): {r.stderr[-2000:]}")
    out = json.loads(r.stdout)
    return {p: pd.DataFrame(rows) for p, rows in out.items()}


class OpenSimUnavailable(RuntimeError):
    """``opensim`` cannot be imported (not installed, or a broken wheel)."""


def _check_worker() -> int:
    """``python -m lumbar.experiments.export_opensim``: the OpenSim side of :func:`static_rom_subprocess` (a JSON request on
    stdin, the ROM tables as JSON on stdout; exit 3 when opensim cannot be imported)."""
    import json  # noqa: PLC0415
    import sys  # noqa: PLC0415
    spec = json.loads(sys.stdin.read())
    try:
        import opensim  # noqa: F401, PLC0415
    except Exception as e:  # noqa: BLE001 - ImportError or a broken binary wheel: said, not fatal
        print(f"opensim not importable: {type(e).__name__}: {e}", file=sys.stderr)
        return 3
    out = {p: static_rom(p, spec["moments_nm"], spec["directions"]).to_dict("records") for p in spec["paths"]}
    print(json.dumps(out))
    return 0


def main(argv=None, prog="lumbar export-opensim") -> int:
    """``lumbar export-opensim``: the units of a characteristic set as .osim models, checked in OpenSim."""
    import argparse  # noqa: PLC0415
    import sys  # noqa: PLC0415

    import yaml  # noqa: PLC0415

    from ..inputs import manifests  # noqa: PLC0415
    p = argparse.ArgumentParser(prog=prog, description="Write a characteristic set's functional spinal units as "
                                "OpenSim 4.6 models (.osim, vertebra meshes beside them) and check each model's range "
                                "of motion in OpenSim against lumbar's solver (docs/opensim_export.md).")
    p.add_argument("--configfile", default="config/config.yaml",
                   help="the workflow configuration whose geometry and fsu sections describe the units")
    p.add_argument("--set", default="calibrated", help="characteristic set (calibrated or a literature set)")
    p.add_argument("--calibrated-dir", default=manifests.calibrated_dir(),
                   help="the calibration's characteristic tables (for --set calibrated; else data/characteristics' "
                        "published Table 3 set)")
    p.add_argument("--levels", nargs="+", default=None, help="levels (default: every level of the geometry)")
    p.add_argument("--out", default=None, help="output folder (default: the workflow's export folder of the set)")
    p.add_argument("--no-check", action="store_true", help="write the models only")
    a = p.parse_args(argv)
    from ..geometry.configured import load_configured  # noqa: PLC0415
    from ..inputs.characteristics import CharacteristicsError, resolve_characteristic_set  # noqa: PLC0415
    try:
        with open(a.configfile) as fh:
            cfg = yaml.safe_load(fh) or {}
    except OSError as e:
        print(f"{prog}: error: --configfile {a.configfile}: {e.strerror}", file=sys.stderr)
        return 2
    try:
        cs = resolve_characteristic_set(a.set, calibrated_dir=a.calibrated_dir)
        geo = load_configured(cfg.get("geometry", {"kind": "visible_human"}))
        models = manifests.MANIFESTS["export_opensim"].outputs["models"].paths()[0]
        out = Path(a.out) if a.out else Path(models).parent / a.set
        files, fits = export_set(geo, cs, cfg, a.set, out, levels=a.levels)
        fits.to_csv(out / "reduced_joints.csv", index=False)
    except (ExportError, CharacteristicsError, ValueError) as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    for f in files[files["variant"] != "detailed_no_facets"]["path"]:
        print(f"wrote {f}")
    if a.no_check:
        return 0
    table = check_table(files, a.set)
    path = out / "opensim_check.csv"
    table.to_csv(path, index=False)
    ok = table[table["status"] == "ok"]
    if not len(ok):
        print(f"OpenSim check not run: {table['status'].iloc[0]}")
        return 0
    for v, g in ok.groupby("variant"):
        print(f"OpenSim check, {v}: largest |difference| {g['difference_deg'].abs().max():.2g} deg over {len(g)} "
              f"scenarios ({path})")
    return 0 if len(ok) == len(table) else 1


if __name__ == "__main__":
    raise SystemExit(_check_worker())
