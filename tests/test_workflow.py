"""The Snakemake workflow: dry run, lint, and the geometry rules' outputs of the session DAG run on config/test."""
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]
TEST_CONFIG = "config/test/config.yaml"
MY_RULES = ("all", "fsu_geometry", "fig1_l4l5_model")


def _smk(*args, cwd=ROOT, timeout=300):
    return subprocess.run(SNAKEMAKE + list(args), cwd=cwd, capture_output=True, text=True, timeout=timeout)


def _png_std(path) -> float:
    from PIL import Image

    return float(np.asarray(Image.open(path).convert("RGB"), float).std())


@pytest.mark.workflow
def test_dry_run_on_test_config():
    r = _smk("-n", "--forceall", "--configfile", TEST_CONFIG)  # all jobs, whatever results/ holds
    assert r.returncode == 0, r.stdout + r.stderr
    out = r.stdout + r.stderr
    for rule in MY_RULES:
        assert re.search(rf"^{rule}\s+1$", out, re.M), f"{rule} missing from the dry-run job table\n{out}"


@pytest.mark.workflow
def test_dry_run_rejects_invalid_config(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("fsu:\n  facet_stiffness_n_per_m: -1\n")
    r = _smk("-n", "--configfile", str(bad))
    assert r.returncode != 0
    assert "facet_stiffness_n_per_m" in r.stdout + r.stderr


# snakemake --lint of every rule (not only the geometry rules): tests/test_lint.py, test_snakemake_lint_is_clean


def test_conda_env_matches_environment_txt():
    import yaml

    pins = sorted(ln.strip() for ln in (ROOT / "environment.txt").read_text().splitlines()
                  if ln.strip() and not ln.startswith("#"))
    env = yaml.safe_load((ROOT / "workflow" / "envs" / "lumbar.yaml").read_text())
    pip = next(d["pip"] for d in env["dependencies"] if isinstance(d, dict))
    assert sorted(pip) == pins
    assert all(re.fullmatch(r"[A-Za-z0-9_.\-]+==[0-9][^\s]*", p) for p in pins)


def test_library_does_not_import_snakemake():
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "src" / "lumbar").rglob("*.py")
                 if re.search(r"^\s*(import|from)\s+snakemake", p.read_text(), re.M)]
    assert offenders == []


@pytest.fixture(scope="module")
def synthetic_geometry():
    from lumbar.geometry.synthetic import symmetric_fsu   # a broken import fails the test, never skips it

    return symmetric_fsu()


def test_render_matplotlib_fallback_not_blank(tmp_path, synthetic_geometry):
    from lumbar.plots.render import render_fsu

    out = tmp_path / "fig.png"
    assert render_fsu(synthetic_geometry, "L4-L5", out, backend="matplotlib") == "matplotlib"
    assert _png_std(out) > 5.0


def test_render_auto_deterministic(tmp_path, synthetic_geometry):
    """Same input, same bytes (fixed cameras, no time metadata); pyvista when it can render here."""
    from lumbar.plots.render import offscreen_available, render_fsu

    a, b = tmp_path / "a.png", tmp_path / "b.png"
    used = render_fsu(synthetic_geometry, "L4-L5", a)
    render_fsu(synthetic_geometry, "L4-L5", b)
    assert used == ("pyvista" if offscreen_available() else "matplotlib")
    assert _png_std(a) > 5.0
    assert a.read_bytes() == b.read_bytes()
    assert b"tIME" not in a.read_bytes()


def test_render_unknown_level_names_available(tmp_path, synthetic_geometry):
    from lumbar.plots.render import render_fsu

    with pytest.raises(KeyError, match="L4-L5"):
        render_fsu(synthetic_geometry, "L1-L2", tmp_path / "x.png", backend="matplotlib")


def test_geometry_rules_run(dag_workdir):
    """fsu_geometry and fig1_l4l5_model on config/test, from the session's DAG run (conftest.dag_workdir):
    the table's L4-L5 row is the geometry the library loads for the same config (values, not only the file)."""
    import pandas as pd
    import yaml

    from lumbar.geometry import load_geometry

    targets = ["results/tables/fsu_geometry.csv", "results/figures/fig1_l4l5_model.png"]
    table = pd.read_csv(dag_workdir / targets[0])
    assert len(table) >= 1 and "L4-L5" in set(table["level"])
    row = table.set_index("level").loc["L4-L5"]
    assert 500 < row["disc_csa_mm2"] < 4000          # adult lumbar endplate area, mm^2
    assert 3 < row["disc_height_mm"] < 25
    assert np.isclose(np.linalg.norm(row[["disc_normal_x", "disc_normal_y", "disc_normal_z"]].astype(float)), 1, atol=1e-3)
    g = yaml.safe_load((dag_workdir / TEST_CONFIG).read_text())["geometry"]
    path = g.get("path")
    lev = load_geometry(g["kind"], path=(dag_workdir / path) if path and g["kind"] == "visible_human" else None,
                        levels=["L4-L5"]).levels["L4-L5"]
    assert row["disc_csa_mm2"] == pytest.approx(lev.disc_csa * 1e6, rel=1e-6)
    np.testing.assert_allclose(row[["disc_normal_x", "disc_normal_y", "disc_normal_z"]].astype(float),
                               np.asarray(lev.disc_normal) / np.linalg.norm(lev.disc_normal), atol=1e-6)
    assert _png_std(dag_workdir / targets[1]) > 5.0
    assert (dag_workdir / "logs" / "fig1_l4l5_model.log").read_text().strip()
    assert (dag_workdir / "results" / "benchmarks" / "fig1_l4l5_model.tsv").exists()


def test_render_falls_back_when_offscreen_unavailable(tmp_path, synthetic_geometry, monkeypatch, caplog):
    """No EGL/OSMesa: auto mode logs a warning and still writes a non-blank PNG."""
    import lumbar.plots.render as render

    monkeypatch.setattr(render, "_offscreen_cache", False)
    out = tmp_path / "fig.png"
    with caplog.at_level("WARNING", logger="lumbar.plots.render"):
        assert render.render_fsu(synthetic_geometry, "L4-L5", out) == "matplotlib"
    assert "falling back to matplotlib" in caplog.text
    assert _png_std(out) > 5.0
