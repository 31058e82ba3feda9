"""Byte identity of the results (issue 17): the test-config DAG writes the same result tables as the commit
the manifest was written at (tests/data/results_sha256_test_config.json: 44 tables of every stage except the
muscle model and the two *_vs_paper tables, whose paper columns come from ../shared; written at 2ed2998 and
checked unchanged after the issue-17 restructuring). A refactoring must leave it green; a change meant to
change results re-writes the manifest (tests/data/results_manifest.py) and says so in its commit."""
import importlib.util
import json
from pathlib import Path

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


@pytest.mark.workflow
def test_result_tables_byte_identical_to_manifest(dag_workdir):
    manifest = json.loads(rm.MANIFEST.read_text())
    results = Path(dag_workdir) / "results"
    now = {rel: rm.digest(results / rel) for rel in rm.covered(results)}
    assert sorted(now) == sorted(manifest), (
        f"tables added {sorted(set(now) - set(manifest))}, missing {sorted(set(manifest) - set(now))}")
    changed = sorted(k for k in manifest if now[k] != manifest[k])
    assert not changed, f"result tables changed: {changed} (re-write the manifest only for an intended change)"
