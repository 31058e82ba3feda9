"""Identity of the results (issue 17): the test-config DAG writes the same result tables as the reference run
(tests/data/results_sha256_test_config.json: SHA-256 of 44 tables of every stage except the muscle model and
the two *_vs_paper tables, whose paper columns come from ../shared; tests/data/results_test_config.tar.gz: the
tables themselves). A table whose bytes differ is compared number by number with the reference: floating-point
round-off differs between CPUs and BLAS builds (the manifest of 2ed2998 was not reproduced byte for byte on
another machine of the same kind, by the same code), so where the bytes differ every text cell must be equal
and every number within a relative 1e-6 (of the column's largest magnitude) of the reference: far below any
change a refactoring could make by mistake, far above round-off. A refactoring must leave it green; a change
meant to change results re-writes the reference (tests/data/results_manifest.py) and says so in its commit."""
import importlib.util
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("results_manifest", HERE / "data" / "results_manifest.py")
rm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rm)


def test_manifest_checker_detects_a_changed_table(tmp_path):
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "a.csv").write_text("x\n1\n")
    (tmp_path / "tables" / "sobol_indices.csv").write_text("excluded\n")
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "t.csv").write_text("excluded\n")
    assert rm.covered(tmp_path) == ["tables/a.csv"]
    before = rm.digest(tmp_path / "tables" / "a.csv")
    (tmp_path / "tables" / "a.csv").write_text("x\n1.0\n")
    assert rm.digest(tmp_path / "tables" / "a.csv") != before


RTOL = 1e-6     # of the column's largest magnitude


def numeric_differences(ref: bytes, now: bytes, rtol=RTOL) -> list[str]:
    """Where two CSV tables differ beyond round-off: columns, row count, text cells, numbers (NaN = NaN)."""
    a, b = pd.read_csv(io.BytesIO(ref)), pd.read_csv(io.BytesIO(now))
    if list(a.columns) != list(b.columns):
        return [f"columns {list(a.columns)} -> {list(b.columns)}"]
    if len(a) != len(b):
        return [f"rows {len(a)} -> {len(b)}"]
    out = []
    for c in a.columns:
        x, y = a[c], b[c]
        if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y) and not (
                pd.api.types.is_bool_dtype(x) or pd.api.types.is_bool_dtype(y)):
            xf, yf = x.to_numpy(float), y.to_numpy(float)
            scale = np.nanmax(np.abs(xf)) if np.isfinite(xf).any() else 0.0
            same = (np.isnan(xf) & np.isnan(yf)) | (np.abs(xf - yf) <= rtol * max(scale, 1e-300))
            if not same.all():
                k = int(np.flatnonzero(~same)[0])
                out.append(f"{c}: {int((~same).sum())} values, e.g. row {k}: {xf[k]!r} -> {yf[k]!r}")
        elif not x.astype(str).equals(y.astype(str)):
            k = int(np.flatnonzero(x.astype(str).to_numpy() != y.astype(str).to_numpy())[0])
            out.append(f"{c}: text row {k}: {x.iloc[k]!r} -> {y.iloc[k]!r}")
    return out


def test_numeric_comparison_tolerates_round_off_only():
    ref = b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\nc,,5,True\n"
    assert numeric_differences(ref, ref) == []
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0000000000000002,3,True\nb,2.5e-3,4,False\nc,,5,True\n") == []
    assert numeric_differences(ref, b"name,v,n,ok\na,1.00001,3,True\nb,2.5e-3,4,False\nc,,5,True\n")
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,True\nc,,5,True\n")
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\nc,0.1,5,True\n")
    assert numeric_differences(ref, b"name,v,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\n")
    assert numeric_differences(ref, b"name,w,n,ok\na,1.0,3,True\nb,2.5e-3,4,False\nc,,5,True\n")


def test_reference_snapshot_matches_the_manifest():
    snap = rm.read_snapshot()
    manifest = json.loads(rm.MANIFEST.read_text())
    assert sorted(snap) == sorted(manifest)
    import hashlib
    assert all(hashlib.sha256(snap[k]).hexdigest() == manifest[k] for k in manifest)


@pytest.mark.workflow
def test_result_tables_identical_to_reference(dag_workdir):
    manifest = json.loads(rm.MANIFEST.read_text())
    snap = rm.read_snapshot()
    results = Path(dag_workdir) / "results"
    now = {rel: rm.digest(results / rel) for rel in rm.covered(results)}
    assert sorted(now) == sorted(manifest), (
        f"tables added {sorted(set(now) - set(manifest))}, missing {sorted(set(manifest) - set(now))}")
    bytes_differ = sorted(k for k in manifest if now[k] != manifest[k])
    changed = {k: d for k in bytes_differ if (d := numeric_differences(snap[k], (results / k).read_bytes()))}
    assert not changed, (f"result tables changed beyond round-off: {changed} (re-write the reference only for an "
                         f"intended change); {len(bytes_differ)} tables differ in their bytes")
