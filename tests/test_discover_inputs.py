"""Measured tables of the discrepancy discovery read strictly (lumbar.discovery.read_measured with
lumbar.inputs.tables.check_measured): repeated scenarios, values outside the sourced physiological ranges (with the
unit they look like), spreads the specimens cannot have; and a property test that corrupts every measured schema at
random and gets a clear error or a correct reading, never a traceback and never a silent number.

The base tables below are TEST FIXTURES in the measured schemas (plausible values typed for the test, not data)."""
import csv
import io
import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lumbar import discovery as D
from lumbar.inputs import tables as T

ROOT = Path(__file__).resolve().parents[1]
DERIVED = ROOT / "data" / "experiments" / "heuer2007_disc_only_derived_from_published_fit.csv"
VA = ROOT / "data" / "experiments" / "heuer2007_va_artefact_original_text.csv"


# ------------------------------------------------------------------ base tables (fixtures), one per measured schema
def rom_base() -> pd.DataFrame:
    """Four stages x four directions x two moments; a range on every row (8 specimens)."""
    rows = []
    base = {"flexion": 4.0, "extension": 2.5, "lateral_bending": 3.0, "axial_rotation": 1.2}
    for k, (st_, (d, r), m) in enumerate(itertools.product(["intact", "wo_cl", "wo_va", "wo_pll"], base.items(),
                                                           [2.5, 7.5])):
        mean = r * (1 + 0.3 * k / 32) * (1.6 if m == 7.5 else 1.0)
        rows.append(dict(stage=st_, direction=d, moment_nm=m, rom_mean_deg=round(mean, 4),
                         rom_min_deg=round(0.7 * mean, 4), rom_max_deg=round(1.3 * mean, 4), n_specimens=8,
                         kind="surrogate", source="TEST FIXTURE"))
    return pd.DataFrame(rows)


def idp_base() -> pd.DataFrame:
    rng = np.random.default_rng(4)
    grid = list(itertools.product(T.MUSCLE_SETUPS, T.LOAD_CASES))
    mean = np.round(0.1 + 0.3 * rng.random(len(grid)), 4)
    return pd.DataFrame({"muscle_setup": [g[0] for g in grid], "load_case": [g[1] for g in grid],
                         "idp_mean_mpa": mean, "idp_sd_mpa": np.round(0.1 * mean + 0.01, 4), "n_specimens": 7,
                         "kind": "surrogate", "source": "TEST FIXTURE"})


def in_vivo_base() -> pd.DataFrame:
    acts = ["extension_20deg", "relaxed_standing", "crate_close_chest", "crate_far_60cm", "flexion_36deg"]
    return pd.DataFrame({"activity": acts, "idp_sim_mpa": [0.55, 0.4, 1.1, 1.6, 1.0],
                         "idp_in_vivo_mpa": [0.6, 0.5, 1.0, 1.8, 1.08], "source": "TEST FIXTURE", "converged": "True"})


def neutral_base() -> pd.DataFrame:
    return pd.DataFrame({"stage": ["wo_cl", "wo_va", "wo_pll"], "lordosis_deg": [0.66, 2.2, 2.4],
                         "lordosis_sd_deg": ["", "", 0.3], "kind": "surrogate", "source": "TEST FIXTURE"})


BASES = {"stepwise_rom": rom_base, "idp_invitro": idp_base, "in_vivo": in_vivo_base, "neutral_angle": neutral_base}
#: value columns and their unit (what a unit confusion scales)
VALUE_COLUMNS = {"stepwise_rom": (["rom_mean_deg", "rom_min_deg", "rom_max_deg"], "deg"),
                 "idp_invitro": (["idp_mean_mpa", "idp_sd_mpa"], "MPa"),
                 "in_vivo": (["idp_sim_mpa", "idp_in_vivo_mpa"], "MPa"),
                 "neutral_angle": (["lordosis_deg"], "deg")}


def write(tmp_path, df, name="t.csv") -> Path:
    p = tmp_path / name
    df.to_csv(p, index=False)
    return p


def test_base_tables_are_read_as_written(tmp_path):
    for kind, make in BASES.items():
        exp, df = D.read_measured(write(tmp_path, make(), f"{kind}.csv"))
        assert exp == kind and df.attrs["input_warnings"] == []


# ------------------------------------------------------------------ the corruptions found by hand, each refused
def test_idp_table_with_a_repeated_scenario_is_refused(tmp_path):
    df = idp_base()
    p = write(tmp_path, pd.concat([df, df.iloc[[10]]], ignore_index=True))      # 50 rows for 49 scenarios
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(p)
    assert str(e.value).startswith(f"{p}, row 50, column 'load_case': duplicate (muscle_setup, load_case) "
                                   f"('{df['muscle_setup'][10]}', '{df['load_case'][10]}') (first at row 11)")


@pytest.mark.parametrize("kind, key", [("in_vivo", "activity"), ("neutral_angle", "stage")])
def test_every_measured_schema_refuses_a_repeated_key(tmp_path, kind, key):
    df = BASES[kind]()
    p = write(tmp_path, pd.concat([df, df.iloc[[1]]], ignore_index=True))
    with pytest.raises(D.DiscoveryInputError, match=rf"row {len(df) + 1}, column '{key}': duplicate {key} "):
        D.read_measured(p)


def test_negative_mean_idp_is_refused(tmp_path):
    df = idp_base()
    df.loc[3, "idp_mean_mpa"] = -0.05
    with pytest.raises(D.DiscoveryInputError, match=r"row 4, column 'idp_mean_mpa': got '-0.05', below the minimum"):
        D.read_measured(write(tmp_path, df))


@pytest.mark.parametrize("make, columns, convert, parts", [
    (idp_base, ["idp_mean_mpa", "idp_sd_mpa"], lambda v: v * 1000.0,          # values 100-1000 read as MPa before
     ["row 1, column 'idp_mean_mpa'", "look like kPa, not MPa", "wilke_idp_l4l5.csv"]),
    (rom_base, ["rom_mean_deg", "rom_min_deg", "rom_max_deg"], np.radians,   # every value below 0.2 "deg"
     ["row 1, column 'rom_mean_deg'", "look like radians, not deg", "yamamoto1989"]),
], ids=["idp_in_kpa", "rom_in_radians"])
def test_table_in_another_unit_is_refused_naming_the_unit(tmp_path, make, columns, convert, parts):
    df = make()
    df[columns] = convert(df[columns])
    with pytest.raises(D.DiscoveryInputError) as e:
        D.read_measured(write(tmp_path, df))
    assert all(x in str(e.value) for x in parts), str(e.value)


def test_idp_sd_in_kpa_beside_a_mean_in_mpa_is_refused(tmp_path):
    df = idp_base()
    df["idp_sd_mpa"] = df["idp_sd_mpa"] * 20.0                   # larger than 7 pressures >= 0 can spread
    with pytest.raises(D.DiscoveryInputError, match=r"column 'idp_sd_mpa': SD .* is larger than 7 pressures >= 0"):
        D.read_measured(write(tmp_path, df))


def test_neutral_angle_table_in_radians_is_refused(tmp_path):
    df = neutral_base()
    df["lordosis_deg"] = np.radians(df["lordosis_deg"])
    with pytest.raises(D.DiscoveryInputError, match="look like radians, not deg"):
        D.read_measured(write(tmp_path, df))


def test_range_from_one_specimen_and_sd_from_one_specimen_are_refused(tmp_path):
    df = rom_base()
    df.loc[2, "n_specimens"] = 1
    with pytest.raises(D.DiscoveryInputError, match=r"row 3, column 'n_specimens': a range .* from one specimen"):
        D.read_measured(write(tmp_path, df))
    df = idp_base()
    df.loc[0, "n_specimens"] = 1
    with pytest.raises(D.DiscoveryInputError, match=r"row 1, column 'idp_sd_mpa': an SD of .* from one specimen"):
        D.read_measured(write(tmp_path, df))
    df.loc[0, "n_specimens"] = 0
    with pytest.raises(D.DiscoveryInputError, match=r"row 1, column 'n_specimens': no specimen behind the mean"):
        D.read_measured(write(tmp_path, df))


def test_a_small_rom_at_a_small_moment_is_read_with_a_warning(tmp_path):
    """One noisy ROM of 0 deg at 2.5 N*m (possible: a stiff direction, noise, values clipped at 0) is flagged, not
    refused; the table in radians (every value low) is refused above."""
    df = rom_base()
    df.loc[7, ["rom_mean_deg", "rom_min_deg"]] = 0.0
    exp, t = D.read_measured(write(tmp_path, df))
    assert t["rom_mean_deg"].iat[7] == 0.0
    assert any("row 8, column 'rom_mean_deg'" in w and "below the plausible range" in w
               for w in t.attrs["input_warnings"])


def test_many_specimens_are_read_with_a_warning(tmp_path):
    df = idp_base()
    df.loc[5, "n_specimens"] = 700
    exp, t = D.read_measured(write(tmp_path, df))
    assert t["n_specimens"].iat[5] == 700
    assert len(t.attrs["input_warnings"]) == 1 and "row 6, column 'n_specimens'" in t.attrs["input_warnings"][0]


def test_plausible_ranges_are_derived_from_the_sourced_tables():
    """The bounds come from the data files (not typed numbers): the smallest and largest sourced values."""
    src = T.sourced_ranges()
    rom = pd.concat([pd.read_csv(ROOT / "data" / f) for f in T.PLAUSIBILITY_SOURCES["rom_deg_at_10nm"]])
    at10 = rom[rom["moment_nm"] == 10]["rom_mean_deg"]
    assert (src["rom_deg_at_10nm"].low, src["rom_deg_at_10nm"].high) == (at10.min(), at10.max())
    idp = pd.read_csv(ROOT / "data" / T.PLAUSIBILITY_SOURCES["idp_mpa"][0])["idp_mpa"]
    assert (src["idp_mpa"].low, src["idp_mpa"].high) == (idp.min(), idp.max())
    # the per-row lower ROM bound takes ROM(M) ~ ROM(10 N*m) M / 10 or more below 10 N*m (within the factor F):
    # every sourced curve has at least half of it (the least: lateral bending at 7.5 N*m, 0.96 of it)
    der = pd.read_csv(DERIVED)
    ratio = []
    for d, g in der.groupby("direction"):
        r10 = g.loc[g["moment_nm"] == 10, "rom_mean_deg"].iat[0]
        ratio += list(g["rom_mean_deg"] / (r10 * g["moment_nm"] / 10))
    assert min(ratio) > 0.5 and np.isclose(min(ratio), 0.955, atol=0.01)
    # radians for degrees and kPa or Pa for MPa cannot be plausible in both units: F^2 below their factors
    for unit, name in (("deg", "radians"), ("MPa", "kPa"), ("MPa", "Pa")):
        f = T.UNIT_CONFUSIONS[unit][name]
        assert T.PLAUSIBILITY_FACTOR ** 2 < max(f, 1 / f), (unit, name)


# ------------------------------------------------------------------ property test: random corruptions
GARBAGE = ["abc", "nan", "NaN", "inf", "-inf", "1e999", "", " ", "1,5", "0x1F", "None", "--3", "4.9 deg"]


def _rows(df):
    buf = io.StringIO()
    df.to_csv(buf, index=False)
    return list(csv.reader(io.StringIO(buf.getvalue())))


def _to_text(rows):
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    return buf.getvalue()


@st.composite
def corruption(draw):
    """(kind, file text, expectation, hint): expectation 'refuse' = only a clear error is right; 'either' = a clear
    error or a correct reading; hint = a word the error must contain (column or unit)."""
    kind = draw(st.sampled_from(sorted(BASES)))
    df = BASES[kind]()
    rows = _rows(df)
    head, body = rows[0], rows[1:]
    vcols, unit = VALUE_COLUMNS[kind]
    op = draw(st.sampled_from(["duplicate", "unit", "garbage", "negate", "drop_column", "short_row", "long_row",
                               "bad_label", "scale_cell", "drop_row", "n_zero", "n_large", "header_case",
                               "header_only", "swap_values"]))
    i = draw(st.integers(0, len(body) - 1))
    if op == "duplicate":
        body.insert(draw(st.integers(0, len(body))), list(body[i]))
        return kind, _to_text([head] + body), "refuse", "duplicate"
    if op == "unit":
        name, f = draw(st.sampled_from(sorted(T.UNIT_CONFUSIONS[unit].items())))
        for r in body:
            for c in vcols:
                j = head.index(c)
                if r[j] != "":
                    r[j] = repr(float(r[j]) / f)
        # radians for degrees, kPa or Pa for MPa cannot be plausible (F^2 below their factors): refused, naming the
        # unit; bar and psi (factors 10, 145) can be, and another unit may fit as well
        sure = name in ("radians", "kPa", "Pa")
        return kind, _to_text([head] + body), "refuse" if sure else "either", name if sure else None
    if op == "garbage":
        c = draw(st.sampled_from(head))
        g = draw(st.sampled_from(GARBAGE))
        body[i][head.index(c)] = g
        numeric = c in vcols + ["moment_nm", "n_specimens"]
        spec = MEASURED_SPEC[kind].columns.get(c)
        nullable_empty = spec is not None and spec.nullable and g.strip() == ""
        refuse = numeric and not nullable_empty and not (c == "idp_sim_mpa" and g.strip() == "")
        if c in ("rom_min_deg", "rom_max_deg") and g.strip() == "":
            refuse = True                                        # one of a pair: refused (both or none)
        return kind, _to_text([head] + body), "refuse" if refuse else "either", c if refuse else None
    if op == "negate":
        c = draw(st.sampled_from(vcols))
        v = body[i][head.index(c)]
        if v == "" or float(v) == 0:
            return kind, _to_text([head] + body), "either", None
        body[i][head.index(c)] = repr(-float(v))
        return kind, _to_text([head] + body), "either" if kind == "neutral_angle" else "refuse", c
    if op == "drop_column":
        c = draw(st.sampled_from(head))
        j = head.index(c)
        new = [[x for k, x in enumerate(r) if k != j] for r in [head] + body]
        used = c in T.MEASURED[kind].columns
        return kind, _to_text(new), "refuse" if used else "either", None
    if op == "short_row":
        body[i] = body[i][:-1]
        return kind, _to_text([head] + body), "refuse", "field(s) but the header has"
    if op == "long_row":
        body[i] = body[i] + ["1.0"]
        return kind, _to_text([head] + body), "refuse", "field(s) but the header has"
    if op == "bad_label":
        c = head[0]
        body[i][0] = body[i][0] + "_x"
        if kind == "in_vivo":      # free text: checked against the segment loads when the problem is built
            return kind, _to_text([head] + body), "either", None
        return kind, _to_text([head] + body), "refuse", c
    if op == "scale_cell":
        c = draw(st.sampled_from(vcols))
        j = head.index(c)
        if body[i][j] != "":
            body[i][j] = repr(float(body[i][j]) * draw(st.sampled_from([0.5, 0.9, 1.1, 2.0, 57.3, 1000.0, 1e-3])))
        return kind, _to_text([head] + body), "either", None
    if op == "drop_row":
        del body[i]
        few = kind == "neutral_angle" and len(body) < 2
        return kind, _to_text([head] + body), "refuse" if few else "either", None
    if op in ("n_zero", "n_large"):
        if "n_specimens" not in head:
            return kind, _to_text([head] + body), "either", None
        body[i][head.index("n_specimens")] = "0" if op == "n_zero" else "5000"
        return kind, _to_text([head] + body), "refuse" if op == "n_zero" else "either", "n_specimens"
    if op == "header_case":
        j = draw(st.integers(0, len(head) - 1))
        head = list(head)
        used = head[j] in T.MEASURED[kind].columns
        head[j] = head[j].upper()
        return kind, _to_text([head] + body), "refuse" if used else "either", None
    if op == "header_only":
        return kind, _to_text([head]), "refuse", None
    # swap_values: two value cells of a row exchanged (may break min <= mean <= max, or stay plausible)
    a, b = (draw(st.sampled_from(vcols)) for _ in range(2))
    ja, jb = head.index(a), head.index(b)
    body[i][ja], body[i][jb] = body[i][jb], body[i][ja]
    return kind, _to_text([head] + body), "either", None


MEASURED_SPEC = {k: v.schema for k, v in T.MEASURED.items()}


def _correct_reading(kind, text, df) -> list[str]:
    """What is wrong with an accepted reading: it must be the file's cells, number by number, every value within
    the plausible ranges (or a warning naming it), keys unique."""
    problems = []
    rows = list(csv.reader(io.StringIO(text)))
    head, body = rows[0], [r for r in rows[1:] if r]
    if len(df) != len(body):
        problems.append(f"{len(body)} data rows read as {len(df)}")
        return problems
    spec = MEASURED_SPEC[kind]
    for c in head:
        if c not in spec.columns or spec.columns[c].dtype == "str":
            continue
        want = np.array([float(r[head.index(c)]) if r[head.index(c)].strip() else np.nan for r in body])
        got = df[c].to_numpy(float)
        if not np.array_equal(want, got, equal_nan=True):
            problems.append(f"column {c}: file {want} read as {got}")
    key = list(spec.unique.columns)
    if df.duplicated(key).any():
        problems.append("repeated key accepted")
    warns = df.attrs.get("input_warnings", [])
    for rng in T.plausible_ranges(kind, df):
        if rng.column in df:
            v = df[rng.column].to_numpy(float)
            out = np.isfinite(v) & ((v < np.nan_to_num(rng.lo, nan=-np.inf)) | (v > np.nan_to_num(rng.hi, nan=np.inf)))
            for i in np.flatnonzero(out):         # accepted only with a warning naming row and column
                if not any(f"row {i + 1}, column '{rng.column}'" in w for w in warns):
                    problems.append(f"implausible {rng.column} = {v[i]} (row {i + 1}) accepted without a warning")
    if "n_specimens" in df and (df["n_specimens"] > T.PLAUSIBILITY_FACTOR * 10).any() and \
            not any("n_specimens" in w for w in df.attrs.get("input_warnings", [])):
        problems.append("a count beyond the sourced studies without a warning")
    return problems


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=corruption())
def test_random_corruption_gives_a_clear_error_or_a_correct_reading(tmp_path, case):
    kind, text, expect, hint = case
    p = tmp_path / "corrupted.csv"
    p.write_text(text)
    try:
        exp, df = D.read_measured(p)
    except D.DiscoveryInputError as e:           # a clear error: names the file (and the column / unit it can)
        msg = str(e)
        assert msg.startswith(str(p)), msg
        if hint:
            assert hint in msg, (hint, msg)
        return
    assert expect != "refuse", f"silent acceptance of a corrupted {kind} table:\n{text}"
    assert exp == kind
    problems = _correct_reading(kind, text, df)
    assert not problems, (problems, text)


def test_infinite_range_end_is_refused_naming_its_column(tmp_path):
    """An 'inf' in a ROM range column (found by the corruption suite) is refused with the column named, not read
    as a measurement; an empty cell still means 'no range'."""
    rows = ["stage,direction,moment_nm,rom_mean_deg,rom_min_deg,rom_max_deg,n_specimens,kind,source"]
    rows += [f"intact,{d},{m},{4.0 + m / 5:.2f},,,8,surrogate,TEST FIXTURE" for d in ("flexion", "extension")
             for m in (2.5, 7.5)]
    ok = tmp_path / "ok.csv"
    ok.write_text("\n".join(rows) + "\n")
    D.read_measured(ok)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(rows[:1] + [rows[1].replace(",,,8,", ",2.8,inf,8,")] + rows[2:]) + "\n")
    with pytest.raises(Exception, match="rom_max_deg") as e:
        D.read_measured(bad)
    assert "bad.csv" in str(e.value)
