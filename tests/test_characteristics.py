"""Tests for lumbar.inputs.characteristics: paper values, physics checks, bad input."""
import shutil

import numpy as np
import pandas as pd
import pytest

from lumbar.inputs.characteristics import (CHARACTERISTIC_SETS, CharacteristicsError, RuppLaw, SoftplusLaw,
                                    load_characteristic_set, load_shape_check, rupp_shape_parameters,
                                    default_data_dir)

DATA = default_data_dir()


def softplus(law, eps_pct):
    """Eq. 7 with numpy, independent of the library: a*ln(exp((eps+b)/d)+1)+c."""
    return law.a * np.logaddexp(0.0, (np.asarray(eps_pct, float) + law.b) / law.d) + law.c


# ---------------------------------------------------------------- paper values
def test_table1_values_load_exactly():
    d = load_characteristic_set("calibrated").disc
    assert d.torque == {"flexion": (10.67, 0.005913, -1.685), "extension": (5.196, 0.008417, 24.50),
                        "lateral_bending": (6.929, 0.001482, 19.76), "axial_rotation": (4.399, 0.001141, 42.38)}
    assert d.k_axial_quadratic == 690234060.0 and d.k_axial_linear == 659748.0
    assert d.damping_translational == 400000.0 and d.damping_rotational == 100.0
    assert d.k_tension == 0.0


def test_all_sets_share_disc_and_facet():
    sets = [load_characteristic_set(n) for n in CHARACTERISTIC_SETS]
    for cs in sets[1:]:
        assert cs.disc == sets[0].disc and cs.facet == sets[0].facet
    assert sets[0].facet.stiffness == 12000.0 and sets[0].facet.damping == 4000.0
    assert sets[0].facet.surface_paper["left"]["p00"] == 47.31


def test_shear_stiffness_defaults_to_midpoint_of_sourced_range_in_si():
    d = load_characteristic_set("calibrated").disc
    assert d.k_shear == pytest.approx(96500.0)  # project decision: midpoint of 53..140 N/mm
    assert d.k_shear_range == (53000.0, 140000.0)  # 53..140 N/mm converted to N/m
    d2 = load_characteristic_set("calibrated", overrides={"disc.k_shear": 1.0e5}).disc
    assert d2.k_shear == 1.0e5


@pytest.mark.parametrize("kind,eps,force", [
    ("ALL", 0, 0.01), ("ALL", 8, 64.6), ("PLL", 10, 2.3), ("CL", 10, 7.8), ("ISL", 4, 9.3),
    ("FL", 0, 79.5), ("FL", 10, 66.6), ("FL", 15, 62.7)])
def test_calibrated_softplus_matches_notes(kind, eps, force):
    law = load_characteristic_set("calibrated").ligaments[kind]
    assert isinstance(law, SoftplusLaw)
    assert softplus(law, eps) == pytest.approx(force, abs=0.1)


def test_calibrated_ssl_slack_until_about_20_percent():
    ssl = load_characteristic_set("calibrated").ligaments["SSL"]
    assert np.all(softplus(ssl, np.linspace(-20, 19, 200)) < 0.1)
    assert 0.5 < softplus(ssl, 23) < 1.5  # knee at b = -22.97 %
    assert softplus(ssl, 30) > 5


def test_calibrated_prestrains_and_absent_itl():
    cs = load_characteristic_set("calibrated")
    assert {k: lig.prestrain_pct for k, lig in cs.ligaments.items()} == {
        "ALL": 8, "PLL": 10, "FL": 10, "CL": 10, "ISL": 4, "SSL": -6}
    assert "ITL" not in cs.ligaments and "ITL" in cs.absent
    alt = cs.alternatives["SSL"]
    assert (alt.a, alt.b, alt.c, alt.d) == (-50.49, -36.00, -0.02453, 4.718)
    assert cs.ligaments["SSL"].a == 1.218


@pytest.mark.parametrize("name", ["chazal1985", "shirazi_adl1986", "white_panjabi1990", "nolte1990"])
def test_literature_softplus_laws_physical(name):
    cs = load_characteristic_set(name)
    eps = np.linspace(0, 30, 301)
    for kind, law in cs.ligaments.items():
        f = softplus(law, eps)
        assert np.all(np.isfinite(f)), kind
        assert abs(f[0]) < 0.5, (name, kind, f[0])         # fits pass through ~0 N at 0 % strain
        assert np.all(np.diff(f) > 0), (name, kind)         # monotonically stiffening in tension
        assert f[-1] > 5, (name, kind)


def test_literature_sets_absences():
    assert "CL" not in load_characteristic_set("chazal1985").ligaments
    assert "ITL" not in load_characteristic_set("white_panjabi1990").ligaments
    assert "ITL" not in load_characteristic_set("nolte1990").ligaments
    assert len(load_characteristic_set("shirazi_adl1986").ligaments) == 7


def test_rupp_all_check_example():
    law = load_characteristic_set("rupp2015").ligaments["ALL"]
    assert isinstance(law, RuppLaw)
    assert (law.l_a_m, law.l_b_m, law.f_a_n, law.f_b_n, law.n_strands, law.prestrain_pct) == pytest.approx(
        (1.52e-3, 4.98e-3, 55, 456, 3, 6.8))
    sp = rupp_shape_parameters(law, 0.0135471 * 1.068)
    assert sp["l0"] == pytest.approx(0.0135471, rel=1e-9)
    assert sp["dU_nll"] == pytest.approx(0.112201, rel=1e-3)
    assert sp["nu"] == pytest.approx(3.20294, rel=1e-3)
    assert sp["K_nl"] == pytest.approx(1.94821e10, rel=1e-3)
    assert sp["K_l"] == pytest.approx(38632, rel=1e-3)


def _check_rows():
    chk = load_shape_check()
    return [r for r in chk.to_dict("records")]


@pytest.mark.parametrize("row", [r for r in _check_rows() if r["ligament"] != "ITL"],
                         ids=lambda r: f"{r['ligament']}-{r['fibre']}")
def test_rupp_shape_parameters_reproduce_paper_table(row):
    law = load_characteristic_set("rupp2015").ligaments[row["ligament"]]
    l_set = row["l0"] * (1 + law.prestrain_pct / 100)
    sp = rupp_shape_parameters(law, l_set)
    for k in ("dU_nll", "nu", "K_nl", "K_l"):
        assert sp[k] == pytest.approx(row[k], rel=1e-3), k
    # continuity of force at the transition: K_nl*(dU_nll*l0)^nu == dF0
    assert sp["K_nl"] * (sp["dU_nll"] * sp["l0"]) ** sp["nu"] == pytest.approx(sp["dF0"], rel=1e-9)
    # C1 continuity: nu*K_nl*(dU_nll*l0)^(nu-1) == K_l
    assert sp["nu"] * sp["K_nl"] * (sp["dU_nll"] * sp["l0"]) ** (sp["nu"] - 1) == pytest.approx(sp["K_l"], rel=1e-9)


def test_rupp_itl_check_rows_follow_isl_inputs_not_itl_inputs():
    """Documents an inconsistency in the paper: the ITL shape parameters equal ISL's."""
    cs = load_characteristic_set("rupp2015")
    itl = [r for r in _check_rows() if r["ligament"] == "ITL"]
    for row in itl:
        isl_like = RuppLaw(**{**cs.ligaments["ISL"].__dict__, "prestrain_pct": cs.ligaments["ITL"].prestrain_pct})
        sp = rupp_shape_parameters(isl_like, row["l0"] * 1.10)
        assert sp["nu"] == pytest.approx(row["nu"], rel=1e-3)
        assert sp["dU_nll"] == pytest.approx(row["dU_nll"], rel=1e-3)
        sp_itl = rupp_shape_parameters(cs.ligaments["ITL"], row["l0"] * 1.10)
        assert sp_itl["nu"] != pytest.approx(row["nu"], rel=1e-2)


def test_every_data_row_has_source_and_kind():
    for f in DATA.glob("*.csv"):
        df = pd.read_csv(f, dtype=str, keep_default_na=False)
        assert {"source", "kind"} <= set(df.columns), f
        assert (df["source"].str.strip() != "").all(), f
        assert df["kind"].isin(["original_text", "original_figure", "third_party",
                                "derived_from_published_fit", "surrogate"]).all(), f


def test_data_dir_from_env(tmp_path, monkeypatch):
    shutil.copytree(DATA, tmp_path / "data" / "characteristics")
    monkeypatch.setenv("LUMBAR_DATA_DIR", str(tmp_path / "data"))
    assert default_data_dir() == tmp_path / "data" / "characteristics"
    cs = load_characteristic_set("nolte1990")
    assert str(tmp_path) in cs.source


def test_overrides_apply():
    cs = load_characteristic_set("calibrated", overrides={"facet.stiffness": 2e4, "ligaments.ALL.prestrain_pct": 5})
    assert cs.facet.stiffness == 2e4 and cs.ligaments["ALL"].prestrain_pct == 5


# ---------------------------------------------------------------- bad input
@pytest.fixture
def data_copy(tmp_path):
    d = tmp_path / "characteristics"
    shutil.copytree(DATA, d)
    return d


def _edit(path, row, column, value):
    """Set data row `row` (1-based) of `column` to the raw text `value`."""
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    df.loc[row - 1, column] = value
    df.to_csv(path, index=False, lineterminator="\n")


def _row_of(path, **match):
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    m = np.ones(len(df), bool)
    for k, v in match.items():
        m &= (df[k] == v).to_numpy()
    return int(np.flatnonzero(m)[0]) + 1


def _assert_msg(exc, fname, column, row=None):
    msg = str(exc.value)
    assert fname in msg and f"column '{column}'" in msg and "expected" in msg, msg
    if row is not None:
        assert f"row {row}" in msg, msg


def test_reject_negative_facet_stiffness(data_copy):
    p = data_copy / "facet.csv"
    r = _row_of(p, parameter="stiffness")
    _edit(p, r, "value", "-12000")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "facet.csv", "value", r)
    assert "negative" in str(e.value)


def test_reject_negative_disc_axial_stiffness(data_copy):
    p = data_copy / "disc.csv"
    r = _row_of(p, parameter="axial_linear")
    _edit(p, r, "value", "-659748")
    with pytest.raises(ValueError) as e:
        load_characteristic_set("nolte1990", data_dir=data_copy)
    _assert_msg(e, "disc.csv", "value", r)


def test_reject_nan_value(data_copy):
    p = data_copy / "ligaments_softplus.csv"
    r = _row_of(p, set="calibrated", ligament="ALL", parameter="a")
    _edit(p, r, "value", "nan")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "ligaments_softplus.csv", "value", r)
    assert "non-finite" in str(e.value)


def test_reject_inf_in_rupp(data_copy):
    p = data_copy / "ligaments_rupp2015.csv"
    r = _row_of(p, ligament="FL", parameter="f_b")
    _edit(p, r, "value", "inf")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("rupp2015", data_dir=data_copy)
    _assert_msg(e, "ligaments_rupp2015.csv", "value", r)


def test_bad_missing_column(data_copy):
    p = data_copy / "disc.csv"
    pd.read_csv(p, dtype=str, keep_default_na=False).drop(columns=["unit"]).to_csv(p, index=False)
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "disc.csv", "unit")
    assert "missing column" in str(e.value)


def test_reject_unknown_set():
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("panjabi2001")
    assert "panjabi2001" in str(e.value) and "calibrated" in str(e.value) and "column 'name'" in str(e.value)


def test_bad_missing_ligament(data_copy):
    p = data_copy / "ligaments_softplus.csv"
    df = pd.read_csv(p, dtype=str, keep_default_na=False)
    df = df[~((df["set"] == "shirazi_adl1986") & (df["ligament"] == "ITL"))]
    df.to_csv(p, index=False, lineterminator="\n")
    load_characteristic_set("calibrated", data_dir=data_copy)  # other sets unaffected
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("shirazi_adl1986", data_dir=data_copy)
    _assert_msg(e, "ligaments_softplus.csv", "ligament")
    assert "ITL" in str(e.value)


def test_bad_missing_rupp_ligament(data_copy):
    p = data_copy / "ligaments_rupp2015.csv"
    df = pd.read_csv(p, dtype=str, keep_default_na=False)
    df[df["ligament"] != "CL"].to_csv(p, index=False, lineterminator="\n")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("rupp2015", data_dir=data_copy)
    _assert_msg(e, "ligaments_rupp2015.csv", "ligament")


def test_malformed_number(data_copy):
    p = data_copy / "disc.csv"
    r = _row_of(p, parameter="torque_p2", direction="extension")
    _edit(p, r, "value", "0,008417")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "disc.csv", "value", r)
    assert "not a number" in str(e.value)


def test_malformed_rupp_fraction(data_copy):
    p = data_copy / "ligaments_rupp2015.csv"
    r = _row_of(p, ligament="ALL", parameter="l_a")
    _edit(p, r, "value_as_printed", "1 13/2x")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("rupp2015", data_dir=data_copy)
    _assert_msg(e, "ligaments_rupp2015.csv", "value_as_printed", r)


def test_reject_value_disagreeing_with_printed_fraction(data_copy):
    p = data_copy / "ligaments_rupp2015.csv"
    r = _row_of(p, ligament="ALL", parameter="l_a")
    _edit(p, r, "value", "1.5")  # rounded: the paper warns rounding breaks K_nl
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("rupp2015", data_dir=data_copy)
    _assert_msg(e, "ligaments_rupp2015.csv", "value", r)


def test_bad_units_column(data_copy):
    p = data_copy / "facet.csv"
    r = _row_of(p, parameter="stiffness")
    _edit(p, r, "unit", "N/rad")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "facet.csv", "unit", r)
    assert "N/m" in str(e.value)


def test_bad_units_softplus_fraction_not_percent(data_copy):
    p = data_copy / "ligaments_softplus.csv"
    r = _row_of(p, set="nolte1990", ligament="FL", parameter="b")
    _edit(p, r, "unit", "1")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("nolte1990", data_dir=data_copy)
    _assert_msg(e, "ligaments_softplus.csv", "unit", r)


def test_units_converted_to_si(data_copy):
    p = data_copy / "facet.csv"
    r = _row_of(p, parameter="stiffness")
    _edit(p, r, "value", "12")
    _edit(p, r, "unit", "N/mm")
    assert load_characteristic_set("calibrated", data_dir=data_copy).facet.stiffness == pytest.approx(12000.0)


def test_reject_unknown_kind(data_copy):
    p = data_copy / "ligament_prestrain.csv"
    _edit(p, 2, "kind", "from_memory")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "ligament_prestrain.csv", "kind", 2)
    assert "original_text" in str(e.value)


def test_reject_zero_softplus_d(data_copy):
    p = data_copy / "ligaments_softplus.csv"
    r = _row_of(p, set="calibrated", ligament="ISL", parameter="d")
    _edit(p, r, "value", "0")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "ligaments_softplus.csv", "value", r)


def test_reject_rows_for_documented_absent_ligament(data_copy):
    p = data_copy / "ligaments_softplus.csv"
    df = pd.read_csv(p, dtype=str, keep_default_na=False)
    extra = df[(df["set"] == "calibrated") & (df["ligament"] == "ALL") & (df["variant"] == "primary")].copy()
    extra["ligament"] = "ITL"
    pd.concat([df, extra]).to_csv(p, index=False, lineterminator="\n")
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", data_dir=data_copy)
    _assert_msg(e, "ligaments_softplus.csv", "ligament")


def test_reject_negative_override():
    with pytest.raises(CharacteristicsError) as e:
        load_characteristic_set("calibrated", overrides={"disc.k_shear": -1.0})
    assert "disc.k_shear" in str(e.value)
    with pytest.raises(CharacteristicsError):
        load_characteristic_set("calibrated", overrides={"ligaments.ITL.a": 1.0})
