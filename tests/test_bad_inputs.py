"""Bad inputs are rejected with a message naming the file, row, column (or config key) and the expected form,
and the rule that read them leaves no result behind.

Most cases run the rule's workflow script by hand, in this process (``python workflow/scripts/<stage>.py
<rule> --configfile ... --output <tmp_path>/...``, as README.md documents), on a config pointing at a
corrupted copy of one data table; a few run Snakemake on a copied tree. Each case asserts the exact
message content and that neither the output nor a temporary file of the atomic writer exists.
"""
import csv
import io
import os
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
    """Run ``workflow/scripts/<script>.py <rule>`` by hand with --output; return the exception it raised."""
    monkeypatch.chdir(ROOT)                   # config paths are relative to the repository root
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
    exc = run_rule("stepwise_reduction", "table4", cfg, out, monkeypatch)
    assert_message(exc, f"{path}, row {row}", *parts)
    assert_no_result(out)


def test_bad_measured_rom_table_rejected_by_calibrate(tmp_path, monkeypatch):
    path, row = _measured(tmp_path, _cell("stage", "wo_xyz", i=5))
    cfg = config_file(tmp_path, stepwise_reduction={"measured_table": str(path)})
    out = tmp_path / "out"
    out.mkdir()
    outs = [out / f"o{i}.csv" for i in range(15)]
    exc = run_rule("calibration", "calibrate", cfg, outs, monkeypatch)
    assert_message(exc, f"{path}, row 6, column 'stage'", "got 'wo_xyz'", "expected one of")
    assert_no_result(outs)


def test_malformed_derived_disc_only_table_rejected_by_table4(tmp_path, monkeypatch):
    bad = tmp_path / "derived.csv"
    row = set_cell(DERIVED, bad, "rom_mean_deg", "NaN", direction="extension")
    measured, _ = _measured(tmp_path, lambda df: None)
    cfg = config_file(tmp_path, stepwise_reduction={"disc_only_derived": str(bad), "measured_table": str(measured)})
    out = [tmp_path / f for f in TABLE4_OUT]
    exc = run_rule("stepwise_reduction", "table4", cfg, out, monkeypatch)
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
    exc = run_rule("l2s1", "fig3_l2s1_cables", cfg, out, monkeypatch)
    assert_message(exc, f"{bad}, row {row}", *parts)
    assert_no_result(out)


def test_bad_cable_table_rejected_by_idp_surrogate(tmp_path, monkeypatch):
    bad = tmp_path / "cables.csv"
    row = set_cell(CABLES, bad, "tension_per_side", "forty")
    cfg = config_file(tmp_path, l2s1={"cables": str(bad)})
    out = [tmp_path / "idp_surrogate.csv"]
    exc = run_rule("l2s1", "idp_surrogate", cfg, out, monkeypatch)
    assert_message(exc, f"{bad}, row {row}, column 'tension_per_side'", "got 'forty', which is not a number")
    assert_no_result(out)


# ---------------------------------------------------------------- measured IDP table (table5)
TABLE5_OUT = ["table5_idp_synopsis.csv", "table5_outlier_counts.csv", "table5_vs_paper.csv",
              "l2s1_internal_loads.csv", "table5_grid.png", "fig7_idp.png"]


def _idp_table():
    from lumbar import l2s1
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
    exc = run_rule("l2s1", "table5", cfg, out, monkeypatch)
    assert_message(exc, str(path), *parts)
    assert_no_result(out)


def test_bad_idp_table_missing_scenarios_rejected(tmp_path, monkeypatch):
    path = write_rows(_idp_table().iloc[:-3], tmp_path / "idp.csv")
    cfg = config_file(tmp_path, l2s1={"measured_table": str(path)})
    out = [tmp_path / f for f in TABLE5_OUT]
    exc = run_rule("l2s1", "table5", cfg, out, monkeypatch)
    assert_message(exc, str(path), "missing")
    assert_no_result(out)


# ---------------------------------------------------------------- geometry (fsu_geometry)
def test_reject_missing_visible_human_directory_names_config_key(tmp_path, monkeypatch):
    cfg = config_file(tmp_path, geometry={"kind": "visible_human", "path": str(tmp_path / "nope")})
    out = [tmp_path / "fsu_geometry.csv"]
    exc = run_rule("geometry", "fsu_geometry", cfg, out, monkeypatch)
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
                  f"characteristics={{data_dir: {data}}}", cwd=smk_tree, timeout=300)
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


# ---------------------------------------------------------------- landmarks and the other data tables (lumbar.tables)
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
    from lumbar.io import TableError
    from lumbar.tables import read_kind
    bad = tmp_path / Path(fname).name
    row = set_cell(DATA / fname, bad, column, value)
    with pytest.raises(TableError) as e:
        read_kind(bad, kind)
    assert_message(e.value, f"{bad}, row {row}, column '{column}'", *parts)


@pytest.mark.parametrize("rel", sorted(str(p.relative_to(ROOT)) for p in DATA.rglob("*.csv")))
def test_data_tables_valid(rel):
    """Every registered data table passes its schema; an unregistered one is at least well-formed CSV."""
    from lumbar.tables import DATA_FILES, read_kind
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
    i = next(k for k, l in enumerate(lev.ligaments) if l.name == "SSL")
    upper = np.array(lev.ligaments[i].upper, copy=True)
    upper[0] += [0.0, 0.0, 0.03]
    lev.ligaments[i] = dataclasses.replace(lev.ligaments[i], upper=upper)
    with pytest.raises(GeometryError) as e:
        check_insertions(g)
    assert_message(e.value, "L4-L5 ligament SSL: point 0 (upper end, on L4)", "mm from the L4 mesh surface",
                   "expected within 10 mm")
