"""The library from an installed wheel, outside the checkout: it imports and finds its schema and data.

Builds a wheel (setup.py's build step bundles data/ and the config schema as lumbar/_resources/) from a copy
of the files the build reads, installs it with pip into a temporary target directory, and runs a fresh
interpreter with its working directory outside the checkout, the checkout's src/ removed from sys.path (the
editable install's .pth puts it there) and the target directory first. That interpreter must import lumbar
from the target, load the config schema and defaults, the default ("calibrated", as published) characteristic
set and the embedded Visible Human geometry's summary, and report every path it used: all of them must lie in
the installed copy.
"""
from __future__ import annotations

import filecmp
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# What the build reads (an sdist-like tree): the project files, the package, and the resources it bundles.
BUILD_FILES = ("pyproject.toml", "setup.py", "MANIFEST.in", "LICENSE", "README.md")
BUILD_DIRS = ("src", "data", "workflow/schemas")

PROBE = r"""
import json, sys
from pathlib import Path
target, checkout_src = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
sys.path[:] = [target.as_posix()] + [p for p in sys.path if p and Path(p).resolve() != checkout_src]

import lumbar
from lumbar.inputs import resources
from lumbar.inputs.characteristics import default_data_dir, load_characteristic_set
from lumbar.inputs.config import default_geometry_path, default_schema_path, load_config, resolve_path
from lumbar.geometry import load_geometry
from lumbar.geometry.analysis import summary_table
from lumbar.geometry.landmarks import default_csv_path
from lumbar.experiments.l2s1 import default_cable_table
from lumbar.muscles.muscle_set import DATA_DIR as MUSCLE_DIR
from lumbar.muscles.muscle_model import DATA as MODEL_DATA

cfg = load_config({})
cs = load_characteristic_set("calibrated", data_dir=resolve_path(cfg["characteristics"]["data_dir"]))
geo = load_geometry(cfg["geometry"]["kind"], path=default_geometry_path())
summary = summary_table(geo)
print(json.dumps({
    "lumbar": lumbar.__file__,
    "in_checkout": resources.in_checkout(),
    "paths": {
        "schema": str(default_schema_path()),
        "data_dir": str(resources.data_dir()),
        "characteristics": str(default_data_dir()),
        "characteristic_set": cs.source,
        "disc": cs.disc.source,
        "geometry": str(default_geometry_path()),
        "landmarks": str(default_csv_path()),
        "cables": str(default_cable_table()),
        "muscles": str(MUSCLE_DIR),
        "anthropometry": str(MODEL_DATA / "anthropometry"),
    },
    "fsu_level": cfg["fsu"]["level"],
    "set": cs.name,
    "ligaments": sorted(cs.ligaments),
    "levels": summary["level"].tolist(),
    "disc_csa_mm2": summary["disc_csa_mm2"].tolist(),
}))
"""


def _within(path, parent: Path) -> bool:
    return Path(path).resolve().is_relative_to(parent.resolve())


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(target directory, wheel path): the wheel built from a copy of the build inputs, installed by pip."""
    setuptools = pytest.importorskip("setuptools", reason="building the wheel needs setuptools")
    if int(setuptools.__version__.split(".")[0]) < 77:
        pytest.skip(f"setuptools {setuptools.__version__} < 77 (pyproject's build requirement; "
                    "pip install -r requirements-test.txt)")
    base = tmp_path_factory.mktemp("wheel")
    tree, dist, target = base / "tree", base / "dist", base / "site"
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "*.pyc")
    for f in BUILD_FILES:
        if (ROOT / f).is_file():
            (tree / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, tree / f)
    for d in BUILD_DIRS:
        shutil.copytree(ROOT / d, tree / d, ignore=ignore)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input"]
    subprocess.run(pip + ["wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(dist), str(tree)],
                   check=True, cwd=base, capture_output=True, text=True)
    wheels = sorted(dist.glob("lumbar-*.whl"))
    assert len(wheels) == 1, wheels
    subprocess.run(pip + ["install", "-q", "--no-deps", "--no-index", "--target", str(target), str(wheels[0])],
                   check=True, cwd=base, capture_output=True, text=True)
    return target, wheels[0]


def test_wheel_bundles_data_and_schema_byte_identical(installed):
    target, _ = installed
    res = target / "lumbar" / "_resources"
    assert filecmp.cmp(ROOT / "workflow" / "schemas" / "config.schema.yaml",
                       res / "workflow" / "schemas" / "config.schema.yaml", shallow=False)
    files = [p.relative_to(ROOT) for p in (ROOT / "data").rglob("*") if p.is_file()]
    assert files
    missing = [str(f) for f in files if not (res / f).is_file()]
    assert not missing, f"data files not in the wheel: {missing[:10]}"
    differ = [str(f) for f in files if not filecmp.cmp(ROOT / f, res / f, shallow=False)]
    assert not differ, f"data files differ in the wheel: {differ[:10]}"


def test_installed_wheel_works_outside_the_checkout(installed, tmp_path):
    target, _ = installed
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "LUMBAR_DATA_DIR", "PYTHONHOME")}
    # -I: no PYTHONPATH, no user site, no script directory; the probe puts the wheel's target first itself
    proc = subprocess.run([sys.executable, "-I", "-c", PROBE, str(target), str(ROOT / "src")],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-4000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert _within(out["lumbar"], target), f"imported {out['lumbar']}, not the wheel's copy under {target}"
    assert out["in_checkout"] is False
    for what, path in out["paths"].items():
        assert _within(path, target / "lumbar" / "_resources"), f"{what}: {path} is not the wheel's copy"
        assert Path(path).exists(), f"{what}: {path} does not exist"
    assert out["fsu_level"] == "L4-L5"
    assert out["set"] == "calibrated" and out["ligaments"]
    assert out["levels"] == ["L1-L2", "L2-L3", "L3-L4", "L4-L5", "L5-S1"]
    assert all(a > 0 for a in out["disc_csa_mm2"])
