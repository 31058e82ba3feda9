"""Bad inputs are rejected with a message naming the file, row, column (or config key) and the expected form,
and the rule that read them leaves no result behind.

Most cases run the rule's workflow script by hand, in this process (``python workflow/scripts/<rule>.py
<rule> --configfile ... --output <tmp_path>/...``, as README.md documents), on a config pointing at a
corrupted copy of one data table; a few run Snakemake on a copied tree. Each case asserts the exact
message content and that neither the output nor a temporary file of the atomic writer exists.
"""
import csv
import io
import os
import re
import runpy
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from conftest import ROOT, copy_repo, snakemake

SCRIPTS = ROOT / "workflow" / "scripts"
DATA = ROOT / "data"
TEST_CONFIG = ROOT / "config" / "test" / "config.yaml"


# ---------------------------------------------------------------- helpers
def read_rows(path) -> pd.DataFrame:
    return pd.read_csv(path, dtype=str, keep_default_na=False)


def write_rows(df: pd.DataFrame, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(path, index=False, quoting=csv.QUOTE_MINIMAL, lineterminator="\n")
    return path


def first_row(df, **match) -> int:
    """0-based index of the first row matching all column=value pairs."""
    m = pd.Series(True, index=df.index)
    for k, v in match.items():
        m &= df[k] == v
    assert m.any(), match
    return int(m.to_numpy().nonzero()[0][0])


def set_cell(src, dst, column, value, **match) -> int:
    """Copy CSV ``src`` to ``dst`` with one cell replaced; returns the 1-based data row changed."""
    df = read_rows(src)
    i = first_row(df, **match) if match else 0
    df.loc[i, column] = value
    write_rows(df, dst)
    return i + 1


def config_file(tmp_path, **sections) -> Path:
    """config/test/config.yaml with sections overridden (shallow per section)."""
    cfg = yaml.safe_load(TEST_CONFIG.read_text())
    for name, values in sections.items():
        if isinstance(values, dict):
            cfg.setdefault(name, {}).update(values)
        else:
            cfg[name] = values
    p = tmp_path / "config.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def run_rule(script, rule, configfile, outputs, monkeypatch) -> BaseException:
    """Run ``workflow/scripts/<script>.py <rule>`` by hand with --output; return the exception it raised.

    The job's inputs are the rule's, relative to the repository root; for the characteristic sets, the set
    "calibrated" would come from the calibration output of a local ``results/`` folder where one exists (a DAG
    edge), which must not shadow the table under test: the resolver is given no calibration output here."""
    monkeypatch.chdir(ROOT)                   # config paths are relative to the repository root
    from lumbar.inputs import characteristics as ch
    resolve = ch.resolve_characteristic_set
    monkeypatch.setattr(ch, "resolve_characteristic_set",
                        lambda name, data_dir=None, calibrated_dir=None, overrides=None:
                        resolve(name, data_dir=data_dir, calibrated_dir=None, overrides=overrides))
    monkeypatch.setattr(sys, "argv", [str(SCRIPTS / f"{script}.py"), rule, "--configfile", str(configfile),
                                      "--output", *map(str, outputs)])
    with pytest.raises(BaseException) as exc:
        runpy.run_path(str(SCRIPTS / f"{script}.py"), run_name="__main__")
    return exc.value


def assert_no_result(outputs):
    for o in outputs:
        assert not Path(o).exists(), f"partial result left: {o}"
        assert not [f for f in os.listdir(Path(o).parent) if f.endswith(".tmp")], "temporary file left"


def assert_message(exc, *parts):
    msg = str(exc)
    for part in parts:
        assert part in msg, f"{part!r} not in message:\n{msg}"


# ---------------------------------------------------------------- characteristic sets (rule fsu_rom)
CHAR_CASES = [
    # id, set, file, column, value, match, expected message parts
    ("bad_disc_value_not_a_number", "calibrated", "disc.csv", "value", "abc",
     dict(parameter="torque_p1", direction="flexion"), ["column 'value'", "got 'abc', which is not a number",
                                                        "expected a finite number"]),
    ("reject_disc_negative_stiffness", "calibrated", "disc.csv", "value", "-659748",
     dict(parameter="axial_linear"), ["column 'value'", "negative stiffness/damping", "a number >= 0"]),
    ("invalid_disc_kind", "calibrated", "disc.csv", "kind", "guessed",
     dict(parameter="torque_p1", direction="flexion"), ["column 'kind'", "got 'guessed'", "expected one of"]),
    ("bad_disc_empty_unit", "calibrated", "disc.csv", "unit", "",
     dict(parameter="torque_p1", direction="flexion"), ["column 'unit'", "empty cell"]),
    ("reject_facet_negative_stiffness", "calibrated", "facet.csv", "value", "-12000",
     dict(parameter="stiffness"), ["column 'value'", "negative stiffness/damping", "a positive number"]),
    ("invalid_ligament_name", "calibrated", "ligaments_softplus.csv", "ligament", "XYZ",
     dict(set="calibrated", ligament="ALL", parameter="a"), ["column 'ligament'", "got 'XYZ'", "'SSL'"]),
    ("malformed_softplus_value", "calibrated", "ligaments_softplus.csv", "value", "1,73.5",
     dict(set="calibrated", ligament="ALL", parameter="a"), ["column 'value'", "not a number"]),
    ("reject_prestrain_below_minus_100", "calibrated", "ligament_prestrain.csv", "prestrain", "-150",
     dict(ligament="ALL"), ["column 'prestrain'", "below the minimum", ">= -100"]),
    ("invalid_rupp_negative_force", "rupp2015", "ligaments_rupp2015.csv", "value", "-55",
     dict(ligament="ALL", parameter="f_a"), ["column 'value'", "-55.0 disagrees with value_as_printed '55'",
                                             "expected the decimal value of value_as_printed"]),
    ("invalid_rupp_parameter_name", "rupp2015", "ligaments_rupp2015.csv", "parameter", "f_c",
     dict(ligament="ALL", parameter="f_a"), ["column 'parameter'", "got 'f_c'", "'l_a'"]),
]


@pytest.mark.parametrize("set_name,fname,column,value,match,parts", [c[1:] for c in CHAR_CASES],
                         ids=[c[0] for c in CHAR_CASES])
def test_bad_characteristics_table_rejected_by_fsu_rom(tmp_path, monkeypatch, set_name, fname, column, value,
                                                        match, parts):
    data = tmp_path / "characteristics"
    shutil.copytree(DATA / "characteristics", data)
    row = set_cell(DATA / "characteristics" / fname, data / fname, column, value, **match)
    cfg = config_file(tmp_path, characteristics={"sets": [set_name], "data_dir": str(data)})
    out = [tmp_path / "out" / "fsu_rom_intact.csv"]
    (tmp_path / "out").mkdir()
    exc = run_rule("fsu", "fsu_rom", cfg, out, monkeypatch)
    assert_message(exc, f"{data / fname}, row {row}", *parts)
    assert_no_result(out)


def test_bad_characteristics_missing_column_rejected(tmp_path, monkeypatch):
    data = tmp_path / "characteristics"
    shutil.copytree(DATA / "characteristics", data)
    write_rows(read_rows(DATA / "characteristics" / "facet.csv").drop(columns=["unit"]), data / "facet.csv")
    cfg = config_file(tmp_path, characteristics={"sets": ["calibrated"], "data_dir": str(data)})
    out = [tmp_path / "fsu_rom_intact.csv"]
    exc = run_rule("fsu", "fsu_rom", cfg, out, monkeypatch)
    assert_message(exc, f"{data / 'facet.csv'}, column 'unit': missing column", "expected header containing")
    assert_no_result(out)


def test_bad_characteristics_empty_file_rejected(tmp_path, monkeypatch):
    data = tmp_path / "characteristics"
    shutil.copytree(DATA / "characteristics", data)
    (data / "disc.csv").write_text("")
    cfg = config_file(tmp_path, characteristics={"sets": ["calibrated"], "data_dir": str(data)})
    out = [tmp_path / "fsu_rom_intact.csv"]
    exc = run_rule("fsu", "fsu_rom", cfg, out, monkeypatch)
    assert_message(exc, f"{data / 'disc.csv'}: file is empty", "expected a header with columns")
    assert_no_result(out)


# ---------------------------------------------------------------- stepwise-reduction ROM tables (table4, calibrate)
DERIVED = DATA / "experiments" / "heuer2007_disc_only_derived_from_published_fit.csv"
TABLE4_OUT = ["table4_rom_synopsis.csv", "table4_outlier_counts.csv", "table4_vs_paper.csv", "table4_grid.png"]


def _measured(tmp_path, mutate) -> tuple[Path, int, str]:
    """A measured-ROM table in the documented schema (the derived rows plus ranges), mutated; returns
    (path, 1-based row, what)."""
    df = read_rows(DERIVED)
    df["rom_min_deg"] = (df["rom_mean_deg"].astype(float) - 1).round(4).astype(str)
    df["rom_max_deg"] = (df["rom_mean_deg"].astype(float) + 1).round(4).astype(str)
    df["kind"] = "measured"
    row = mutate(df)
    return write_rows(df, tmp_path / "measured.csv"), row


def _cell(column, value, i=2):
    def m(df):
        df.loc[i, column] = value
        return i + 1
    return m


def _dup(df):
    df.loc[3, ["stage", "direction", "moment_nm"]] = df.loc[1, ["stage", "direction", "moment_nm"]].to_numpy()
    return 4


EXPERIMENT_CASES = [
    ("invalid_stage_name", _cell("stage", "wo_xyz"), ["column 'stage'", "got 'wo_xyz'", "'intact'"]),
    ("reject_moment_above_50", _cell("moment_nm", "60"), ["column 'moment_nm'", "above the maximum",
                                                          "in [0, 50]", "pure moment [N*m]"]),
    ("bad_rom_range_only_min", _cell("rom_max_deg", ""), ["column 'rom_max_deg'",
                                                          "only one of rom_min_deg / rom_max_deg is given",
                                                          "both empty or both numbers"]),
    ("reject_mean_outside_range", _cell("rom_mean_deg", "99"), ["column 'rom_mean_deg'", "is not within",
                                                                "rom_min_deg <= rom_mean_deg <= rom_max_deg"]),
    ("reject_duplicate_scenario", _dup, ["column 'stage'", "duplicate scenario",
                                         "one row per (stage, direction, moment_nm)"]),
    ("invalid_zero_specimens", _cell("n_specimens", "0"), ["column 'n_specimens'", "below the minimum",
                                                           "an integer >= 1"]),
    ("malformed_rom_mean", _cell("rom_mean_deg", "4.9 deg"), ["column 'rom_mean_deg'", "not a number"]),
    ("invalid_direction", _cell("direction", "torsion"), ["column 'direction'", "got 'torsion'", "'flexion'"]),
]


@pytest.mark.parametrize("mutate,parts", [c[1:] for c in EXPERIMENT_CASES], ids=[c[0] for c in EXPERIMENT_CASES])
def test_bad_measured_rom_table_rejected_by_table4(tmp_path, monkeypatch, mutate, parts):
    path, row = _measured(tmp_path, mutate)
    cfg = config_file(tmp_path, stepwise_reduction={"measured_table": str(path)})
    out = [tmp_path / "out" / f for f in TABLE4_OUT]
    (tmp_path / "out").mkdir()
    exc = run_rule("table4", "table4", cfg, out, monkeypatch)
    assert_message(exc, f"{path}, row {row}", *parts)
    assert_no_result(out)


def test_bad_measured_rom_table_rejected_by_calibrate(tmp_path, monkeypatch):
    path, row = _measured(tmp_path, _cell("stage", "wo_xyz", i=5))
    cfg = config_file(tmp_path, stepwise_reduction={"measured_table": str(path)})
    out = tmp_path / "out"
    out.mkdir()
    outs = [out / f"o{i}.csv" for i in range(19)]          # rule calibrate's 19 outputs, in its order
    exc = run_rule("calibrate", "calibrate", cfg, outs, monkeypatch)
    assert_message(exc, f"{path}, row 6, column 'stage'", "got 'wo_xyz'", "expected one of")
    assert_no_result(outs)


def test_malformed_derived_disc_only_table_rejected_by_table4(tmp_path, monkeypatch):
    bad = tmp_path / "derived.csv"
    row = set_cell(DERIVED, bad, "rom_mean_deg", "NaN", direction="extension")
    measured, _ = _measured(tmp_path, lambda df: None)
    cfg = config_file(tmp_path, stepwise_reduction={"disc_only_derived": str(bad), "measured_table": str(measured)})
    out = [tmp_path / f for f in TABLE4_OUT]
    exc = run_rule("table4", "table4", cfg, out, monkeypatch)
    assert_message(exc, f"{bad}, row {row}, column 'rom_mean_deg'", "non-finite value 'NaN'")
    assert_no_result(out)


# ---------------------------------------------------------------- cable table (fig3_l2s1_cables, idp_surrogate)
CABLES = DATA / "cables" / "wilke1996_cables.csv"
CABLE_CASES = [
    ("invalid_cable_kind", "kind", "surrogate", ["column 'kind'", "got 'surrogate'", "'derived_from_geometry'"]),
    ("reject_negative_cable_tension", "tension_per_side", "-40", ["column 'tension_per_side'", "below the minimum",
                                                                  ">= 0"]),
    ("invalid_cable_muscle_setup", "muscle_setup", "biceps", ["column 'muscle_setup'", "got 'biceps'"]),
    ("invalid_cable_unit", "unit", "kN", ["column 'unit'", "got 'kN'", "one of 'N'"]),
    ("invalid_cable_vertebra", "vertebra", "T12", ["column 'vertebra'", "got 'T12'", "'L2'"]),
]


@pytest.mark.parametrize("column,value,parts", [c[1:] for c in CABLE_CASES], ids=[c[0] for c in CABLE_CASES])
def test_bad_cable_table_rejected_by_fig3(tmp_path, monkeypatch, column, value, parts):
    bad = tmp_path / "cables.csv"
    row = set_cell(CABLES, bad, column, value)
    cfg = config_file(tmp_path, l2s1={"cables": str(bad)})
    out = [tmp_path / "fig3_l2s1_cables.png"]
    exc = run_rule("fig3_l2s1_cables", "fig3_l2s1_cables", cfg, out, monkeypatch)
    assert_message(exc, f"{bad}, row {row}", *parts)
    assert_no_result(out)


def test_bad_cable_table_rejected_by_idp_surrogate(tmp_path, monkeypatch):
    bad = tmp_path / "cables.csv"
    row = set_cell(CABLES, bad, "tension_per_side", "forty")
    cfg = config_file(tmp_path, l2s1={"cables": str(bad)})
    out = [tmp_path / "idp_surrogate.csv"]
    exc = run_rule("idp_surrogate", "idp_surrogate", cfg, out, monkeypatch)
    assert_message(exc, f"{bad}, row {row}, column 'tension_per_side'", "got 'forty', which is not a number")
    assert_no_result(out)


# ---------------------------------------------------------------- measured IDP table (table5)
TABLE5_OUT = ["table5_idp_synopsis.csv", "table5_outlier_counts.csv", "table5_vs_paper.csv",
              "l2s1_internal_loads.csv", "table5_grid.png", "fig7_idp.png"]


def _idp_table():
    from lumbar.experiments import l2s1
    rows = [dict(muscle_setup=m, load_case=c, idp_mean_mpa="0.5", idp_sd_mpa="0.1", n_specimens="7",
                 kind="measured", source="test") for m, c in l2s1.scenario_grid()]
    return pd.DataFrame(rows)


IDP_CASES = [
    ("reject_negative_idp_sd", lambda df: (df.__setitem__("idp_sd_mpa", df["idp_sd_mpa"].where(df.index != 4, "-0.1")), 5)[1],
     ["row 5, column 'idp_sd_mpa'", "below the minimum", ">= 0", "MPa"]),
    ("invalid_idp_load_case", lambda df: (df.__setitem__("load_case", df["load_case"].where(df.index != 0, "jumping")), 1)[1],
     ["row 1, column 'load_case'", "got 'jumping'"]),
    ("bad_idp_duplicate_scenario", lambda df: (df.loc.__setitem__((1, ["muscle_setup", "load_case"]),
                                                                  df.loc[0, ["muscle_setup", "load_case"]].to_numpy()), 2)[1],
     ["row 2, column 'load_case'", "duplicate (muscle_setup, load_case)", "each scenario once"]),
]


@pytest.mark.parametrize("mutate,parts", [c[1:] for c in IDP_CASES], ids=[c[0] for c in IDP_CASES])
def test_bad_measured_idp_table_rejected_by_table5(tmp_path, monkeypatch, mutate, parts):
    df = _idp_table()
    mutate(df)
    path = write_rows(df, tmp_path / "idp.csv")
    cfg = config_file(tmp_path, l2s1={"measured_table": str(path)})
    out = [tmp_path / "out" / f for f in TABLE5_OUT]
    (tmp_path / "out").mkdir()
    exc = run_rule("table5", "table5", cfg, out, monkeypatch)
    assert_message(exc, str(path), *parts)
    assert_no_result(out)


def test_bad_idp_table_missing_scenarios_rejected(tmp_path, monkeypatch):
    path = write_rows(_idp_table().iloc[:-3], tmp_path / "idp.csv")
    cfg = config_file(tmp_path, l2s1={"measured_table": str(path)})
    out = [tmp_path / f for f in TABLE5_OUT]
    exc = run_rule("table5", "table5", cfg, out, monkeypatch)
    assert_message(exc, str(path), "missing")
    assert_no_result(out)


# ---------------------------------------------------------------- geometry (fsu_geometry)
def test_reject_missing_visible_human_directory_names_config_key(tmp_path, monkeypatch):
    cfg = config_file(tmp_path, geometry={"kind": "visible_human", "path": str(tmp_path / "nope")})
    out = [tmp_path / "fsu_geometry.csv"]
    exc = run_rule("fsu_geometry", "fsu_geometry", cfg, out, monkeypatch)
    assert_message(exc, str(tmp_path / "nope"), "directory missing", "geometry.path")
    assert_no_result(out)


# ---------------------------------------------------------------- through Snakemake on a copied tree
@pytest.fixture(scope="module")
def smk_tree(tmp_path_factory):
    pytest.importorskip("snakemake")
    return copy_repo(tmp_path_factory.mktemp("bad_smk") / "repo")


def test_reject_invalid_config_before_any_job_snakemake(smk_tree, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("fsu:\n  facet_stiffness_n_per_m: -1\n")
    r = snakemake("--cores", "1", "--configfile", str(bad), cwd=smk_tree, timeout=120)
    out = r.stdout + r.stderr
    assert r.returncode != 0
    assert "Error validating config file" in out and "-1 is less than or equal to the minimum of 0" in out
    assert "facet_stiffness_n_per_m" in out
    assert not (smk_tree / "results").exists() and not (smk_tree / "logs").exists()


def test_bad_characteristics_table_fails_job_without_result_snakemake(smk_tree, tmp_path):
    data = tmp_path / "characteristics"
    shutil.copytree(DATA / "characteristics", data)
    row = set_cell(DATA / "characteristics" / "disc.csv", data / "disc.csv", "value", "abc",
                   parameter="torque_p1", direction="flexion")
    target = "results/tables/fsu_rom_intact.csv"
    r = snakemake(target, "--cores", "1", "--configfile", "config/test/config.yaml", "--config",
                  # rupp2015 only: the calibrated set of fsu_rom comes from rule calibrate, which reads disc.csv first
                  f"characteristics={{sets: [rupp2015], data_dir: {data}}}", cwd=smk_tree, timeout=300)
    assert r.returncode != 0
    log = (smk_tree / "logs" / "fsu_rom.log").read_text()
    expected = f"{data / 'disc.csv'}, row {row}, column 'value': got 'abc', which is not a number"
    assert expected in log and "rule fsu_rom failed" in log
    assert "Error in rule fsu_rom" in r.stdout + r.stderr and expected in r.stdout + r.stderr
    assert not (smk_tree / target).exists()
    assert not list((smk_tree / "results").rglob("*.tmp"))


# ---------------------------------------------------------------- meshes (lumbar.geometry.checks, on load_geometry)
def _myo_l4():
    from lumbar.geometry import load_geometry
    g = load_geometry("default", levels=["L4-L5"])
    return g, g.vertebrae["L4"]


def test_reject_vertebra_mesh_scaled_down():
    from lumbar.geometry import GeometryError
    from lumbar.geometry.checks import check_vertebra
    _, v = _myo_l4()
    m = v.mesh.copy()
    m.apply_scale(1e-3)
    with pytest.raises(GeometryError) as e:
        check_vertebra("L4", m, v.centroid * 1e-3, "test.stl")
    assert_message(e.value, "L4 mesh (test.stl): largest extent", "is below 0.02 m", "expected a vertebra in metres")


def test_reject_vertebra_mesh_in_millimetres():
    from lumbar.geometry import GeometryError
    from lumbar.geometry.checks import check_vertebra
    _, v = _myo_l4()
    m = v.mesh.copy()
    m.apply_scale(1e3)
    with pytest.raises(GeometryError) as e:
        check_vertebra("L4", m, v.centroid * 1e3, "test.stl")
    assert_message(e.value, "L4 mesh (test.stl)", "looks like millimetres, expected metres")


def test_reject_open_vertebra_mesh_without_cross_section():
    """Half of the faces removed around the body centroid: no closed loop for the disc cross-section."""
    from lumbar.geometry import GeometryError
    from lumbar.geometry.checks import check_vertebra
    _, v = _myo_l4()
    m = v.mesh.copy()
    keep = m.triangles_center[:, 1] > v.centroid[1]         # the left half only
    m.update_faces(keep)
    with pytest.raises(GeometryError) as e:
        check_vertebra("L4", m, v.centroid, "half.stl")
    assert_message(e.value, "L4 mesh (half.stl): the horizontal cross-section", "closed enough for a cross-section")


def test_reject_vertebra_mesh_in_wrong_frame():
    """x pointing posterior (a 180 deg turn about z): the body is behind the posterior elements."""
    from lumbar.geometry import GeometryError
    from lumbar.geometry.checks import check_vertebra
    _, v = _myo_l4()
    m = v.mesh.copy()
    turn = np.diag([-1.0, -1.0, 1.0, 1.0])
    m.apply_transform(turn)
    with pytest.raises(GeometryError) as e:
        check_vertebra("L4", m, turn[:3, :3] @ v.centroid, "turned.stl")
    assert_message(e.value, "L4 mesh (turned.stl): the vertebral body", "is not anterior",
                   "expected the project frame (x anterior, y left, z superior)")


def test_reject_spine_not_stacked_along_z():
    from lumbar.geometry import GeometryError
    from lumbar.geometry.checks import check_spine
    g, _ = _myo_l4()
    g.vertebrae["L4"], g.vertebrae["L5"] = g.vertebrae["L5"], g.vertebrae["L4"]
    with pytest.raises(GeometryError) as e:
        check_spine(g)
    assert_message(e.value, "L4 is not above L5 along +z", "expected the project frame")


# ---------------------------------------------------------------- landmarks and the other data tables (lumbar.inputs.tables)
LANDMARK_CSV = DATA / "landmarks" / "myo_sim_landmarks.csv"


def test_reject_landmarks_in_millimetres(tmp_path):
    from lumbar.geometry import GeometryError, load_geometry
    bad = tmp_path / "lm.csv"
    df = read_rows(LANDMARK_CSV)
    i = first_row(df, level="L4-L5", structure="ALL")
    df.loc[i, "z_m"] = str(float(df.loc[i, "z_m"]) * 1000)
    write_rows(df, bad)
    with pytest.raises(GeometryError) as e:
        load_geometry("default", path=bad, levels=["L4-L5"])
    assert_message(e.value, f"{bad}, row {i + 1}, column 'z_m'", "above the maximum",
                   "metres, project frame: z superior")


def test_malformed_landmark_coordinate(tmp_path):
    from lumbar.geometry import GeometryError, load_geometry
    bad = tmp_path / "lm.csv"
    row = set_cell(LANDMARK_CSV, bad, "x_m", "0.01.2", level="L4-L5", structure="PLL")
    with pytest.raises(GeometryError) as e:
        load_geometry("default", path=bad, levels=["L4-L5"])
    assert_message(e.value, f"{bad}, row {row}, column 'x_m'", "not a number", "metres, project frame: x anterior")


def test_invalid_landmark_structure(tmp_path):
    from lumbar.geometry import GeometryError, load_geometry
    bad = tmp_path / "lm.csv"
    row = set_cell(LANDMARK_CSV, bad, "structure", "XYZ", level="L4-L5", structure="ISL")
    with pytest.raises(GeometryError) as e:
        load_geometry("default", path=bad, levels=["L4-L5"])
    assert_message(e.value, f"{bad}, row {row}, column 'structure'", "got 'XYZ'", "'facet_superior'")


TABLE_CASES = [
    # id, data file, kind, column, value, expected parts
    ("reject_muscle_sarcomere_length_out_of_range", "muscles/muscle_groups.csv", "muscle_groups", "in_situ_sl_um",
     "22.7", ["above the maximum", "in [1, 5]", "in-situ sarcomere length [um]"]),
    ("invalid_muscle_group", "muscles/muscle_groups.csv", "muscle_groups", "group", "Biceps",
     ["got 'Biceps'", "'MF'"]),
    ("reject_pennation_90_deg", "muscles/muscle_groups.csv", "muscle_groups", "pennation_deg", "90",
     ["above the maximum", "pennation angle [deg]"]),
    ("reject_negative_segment_mass_fraction", "anthropometry/upper_body_segments.csv", "anthropometry",
     "mass_fraction", "-0.07", ["below the minimum", "fraction of body mass [-]"]),
    ("invalid_segment_body", "anthropometry/upper_body_segments.csv", "anthropometry", "body", "T12",
     ["got 'T12'", "'L1'"]),
    ("reject_in_vivo_idp_in_kpa", "in_vivo/wilke_idp_l4l5.csv", "in_vivo_idp", "idp_mpa", "500",
     ["above the maximum", "intradiscal pressure [MPa]"]),
    ("invalid_in_vivo_provenance_kind", "in_vivo/wilke_idp_l4l5.csv", "in_vivo_idp", "kind", "guess",
     ["got 'guess'", "'original_text'"]),
]


@pytest.mark.parametrize("fname,kind,column,value,parts", [c[1:] for c in TABLE_CASES], ids=[c[0] for c in TABLE_CASES])
def test_bad_data_table_rejected_with_file_row_column(tmp_path, fname, kind, column, value, parts):
    from lumbar.inputs.io import TableError
    from lumbar.inputs.tables import read_kind
    bad = tmp_path / Path(fname).name
    row = set_cell(DATA / fname, bad, column, value)
    with pytest.raises(TableError) as e:
        read_kind(bad, kind)
    assert_message(e.value, f"{bad}, row {row}, column '{column}'", *parts)


@pytest.mark.parametrize("rel", sorted(str(p.relative_to(ROOT)) for p in DATA.rglob("*.csv")))
def test_data_tables_valid(rel):
    """Every registered data table passes its schema; an unregistered one is at least well-formed CSV."""
    from lumbar.inputs.tables import DATA_FILES, read_kind
    if rel in DATA_FILES:
        read_kind(ROOT / rel, DATA_FILES[rel])
        return
    rows = list(csv.reader(io.StringIO((ROOT / rel).read_text(encoding="utf-8"))))
    widths = {len(r) for r in rows if r}
    assert len(widths) == 1, f"{rel}: rows with different numbers of fields {sorted(widths)}"


def test_reject_ligament_insertion_off_its_vertebra():
    """A fibre end 3 cm anterior of the bone (e.g. a typo in an insertion file) is caught on loading."""
    from lumbar.geometry import GeometryError
    from lumbar.geometry.checks import check_insertions
    g, _ = _myo_l4()
    import dataclasses
    lev = g.levels["L4-L5"]
    i = next(k for k, lig in enumerate(lev.ligaments) if lig.name == "SSL")
    upper = np.array(lev.ligaments[i].upper, copy=True)
    upper[0] += [0.0, 0.0, 0.03]
    lev.ligaments[i] = dataclasses.replace(lev.ligaments[i], upper=upper)
    with pytest.raises(GeometryError) as e:
        check_insertions(g)
    assert_message(e.value, "L4-L5 ligament SSL: point 0 (upper end, on L4)", "mm from the L4 mesh surface",
                   "expected within 10 mm")


# ---------------------------------------------------------------- stale results and interrupts
def _smk_ok(tree, *args, timeout=300) -> str:
    r = snakemake("--configfile", "config/test/config.yaml", *args, cwd=tree, timeout=timeout)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r.stdout


def _pending(tree) -> dict:
    """{output file: rule} of every output Snakemake would (re)build, judged by modification time and content
    (``--summary --rerun-triggers mtime``: params or code changes do not count)."""
    rows = [line.split("\t") for line in _smk_ok(tree, "--summary", "--rerun-triggers", "mtime").splitlines()[1:]]
    return {r[0]: r[2] for r in rows if len(r) > 5 and r[5] != "no update"}


def _forced(tree, *rules) -> set:
    """Rules of the jobs that ``--forcerun rules`` would run: the rules and everything downstream of them."""
    out = _smk_ok(tree, "-n", "--forcerun", *rules)
    stats = out.split("Job stats:", 1)[1].split("total", 1)[0]
    return {m.group(1) for m in re.finditer(r"^(\w+)\s+\d+\s*$", stats, re.M)} - {"all", "job"}


@pytest.fixture(scope="module")
def touched_tree(tmp_path_factory):
    """A copy of the repository in which every output of the test config's DAG exists and is up to date
    (empty files, then ``snakemake --touch``): the dry-run state after a complete run, in seconds."""
    pytest.importorskip("snakemake")
    tree = copy_repo(tmp_path_factory.mktemp("stale") / "repo")
    for line in _smk_ok(tree, "--summary").splitlines()[1:]:
        p = tree / line.split("\t")[0]
        if p.suffix:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.touch()
        else:                                   # directory() outputs (the benchmark fixtures)
            p.mkdir(parents=True, exist_ok=True)
    _smk_ok(tree, "--touch", "--cores", "1")
    assert _pending(tree) == {}
    return tree


def _edit_in_place(path: Path, old: str, new: str):
    """Rewrite one value of a data file in place (the folder's mtime does not change), mtime in the future."""
    text = path.read_text()
    assert old in text, (path, old)
    path.write_text(text.replace(old, new, 1))
    t = path.stat().st_mtime + 5
    os.utime(path, (t, t))


@pytest.mark.workflow
def test_in_place_edit_of_characteristics_table_reruns_exactly_its_readers(touched_tree):
    """Regression: rewriting ligament_prestrain.csv in place re-ran only paper_report (the rules took the folder
    as input) and fsu_rom_intact.csv kept the old ROM. Now every reader of the file, and only they, re-run."""
    f = touched_tree / "data" / "characteristics" / "ligament_prestrain.csv"
    before = f.read_text()
    try:
        _edit_in_place(f, "\nSSL,-6,", "\nSSL,-5,")
        pending = _pending(touched_tree)
    finally:
        f.write_text(before)            # the recorded checksum matches again: the tree is up to date
    # the softplus sets (calibrated) read the prestrains: the intact ROM, the surrogates, the calibration and
    # everything downstream of them
    for out in ("results/tables/fsu_rom_intact.csv", "results/experiments/stepwise_reduction_surrogate.csv",
                "results/experiments/idp_wilke1996_surrogate.csv", "results/tables/table1_disc_calibrated.csv",
                "results/stepwise_reduction/rom_calibrated.csv", "results/l2s1/idp_calibrated.csv",
                "results/tables/muscle_model_segment_loads.csv", "results/report/paper.html"):
        assert out in pending, f"{out} not re-run after an in-place edit of {f.name}"
    # rupp2015 has its own prestrains (ligaments_rupp2015.csv), the geometry rules read no characteristics
    not_readers = {"results/tables/fsu_geometry.csv", "results/figures/fig1_l4l5_model.png",
                   "results/figures/fig3_l2s1_cables.png", "results/stepwise_reduction/rom_rupp2015.csv",
                   "results/l2s1/idp_rupp2015.csv"}
    assert not not_readers & set(pending), sorted(not_readers & set(pending))


@pytest.mark.workflow
def test_in_place_edit_of_experiment_table_reruns_only_its_readers(touched_tree):
    """The vertebral-arch artefact table is read by discovery_va_artefact only (and the report, which lists
    every data table): exactly these re-run."""
    f = touched_tree / "data" / "experiments" / "heuer2007_va_artefact_original_text.csv"
    before = f.read_text()
    lines = before.splitlines(keepends=True)
    try:
        f.write_text("".join(lines[:1] + [lines[1].replace(",", ", ", 1)] + lines[2:]))   # same data, new bytes
        os.utime(f, (f.stat().st_mtime + 5,) * 2)
        pending = _pending(touched_tree)
    finally:
        f.write_text(before)            # the recorded checksum matches again: the tree is up to date
    assert set(pending.values()) == _forced(touched_tree, "discovery_va_artefact", "paper_report"), pending


@pytest.mark.workflow
def test_published_model_results_is_an_input_when_present(touched_tree, tmp_path):
    """Regression: adding ../shared after a run changed nothing (paths.published_model_results was a parameter).
    Now the file is an input of the rules that fill the paper columns, and the workflow runs without it."""
    pub = tmp_path / "published_model_results.csv"
    cfg = tmp_path / "config.yaml"
    test_cfg = yaml.safe_load((touched_tree / "config" / "test" / "config.yaml").read_text())
    cfg.write_text(yaml.safe_dump({**test_cfg, "paths": {"published_model_results": str(pub)}}))
    r = snakemake("-n", "--forceall", "--configfile", str(cfg), cwd=touched_tree, timeout=300)
    assert r.returncode == 0 and str(pub) not in r.stdout, r.stdout[-2000:] + r.stderr[-2000:]
    pub.write_text("x\n")
    r = snakemake("-n", "--forceall", "--configfile", str(cfg), cwd=touched_tree, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    readers = {m.group(1) for m in re.finditer(r"^rule (\w+):\n    input: [^\n]*" + re.escape(str(pub)),
                                                 r.stdout, re.M)}
    assert {"table4", "table5", "paper_report"} <= readers, readers


def _readme_resume_commands() -> list[list[str]]:
    """The README's resume command after an interrupt (``snakemake --unlock && snakemake ...``), split."""
    text = (ROOT / "README.md").read_text()
    m = re.search(r"\*\*After an interrupt\*\*.*?`(snakemake --unlock[^`]*)`", text, re.S)
    assert m, "README.md has no 'After an interrupt' paragraph with the resume command"
    return [c.split() for c in m.group(1).split("&&")]


@pytest.mark.workflow
@pytest.mark.parametrize("sig", ["SIGKILL", "SIGINT"])
def test_readme_resume_command_after_interrupt(tmp_path, sig):
    """Regression: after SIGINT/SIGKILL the README's plain re-run failed (IncompleteFilesException, then
    LockException). Interrupt a one-job run while its job runs, then resume with the README's command."""
    import signal
    import subprocess
    import time
    pytest.importorskip("snakemake")
    tree = copy_repo(tmp_path / "repo")
    target = ["results/tables/fsu_geometry.csv", "--configfile", "config/test/config.yaml"]
    proc = subprocess.Popen([sys.executable, "-m", "snakemake", "--cores", "1", *target], cwd=tree,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        t0 = time.time()           # wait until the job runs: its incomplete marker exists
        while not any((tree / ".snakemake" / "incomplete").glob("*")) and proc.poll() is None:
            assert time.time() - t0 < 60, "the job did not start"
            time.sleep(0.05)
        assert proc.poll() is None, "the job finished before it could be interrupted"
        # Ctrl-C in a terminal signals the whole process group; SIGKILL: Snakemake and its job, no clean-up
        os.killpg(proc.pid, getattr(signal, sig))
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    out = tree / target[0]
    if out.exists() and any((tree / ".snakemake" / "incomplete").glob("*")):
        # the signal came between the job's atomic write (temporary file + rename) and Snakemake's bookkeeping:
        # the file is whole, never cut off, and the README's resume re-runs the job anyway (rerun-incomplete)
        import pandas as pd
        assert len(pd.read_csv(out)) > 0, "a cut-off result was kept"
    for cmd in _readme_resume_commands():
        assert cmd[0] == "snakemake", cmd
        extra = [] if "--unlock" in cmd else target
        r = subprocess.run([sys.executable, "-m", *cmd, *extra], cwd=tree, capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, f"{' '.join(cmd)} failed:\n{r.stdout[-3000:]}{r.stderr[-3000:]}"
    assert (tree / target[0]).stat().st_size > 0


# ---------------------------------------------------------------- silent wrong numbers -> loud errors
VH = DATA / "geometry" / "visible_human_lss"


def _vh_copy(tmp_path) -> Path:
    if not VH.is_dir():
        pytest.skip("data/geometry/visible_human_lss not present")
    d = tmp_path / "vh"
    shutil.copytree(VH, d)
    return d


def _replace_line(path: Path, i: int, fn):
    lines = path.read_text().splitlines(keepends=True)
    lines[i] = fn(lines[i])
    path.write_text("".join(lines))


@pytest.mark.parametrize("rel, old, new, parts", [
    # was: numpy 'SVD did not converge' with no file
    ("disc_fe/L45_NP.node", "0.00140958", "nan",
     ["line 3: non-finite coordinate", "expected finite 'index x y z' numbers (metres)"]),
    # was: "'x' must be finite" with no file name
    ("ligaments/L45_Ligs_AS.lig", "-0.023729", "NaN",
     ["line 3 (L45_CL_R fibre 1): non-finite coordinate", "expected finite x, y, z"]),
], ids=["disc_node", "lig_fibre"])
def test_reject_nan_coordinate_names_file_and_line(tmp_path, rel, old, new, parts):
    from lumbar.geometry import GeometryError, load_geometry
    d = _vh_copy(tmp_path)
    f = d / rel
    _replace_line(f, 2, lambda s: s.replace(old, new))
    with pytest.raises(GeometryError) as e:
        load_geometry("visible_human", path=d, levels=["L4-L5"])
    assert_message(e.value, f"{f}: {parts[0]}", *parts[1:])


def test_reject_disc_nodes_in_millimetres_blames_the_node_file(tmp_path):
    """Was: blamed on L45_Ligs_MP.lig."""
    from lumbar.geometry import GeometryError, load_geometry
    d = _vh_copy(tmp_path)
    f = d / "disc_fe" / "L45_NP.node"
    rows = [line.split() for line in f.read_text().splitlines() if line.strip()]
    f.write_text("".join(f"{r[0]} {float(r[1]) * 1e3:.6f} {float(r[2]) * 1e3:.6f} {float(r[3]) * 1e3:.6f}\n"
                         for r in rows))
    with pytest.raises(GeometryError) as e:
        load_geometry("visible_human", path=d, levels=["L4-L5"])
    assert_message(e.value, str(f), "(millimetres?)", "expected 'index x y z' in metres")
    assert "Ligs" not in str(e.value)


DUP_CASES = [
    # id, set, file, row to duplicate (match), changed column/value of the copy, expected parts
    ("reject_duplicate_prestrain_row", "calibrated", "ligament_prestrain.csv", dict(ligament="SSL"),
     ("prestrain", "50"), ["column 'ligament'", "duplicate row for ligament 'SSL'", "expected one row per ligament"]),
    ("reject_duplicate_facet_row", "calibrated", "facet.csv", dict(parameter="stiffness"), ("value", "24000"),
     ["column 'parameter'", "duplicate row for parameter 'stiffness'", "expected each parameter once"]),
    ("reject_duplicate_rupp_row", "rupp2015", "ligaments_rupp2015.csv", dict(ligament="SSL", parameter="prestrain"),
     ("kind", "original_text"), ["column 'parameter'", "duplicate row for ligament 'SSL' parameter 'prestrain'",
                                 "expected each parameter once per ligament"]),
    ("reject_duplicate_softplus_row", "chazal1985", "ligaments_softplus.csv",
     dict(set="calibrated", ligament="ALL", variant="primary", parameter="a"), ("kind", "original_text"),
     ["column 'parameter'", "duplicate row for (set, ligament, variant, parameter) ('calibrated', 'ALL', 'primary', 'a')"]),
]


@pytest.mark.parametrize("set_name,fname,match,change,parts", [c[1:] for c in DUP_CASES], ids=[c[0] for c in DUP_CASES])
def test_duplicate_characteristic_rows_are_errors(tmp_path, set_name, fname, match, change, parts):
    """Was: last row wins (a duplicated SSL row turned -6 % prestrain into 50 %)."""
    from lumbar.inputs.characteristics import CharacteristicsError, load_characteristic_set
    data = tmp_path / "characteristics"
    shutil.copytree(DATA / "characteristics", data)
    df = read_rows(DATA / "characteristics" / fname)
    i = first_row(df, **match)
    dup = df.iloc[[i]].copy()
    dup[change[0]] = change[1]
    df = pd.concat([df, dup], ignore_index=True)
    write_rows(df, data / fname)
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set(set_name, data_dir=data)
    assert_message(e.value, f"{data / fname}, row {len(df)}", *parts)


BOUND_CASES = [
    ("reject_prestrain_1e6_pct", "calibrated", "ligament_prestrain.csv", "prestrain", "1e6", dict(ligament="SSL"),
     ["column 'prestrain'", "1000000.0 % for the prestrain of SSL is outside its physical range",
      "expected a value in [-50, 50] %"]),
    ("reject_rupp_prestrain_80_pct", "rupp2015", "ligaments_rupp2015.csv", "value", "80",
     dict(ligament="FL", parameter="prestrain"), None),
    ("reject_facet_stiffness_in_wrong_unit", "calibrated", "facet.csv", "value", "12e9", dict(parameter="stiffness"),
     ["column 'value'", "for parameter 'stiffness' is outside its physical range", "expected a value in [0, 1e+07] N/m"]),
]


@pytest.mark.parametrize("set_name,fname,column,value,match,parts", [c[1:] for c in BOUND_CASES],
                         ids=[c[0] for c in BOUND_CASES])
def test_characteristic_outside_physical_bounds_rejected(tmp_path, set_name, fname, column, value, match, parts):
    from lumbar.inputs.characteristics import CharacteristicsError, load_characteristic_set
    data = tmp_path / "characteristics"
    shutil.copytree(DATA / "characteristics", data)
    if fname == "ligaments_rupp2015.csv":       # keep value_as_printed consistent with the new value
        df = read_rows(DATA / "characteristics" / fname)
        i = first_row(df, **match)
        df.loc[i, ["value", "value_as_printed"]] = [value, value]
        write_rows(df, data / fname)
        row = i + 1
        parts = ["column 'value'", "80.0 % for parameter 'prestrain' of FL is outside its physical range",
                 "expected a value in [-50, 50] %"]
    else:
        row = set_cell(DATA / "characteristics" / fname, data / fname, column, value, **match)
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set(set_name, data_dir=data)
    assert_message(e.value, f"{data / fname}, row {row}", *parts)


def test_duplicate_yaml_key_in_config_rejected_by_library(tmp_path):
    """Was: a second `fsu:` section silently replaced the first."""
    from lumbar.inputs.config import ConfigError, load_config
    f = tmp_path / "c.yaml"
    f.write_text("fsu:\n  moments_nm: [1]\nsolver:\n  max_iter: 3\nfsu:\n  level: L4-L5\n")
    with pytest.raises(ConfigError) as e:
        load_config(f)
    assert_message(e.value, str(f), "duplicate key 'fsu' (first at line 1)", "line 5")


def test_duplicate_yaml_key_in_config_rejected_by_snakemake(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("solver:\n  max_iter: 3\n  max_iter: 30\n")
    r = snakemake("-n", "--configfile", str(f), cwd=ROOT, timeout=120)
    assert r.returncode != 0
    assert f"Error in config file {f}, line 3: duplicate key 'max_iter' (first at line 2)" in r.stdout + r.stderr


@pytest.mark.parametrize("section,values,parts", [
    ("solver", {"tol_force_n": 1.0e6, "tol_moment_nm": 1.0e6},
     ["solver.tol_force_n: 1000000.0 is out of range; expected a value <= 0.001",
      "solver.tol_moment_nm: 1000000.0 is out of range; expected a value <= 0.0001"]),
    ("fsu", {"moments_nm": [10, 20, 50]},
     ["fsu.moments_nm[1]: 20 is out of range; expected a value <= 10", "set fsu.beyond_experiment true"]),
    ("stepwise_reduction", {"moments_nm": [1, 5, 12]}, ["stepwise_reduction.moments_nm[2]: 12 is out of range"]),
    ("l2s1", {"moment_nm": 7.5}, ["l2s1.moment_nm: 7.5 is out of range; expected a value <= 3.75",
                                  "set l2s1.beyond_experiment true"]),
], ids=["tolerances_1e6", "fsu_moment_50", "stepwise_moment_12", "l2s1_moment_7_5"])
def test_config_bounds_tolerances_and_moments(section, values, parts):
    from lumbar.inputs.config import ConfigError, load_config
    with pytest.raises(ConfigError) as e:
        load_config({section: values})
    assert_message(e.value, *parts)


def test_moments_beyond_experiment_need_explicit_opt_in():
    from lumbar.inputs.config import load_config
    assert load_config({"fsu": {"moments_nm": [20], "beyond_experiment": True}})["fsu"]["moments_nm"] == [20]


def test_loose_tolerance_never_reports_unloaded_state_converged(caplog):
    """Was: tolerances 1e6 -> every ROM 0 deg, converged=True, residual moments up to 20 N*m in the table."""
    from lumbar.mechanics import solve as S
    from lumbar.inputs.characteristics import load_characteristic_set
    from lumbar.experiments.fsu import build_fsu, range_of_motion
    from lumbar.geometry import load_geometry
    fsu = build_fsu(load_geometry("default", levels=["L4-L5"]), load_characteristic_set("calibrated"))
    df = range_of_motion(fsu, [10.0], ["flexion"], tol=1.0e6)
    assert "looser than the physical limit" in caplog.text
    # the tolerance is clamped to the physical limit, so the state is solved (not given up): every row converged,
    # at the physical residual, and its ROM is the equilibrium the default tolerance finds
    assert df["converged"].all(), df
    assert (df["residual_force_n"] <= S.PHYSICAL_TOL_FORCE_N).all()
    assert (df["residual_moment_nm"] <= S.PHYSICAL_TOL_MOMENT_NM).all()
    tight = range_of_motion(fsu, [10.0], ["flexion"])
    np.testing.assert_allclose(df["rom_deg"], tight["rom_deg"], atol=1e-3)
    assert (df["rom_deg"] > 1.0).all()                   # a real equilibrium, not the unloaded start
    # control: where nothing converges (one Newton step), the flag is raised and no ROM is reported for it
    caplog.clear()
    bad = range_of_motion(fsu, [10.0], ["flexion"], tol=1.0e6, max_iter=1)
    assert not bad["converged"].any() and bad["rom_deg"].isna().all() and not bad["valid"].any(), bad
    assert "did not converge; their rom_deg is NaN" in caplog.text


def test_fsu_cli_flags_states_outside_force_law_validity(capsys):
    """Was: 122.9 deg at 50 N*m, the upper vertebra 30.8 mm lower, converged=True, rc 0."""
    from lumbar.experiments.fsu import main
    rc = main(["--moment", "10", "20", "50", "--direction", "lateral_bending"])
    out, err = capsys.readouterr()
    assert rc == 1
    head = out.splitlines()[1].split()
    assert "valid" in head
    rows = [line.split() for line in out.splitlines()[2:]]
    valid = [r[head.index("valid")] for r in rows]
    assert valid[0] == "True" and valid[-1] == "False", out      # 10 N*m: the experiments' range; 50: far beyond
    assert "N*m) lie OUTSIDE the validity of the force laws" in err and "50 N*m" in err


def test_fsu_cli_visible_human_defaults_to_config_geometry_path(capsys, monkeypatch, tmp_path):
    """Was: a message about a library argument (path=)."""
    from lumbar.inputs.config import default_geometry_path
    from lumbar.experiments.fsu import main
    monkeypatch.chdir(tmp_path)                 # the config path resolves from the repository too
    if not default_geometry_path().is_dir():
        pytest.skip("the configuration's geometry.path is not present")
    rc = main(["--geometry", "visible_human", "--moment", "2.5", "--direction", "flexion"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "# geometry=visible_human" in out


def test_fsu_cli_level_has_help(capsys):
    from lumbar.experiments.fsu import main
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "motion segment to load" in capsys.readouterr().out


def test_output_path_that_is_a_file_or_folder_is_a_clear_error(tmp_path):
    from lumbar.inputs.io import OutputError, write_table_atomic
    blocker = tmp_path / "out"
    blocker.write_text("")
    with pytest.raises(OutputError) as e:
        write_table_atomic(pd.DataFrame({"a": [1]}), blocker / "t.csv")
    assert_message(e.value, f"cannot write {blocker / 't.csv'}: {blocker} is a file, not a folder")
    with pytest.raises(OutputError) as e:
        write_table_atomic(pd.DataFrame({"a": [1]}), tmp_path)
    assert_message(e.value, f"cannot write {tmp_path}: it is a folder; expected a file path")


def test_read_only_output_folder_is_a_clear_error(tmp_path):
    """A folder that refuses new files. Root ignores permission bits (CI runs as root), so the case that runs for
    everyone is a folder of the kernel's sysfs (/sys), where no process, root included, can create a regular file
    (EACCES); a user also gets a folder of mode 555."""
    from lumbar.inputs.io import OutputError, write_table_atomic
    folders = []
    if not (hasattr(os, "geteuid") and os.geteuid() == 0):
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        folders.append(ro)
    sysfs = Path("/sys")
    if os.path.ismount(sysfs):
        folders.append(sysfs)
    assert folders, "no folder that refuses new files for this user (not root, or a /sys mount expected on Linux)"
    try:
        for ro in folders:
            with pytest.raises(OutputError) as e:
                write_table_atomic(pd.DataFrame({"a": [1]}), ro / "t.csv")
            assert_message(e.value, f"cannot write {ro / 't.csv'}: the folder {ro} is read-only")
            assert not (ro / "t.csv").exists()
    finally:
        if folders and folders[0] != sysfs:
            folders[0].chmod(0o755)


def test_measured_rom_table_sharing_no_scenario_with_config_is_an_error(tmp_path, monkeypatch):
    """Was: accepted, Table 4 with no assessed scenario."""
    path, _ = _measured(tmp_path, lambda df: None)        # moments 1 .. 10 N*m
    config_file(tmp_path, stepwise_reduction={"measured_table": str(path), "moments_nm": [3, 4, 6]})
    sims = tmp_path / "sims"
    sims.mkdir()
    from lumbar.experiments import stepwise_reduction as sr
    sim = sr.scenario_grid(moments_nm=(3.0, 4.0, 6.0)).assign(rom_deg=1.0, converged=True, set="calibrated")
    with pytest.raises(ValueError) as e:
        sr.assess(sim, sr.read_experiment_table(path), "calibrated")
    assert_message(e.value, "shares no scenario (stage, direction, moment_nm)", "simulated moments [3.0, 4.0, 6.0]",
                   "Set stepwise_reduction.moments_nm")
