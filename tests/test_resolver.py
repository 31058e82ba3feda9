"""One resolver of a characteristic set (lumbar.inputs.characteristics.resolve_characteristic_set), used by the
workflow's FSU, stepwise-reduction (Table 4) and L2-S1 (Table 5) stages and by the FSU command line."""
import re
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from lumbar.inputs.characteristics import default_data_dir, load_characteristic_set, resolve_characteristic_set

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def calibrated_dir(tmp_path):
    d = tmp_path / "characteristics"
    shutil.copytree(default_data_dir(), d)
    fac = pd.read_csv(d / "facet.csv", dtype=str, keep_default_na=False)
    fac.loc[fac["parameter"] == "stiffness", "value"] = "345678.0"
    fac.loc[fac["parameter"] == "stiffness", "kind"] = "calibrated_on_surrogate"
    fac.to_csv(d / "facet.csv", index=False)
    return d


def test_calibrated_comes_from_the_calibration_output(calibrated_dir):
    cs = resolve_characteristic_set("calibrated", calibrated_dir=calibrated_dir)
    assert cs.facet.stiffness == pytest.approx(345678.0)
    published = resolve_characteristic_set("calibrated", calibrated_dir=calibrated_dir.parent / "missing")
    assert published.facet.stiffness == load_characteristic_set("calibrated").facet.stiffness != 345678.0


def test_literature_sets_ignore_the_calibration_output(calibrated_dir):
    cs = resolve_characteristic_set("rupp2015", calibrated_dir=calibrated_dir)
    assert cs.facet.stiffness == load_characteristic_set("rupp2015").facet.stiffness


def test_fsu_command_line_uses_the_same_calibrated_values(calibrated_dir, capsys, monkeypatch):
    """``lumbar fsu`` (its main, in this process, from the repository root as a user runs it) takes the calibrated
    set from --calibrated-dir and says so; without that output, the published set, and the ROM changes."""
    from lumbar import cli
    monkeypatch.chdir(ROOT)
    args = ["fsu", "--moment", "2.5", "--direction", "axial_rotation", "--calibrated-dir"]
    assert cli.main([*args, str(calibrated_dir)]) == 0
    out = capsys.readouterr().out
    assert str(calibrated_dir) in out.splitlines()[0]
    assert cli.main([*args, str(calibrated_dir / "nope")]) == 0
    out_pub = capsys.readouterr().out
    assert "as published" in out_pub.splitlines()[0]

    def rom(text):
        row = [ln for ln in text.splitlines() if ln.strip().startswith("intact")][0]
        return float(row.split()[3])
    assert rom(out) != pytest.approx(rom(out_pub), abs=1e-3)   # the calibrated facets act


def test_every_stage_takes_calibrated_from_the_calibration_output():
    """Table 4 (stepwise_reduction_sim), Table 5 (l2s1_idp) and fsu_rom take the calibrated set from rule
    calibrate's output, the literature sets never (the DAG of the test configuration)."""
    out = subprocess.run(["snakemake", "-n", "--forceall", "--dag", "dot", "--configfile", "config/test/config.yaml",
                          "--", "results/tables/table5_idp_synopsis.csv", "results/tables/table4_rom_synopsis.csv",
                          "results/tables/fsu_rom_intact.csv"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    label = dict(re.findall(r'^\s*(\d+)\[label = "([^"]+)"', out.stdout, flags=re.M))
    edges = set(re.findall(r"^\s*(\d+) -> (\d+)", out.stdout, flags=re.M))
    cal = [k for k, v in label.items() if v == "calibrate"]
    assert len(cal) == 1
    children = {label[b] for a, b in edges if a == cal[0]}
    assert {"fsu_rom", r"stepwise_reduction_sim\nset: calibrated", r"l2s1_idp\nset: calibrated"} <= children
    assert not any("rupp2015" in c for c in children)
