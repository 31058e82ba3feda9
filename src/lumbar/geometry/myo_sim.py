"""Read the embedded myo-sim (PyPI ``myo-sim``) lumbar meshes and place them in the project frame.

Nothing is copied from the package: meshes and the torso MJCF are read from site-packages at run time.

Frame conversion.  The torso chain (``models/torso/assets/myotorso_chain.xml``) is a MuJoCo port of an
OpenSim model: every body frame is OpenSim-like (x anterior, y superior, z right) and the root body
``sacrum`` is rotated by ``euler="pi/2 -pi/2 0"`` (MuJoCo intrinsic x-y-z) into the MuJoCo world, where
anterior = -y_w, left = +x_w, superior = +z_w.  The project frame (x anterior, y left, z superior) is
therefore ``p = R_PW @ w`` with ``R_PW = [[0,-1,0],[1,0,0],[0,0,1]]`` (a -90 deg turn about z).
World poses are those of qpos0 (all joints zero).  Meshes carry no ``scale`` attribute (scale 1, metres).
"""
from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .core import GeometryError

R_PROJECT_FROM_WORLD = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])

BODY_OF = {"L1": "lumbar1", "L2": "lumbar2", "L3": "lumbar3", "L4": "lumbar4", "L5": "lumbar5", "S1": "sacrum"}
MYO_SIM_VERSION_NOTE = "myo-sim (Apache-2.0)"


def package_root() -> Path:
    try:
        import myo_sim  # noqa: PLC0415
    except ImportError as exc:  # pragma: no cover
        raise GeometryError("kind='default' needs the PyPI package myo-sim (pip install myo-sim)") from exc
    return Path(myo_sim.__file__).resolve().parent


def package_version() -> str:
    try:
        from importlib.metadata import version  # noqa: PLC0415
        return version("myo-sim")
    except Exception:  # pragma: no cover  # noqa: BLE001 - no metadata in any form: "unknown"
        return "unknown"


def mjcf_vector(el, name, default):
    """The numbers of the MJCF attribute ``name`` of element ``el`` as an array (``default`` if absent)."""
    s = el.get(name)
    return np.array([float(v) for v in s.split()]) if s else np.array(default, dtype=float)


def mjcf_rotation(el) -> np.ndarray:
    """Rotation matrix of an MJCF element's orientation (``quat`` or ``euler``; identity if none)."""
    from scipy.spatial.transform import Rotation  # noqa: PLC0415 - see lumbar/__init__.py, lazy imports
    if el.get("quat"):
        w, x, y, z = mjcf_vector(el, "quat", [1, 0, 0, 0])
        return Rotation.from_quat([x, y, z, w]).as_matrix()
    if el.get("euler"):
        # MuJoCo default eulerseq "xyz" = intrinsic (rotating axes) == scipy "XYZ"
        return Rotation.from_euler("XYZ", mjcf_vector(el, "euler", [0, 0, 0])).as_matrix()
    if el.get("axisangle") or el.get("xyaxes") or el.get("zaxis"):  # pragma: no cover
        raise GeometryError(f"unsupported orientation attribute in <{el.tag} name={el.get('name')}>")
    return np.eye(3)


@functools.lru_cache(maxsize=4)
def body_poses(root, path):
    """(body element, R, t) of the sacrum and every body below it at qpos0, in the MJCF world frame, parents
    before children (document order): the pose chain shared by the mesh placements and the muscle sites.
    ``path`` names the file in the error if the model has no sacrum."""
    sac = next((b for b in root.iter("body") if b.get("name") == "sacrum"), None)
    if sac is None:
        raise GeometryError(f"{path}: no <body name='sacrum'> found")
    stack = [(sac, np.eye(3), np.zeros(3))]
    while stack:
        body, R_parent, t_parent = stack.pop()
        R = R_parent @ mjcf_rotation(body)
        t = t_parent + R_parent @ mjcf_vector(body, "pos", [0, 0, 0])
        yield body, R, t
        stack.extend((c, R, t) for c in reversed(body.findall("body")))


def placements(chain_xml: str) -> dict:
    """{body: (mesh_file_stem, R, t)} so that project = R @ v_stl + t (qpos0)."""
    p = Path(chain_xml)
    if not p.is_file():
        raise GeometryError(f"{p}: myo-sim torso chain MJCF missing")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise GeometryError(f"{p}: not valid XML ({exc})") from exc
    assets = p.parent / "myotorso_assets.xml"
    mesh_files = {}
    if assets.is_file():
        for m in ET.parse(assets).getroot().iter("mesh"):
            if m.get("scale"):
                s = mjcf_vector(m, "scale", [1, 1, 1])
                if not np.allclose(s, 1):  # pragma: no cover
                    raise GeometryError(f"{assets}: mesh {m.get('name')} has scale {s}; not supported")
            mesh_files[m.get("name")] = m.get("file")
    out = {}

    for body, R, t in body_poses(root, p):
        name = body.get("name")
        if name in BODY_OF.values():
            for g in body.findall("geom"):
                if g.get("type") == "mesh" and g.get("mesh"):
                    Rg = R @ mjcf_rotation(g)
                    tg = t + R @ mjcf_vector(g, "pos", [0, 0, 0])
                    f = mesh_files.get(g.get("mesh"), f"meshes/{name}.stl")
                    out[name] = (f, R_PROJECT_FROM_WORLD @ Rg, R_PROJECT_FROM_WORLD @ tg)
                    break
    missing = [b for b in BODY_OF.values() if b not in out]
    if missing:
        raise GeometryError(f"{p}: mesh geoms missing for bodies {missing}")
    return out


def chain_path() -> Path:
    return package_root() / "models" / "torso" / "assets" / "myotorso_chain.xml"


def meshes_dir() -> Path:
    return package_root() / "models"


def load_raw_meshes(names=tuple(BODY_OF)) -> dict:
    """Return {vertebra: trimesh in the project frame} for the requested vertebrae."""
    from .meshio import read_mesh  # noqa: PLC0415
    pl = placements(str(chain_path()))
    out = {}
    for v in names:
        f, R, t = pl[BODY_OF[v]]
        m = read_mesh(meshes_dir() / f)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = t
        m.apply_transform(T)
        out[v] = m
    return out
