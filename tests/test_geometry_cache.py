"""The content-addressed cache of parsed geometry files (lumbar.geometry.diskcache): the meshes and nodes a process
reads from it are the ones it would parse; an entry belongs to the bytes of a file, not to its name or time; a
damaged entry or an unwritable cache falls back to parsing; the checks on the arrays run on every read."""
import os

import numpy as np
import pytest
import trimesh

from lumbar.geometry import GeometryError, diskcache, load_geometry, meshio, visible_human
from lumbar.geometry.synthetic import symmetric_fsu


@pytest.fixture
def cache(tmp_path, monkeypatch):
    d = tmp_path / "cache"
    monkeypatch.setenv(diskcache.ENV, str(d))
    meshio._read_mesh_cached.cache_clear()
    visible_human._read_nodes_cached.cache_clear()
    yield d
    meshio._read_mesh_cached.cache_clear()
    visible_human._read_nodes_cached.cache_clear()


def _mesh_file(path, scale=1.0):
    m = symmetric_fsu().vertebrae["L4"].mesh.copy()
    m.apply_scale(scale)
    m.export(path)
    return path


def test_a_mesh_from_the_cache_is_the_mesh_trimesh_loads(cache, tmp_path):
    f = _mesh_file(tmp_path / "v.obj")
    first = meshio.read_mesh(f)
    assert len(list((cache / "mesh").glob("*.npz"))) == 1
    meshio._read_mesh_cached.cache_clear()                 # a new process: the in-process cache is empty
    second = meshio.read_mesh(f)
    direct = trimesh.load(f, force="mesh", process=True)
    for m in (first, second):
        assert np.array_equal(m.vertices, direct.vertices) and np.array_equal(m.faces, direct.faces)
        assert m.volume == pytest.approx(direct.volume, rel=1e-12)


def test_an_entry_belongs_to_the_bytes_not_to_the_name_or_the_time(cache, tmp_path):
    f = tmp_path / "nodes.txt"
    calls = []

    def parse():
        calls.append(1)
        return {"nodes": np.loadtxt(f)[:, 1:]}

    f.write_text("1 0.0 0.0 0.0\n2 0.01 0.0 0.0\n")
    st = os.stat(f)
    a = diskcache.load_or_parse(f, "nodes", "t", parse)["nodes"]
    f.write_text("1 0.0 0.0 0.0\n2 0.02 0.0 0.0\n")             # other bytes, same name, same time stamps
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    b = diskcache.load_or_parse(f, "nodes", "t", parse)["nodes"]
    assert a[1, 0] == 0.01 and b[1, 0] == 0.02 and len(calls) == 2
    assert diskcache.load_or_parse(f, "nodes", "t", parse)["nodes"][1, 0] == 0.02 and len(calls) == 2
    assert diskcache.load_or_parse(f, "nodes", "another version", parse)["nodes"][1, 0] == 0.02 and len(calls) == 3


def test_a_damaged_entry_is_parsed_again_and_replaced(cache, tmp_path):
    f = _mesh_file(tmp_path / "v.obj")
    good = meshio.read_mesh(f)
    (entry,) = (cache / "mesh").glob("*.npz")
    entry.write_bytes(b"not an npz file")
    meshio._read_mesh_cached.cache_clear()
    again = meshio.read_mesh(f)
    assert np.array_equal(again.vertices, good.vertices) and np.array_equal(again.faces, good.faces)
    with np.load(entry) as z:                                   # rewritten
        assert np.array_equal(z["faces"], good.faces)


def test_the_checks_run_on_a_mesh_read_from_the_cache(cache, tmp_path):
    f = _mesh_file(tmp_path / "mm.obj", scale=1000.0)           # millimetres
    for _ in range(2):
        meshio._read_mesh_cached.cache_clear()
        with pytest.raises(GeometryError, match="millimetres"):
            meshio.read_mesh(f)


def test_an_empty_setting_or_an_unwritable_folder_means_no_cache(tmp_path, monkeypatch):
    f = _mesh_file(tmp_path / "v.obj")
    monkeypatch.setenv(diskcache.ENV, "")
    assert diskcache.cache_dir() is None
    meshio._read_mesh_cached.cache_clear()
    assert len(meshio.read_mesh(f).faces) > 0
    blocker = tmp_path / "file_not_folder"
    blocker.write_text("")
    monkeypatch.setenv(diskcache.ENV, str(blocker))
    meshio._read_mesh_cached.cache_clear()
    assert np.array_equal(meshio.read_mesh(f).faces, trimesh.load(f, force="mesh", process=True).faces)
    meshio._read_mesh_cached.cache_clear()


def test_the_visible_human_geometry_is_the_same_from_the_cache(cache):
    first = load_geometry("visible_human", levels=["L4-L5"])
    n = len(list(cache.rglob("*.npz")))
    assert n > 0 and (cache / "mesh").is_dir() and (cache / "nodes").is_dir()
    meshio._read_mesh_cached.cache_clear()
    visible_human._read_nodes_cached.cache_clear()
    second = load_geometry("visible_human", levels=["L4-L5"])
    assert len(list(cache.rglob("*.npz"))) == n
    for v in ("L4", "L5"):
        assert np.array_equal(first.vertebrae[v].centroid, second.vertebrae[v].centroid)
        assert np.array_equal(first.vertebrae[v].mesh.vertices, second.vertebrae[v].mesh.vertices)
    a, b = first.levels["L4-L5"], second.levels["L4-L5"]
    assert np.array_equal(a.disc_centre, b.disc_centre)
    for k in a.facets:
        assert np.array_equal(a.facets[k].superior, b.facets[k].superior)
