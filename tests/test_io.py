"""Tests for lumbar.inputs.io: schema validation and atomic writers."""
import json
import os

import numpy as np
import pandas as pd
import pytest

from lumbar.inputs.io import (Column, TableError, TableSchema, atomic_writer, read_table, write_json_atomic,
                       write_table_atomic, write_text_atomic)

SCHEMA = TableSchema("demo", {
    "name": Column("str"),
    "kind": Column("str", allowed={"a", "b"}),
    "x": Column("float", min=0.0),
    "n": Column("int", min=1),
    "note": Column("str", required=False, nullable=True),
})


def _write(tmp_path, text, name="t.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_read_ok_types(tmp_path):
    p = _write(tmp_path, "name,kind,x,n,note\nfoo,a,1.5,2,\nbar,b,0,3,hi\n")
    df = read_table(p, SCHEMA)
    assert df["x"].dtype == np.float64 and df["n"].dtype == np.int64
    assert df["x"].tolist() == [1.5, 0.0] and df["note"].tolist() == ["", "hi"]


def test_bad_row_number_is_one_based_data_row(tmp_path):
    p = _write(tmp_path, "name,kind,x,n\nfoo,a,1,2\nbar,a,-1,2\n")
    with pytest.raises(TableError) as e:
        read_table(p, SCHEMA)
    assert e.value.row == 2 and e.value.column == "x"
    assert "t.csv" in str(e.value) and "row 2" in str(e.value) and ">= 0" in str(e.value)


def test_malformed_number_message(tmp_path):
    p = _write(tmp_path, "name,kind,x,n\nfoo,a,1.2.3,2\n")
    with pytest.raises(TableError, match=r"t\.csv, row 1, column 'x'.*not a number.*expected a finite number"):
        read_table(p, SCHEMA)


def test_malformed_csv_too_many_fields(tmp_path):
    p = _write(tmp_path, "name,kind,x,n\nfoo,a,1,2,9,9\n")
    with pytest.raises(TableError, match="t.csv"):
        read_table(p, SCHEMA)


def test_reject_nan_and_allowed_values(tmp_path):
    with pytest.raises(TableError, match="non-finite"):
        read_table(_write(tmp_path, "name,kind,x,n\nfoo,a,NaN,2\n"), SCHEMA)
    with pytest.raises(TableError, match=r"column 'kind'.*one of 'a', 'b'"):
        read_table(_write(tmp_path, "name,kind,x,n\nfoo,c,1,2\n"), SCHEMA)


def test_reject_non_integer_and_empty(tmp_path):
    with pytest.raises(TableError, match=r"column 'n'.*not an integer"):
        read_table(_write(tmp_path, "name,kind,x,n\nfoo,a,1,2.5\n"), SCHEMA)
    with pytest.raises(TableError, match=r"column 'name'.*empty"):
        read_table(_write(tmp_path, "name,kind,x,n\n,a,1,2\n"), SCHEMA)


def test_bad_missing_column_and_file(tmp_path):
    with pytest.raises(TableError, match=r"column 'n'.*missing column"):
        read_table(_write(tmp_path, "name,kind,x\nfoo,a,1\n"), SCHEMA)
    with pytest.raises(TableError, match="file not found"):
        read_table(tmp_path / "nope.csv", SCHEMA)
    with pytest.raises(TableError, match="empty"):
        read_table(_write(tmp_path, ""), SCHEMA)


def test_reject_extra_column_when_strict(tmp_path):
    strict = TableSchema("s", {"x": Column("float")}, allow_extra=False)
    with pytest.raises(TableError, match="unexpected column"):
        read_table(_write(tmp_path, "x,y\n1,2\n"), strict)


def test_write_table_deterministic(tmp_path):
    df = pd.DataFrame({"a": [1.0 / 3.0, 2.0e10], "b": ["x", "y"], "n": [1, 2]})
    p = write_table_atomic(df, tmp_path / "out.csv")
    raw = p.read_bytes()
    assert raw == b"a,b,n\n0.333333,x,1\n2e+10,y,2\n"
    write_table_atomic(df, tmp_path / "out2.csv")
    assert (tmp_path / "out2.csv").read_bytes() == raw


def test_write_json_and_text(tmp_path):
    p = write_json_atomic({"b": np.float64(1.5), "a": [np.int64(1)]}, tmp_path / "o.json")
    assert p.read_text() == '{\n  "a": [\n    1\n  ],\n  "b": 1.5\n}\n'
    assert json.loads(p.read_text()) == {"a": [1], "b": 1.5}
    with pytest.raises(ValueError):
        write_json_atomic({"x": float("nan")}, tmp_path / "nan.json")
    assert not (tmp_path / "nan.json").exists()
    q = write_text_atomic("hello\n", tmp_path / "sub" / "t.txt")
    assert q.read_text() == "hello\n"


class _Boom:
    def __str__(self):
        raise RuntimeError("boom while formatting")

    __repr__ = __str__
    def __format__(self, spec):
        return str(self)


def _leftovers(d):
    return [f for f in os.listdir(d) if f.endswith(".tmp")]


def test_atomic_table_write_leaves_no_partial_file(tmp_path):
    target = tmp_path / "res.csv"
    df = pd.DataFrame({"a": list(range(1000)) + [0], "b": ["ok"] * 1000 + [_Boom()]})
    with pytest.raises(RuntimeError, match="boom"):
        write_table_atomic(df, target)
    assert not target.exists() and _leftovers(tmp_path) == []


def test_atomic_write_keeps_old_content_when_writer_raises(tmp_path):
    target = tmp_path / "keep.txt"
    write_text_atomic("old\n", target)
    with pytest.raises(RuntimeError):
        with atomic_writer(target) as f:
            f.write("new partial content")
            f.flush()
            raise RuntimeError("writer died mid-way")
    assert target.read_text() == "old\n" and _leftovers(tmp_path) == []


@pytest.mark.parametrize("suffix", ["png", "pdf", "svg"])
def test_save_figure_atomic_deterministic_bytes(tmp_path, suffix):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lumbar.inputs.io import save_figure_atomic

    def draw(p):
        fig, ax = plt.subplots(figsize=(2, 2))
        ax.plot([0, 1], [0, 1], label="x")
        ax.legend()
        save_figure_atomic(fig, p, dpi=50)
        plt.close(fig)

    a, b = tmp_path / f"a.{suffix}", tmp_path / f"b.{suffix}"
    draw(a)
    draw(b)
    assert a.read_bytes() == b.read_bytes() and a.stat().st_size > 100
    assert b"tIME" not in a.read_bytes() and b"CreationDate" not in a.read_bytes()
    assert b"Matplotlib v" not in a.read_bytes() and b"matplotlib.org" not in a.read_bytes()
    assert _leftovers(tmp_path) == []
