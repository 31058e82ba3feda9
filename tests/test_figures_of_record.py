"""The figures of record and their ratchet (lumbar.report.figures_of_record).

The comparison is tested on doctored figures documents (the controls: a worsened figure fails naming the figure, the
old and the new value and the tolerance; an improved one passes and asks for the reference; a worse one accepted in
the reference with a one-line reason passes, without a reason it is refused; a figure the run lacks is reported;
job times are never compared). The ratchet itself: the figures the session's test-config DAG wrote
(``dag_workdir``, conftest.py: no DAG run of its own) against tests/reference/figures_test_config.json.
"""
import copy
import json
import warnings
from pathlib import Path

import pandas as pd
import pytest

from lumbar.report import figures_of_record as F

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "tests" / "reference" / "figures_test_config.json"


def doc(**values):
    """A small figures document (TEST DATA): the kinds of figure a run has."""
    figs = {
        "table4.outliers.calibrated": F.figure(55, F.LOWER, "t4.csv", ("abs", 0), of=96),
        "validation.independent.within": F.figure(7, F.HIGHER, "v.csv", ("abs", 0), of=18),
        "report.first_page_words": F.figure(235, F.LOWER, "paper.html", ("abs", 10)),
        "muscle.in_vivo_r2": F.figure(0.95, F.HIGHER, "m.json", ("abs", 0.02)),
        "discovery.library_accuracy": F.figure(0.9, F.HIGHER, "b.json", ("rel", 0.05)),
        "landmark_accuracy.group_median_mm": F.absent(F.LOWER, "l.csv", "not built", ("abs", 0.1)),
        "job_time_s.calibrate": F.figure(17.7, F.INFO, "calibrate.tsv"),
    }
    for k, v in values.items():
        figs[k.replace("__", ".")]["value"] = v
    return {"note": "TEST DATA", "figures": figs}


def test_identical_figures_pass():
    res = F.compare(doc(), doc())
    assert res.ok and not res.improvements and not res.new, res.report()


def test_a_worsened_figure_fails_naming_figure_old_new_and_tolerance():
    res = F.compare(doc(), doc(table4__outliers__calibrated=56))
    assert not res.ok
    assert res.regressions == [res.failures()[0]]
    line = res.regressions[0]
    assert line.startswith("table4.outliers.calibrated: old 55, new 56, tolerance 0") and "lower is better" in line
    # a higher-is-better figure the other way round, and a relative tolerance exceeded
    assert not F.compare(doc(), doc(validation__independent__within=6)).ok
    res = F.compare(doc(), doc(discovery__library_accuracy=0.85))       # 0.9 - 0.85 > 5 % of 0.9
    assert not res.ok and "tolerance 5 %" in res.regressions[0]


def test_a_worse_value_within_its_tolerance_passes():
    """The control of the tolerance: 9 more words on the first page (tolerance 10) and a share 4 % lower (5 %)."""
    assert F.compare(doc(), doc(report__first_page_words=244, discovery__library_accuracy=0.865)).ok
    assert not F.compare(doc(), doc(report__first_page_words=246)).ok


def test_an_improved_figure_passes_and_asks_for_the_reference_to_be_updated():
    res = F.compare(doc(), doc(table4__outliers__calibrated=50, muscle__in_vivo_r2=0.99))
    assert res.ok
    assert [x.split(":")[0] for x in res.improvements] == ["table4.outliers.calibrated", "muscle.in_vivo_r2"]
    assert "update the reference" in res.report()


def test_a_worse_value_accepted_with_a_reason_passes_and_without_one_is_refused():
    ref = doc(table4__outliers__calibrated=58)
    ref["figures"]["table4.outliers.calibrated"].update(was=55, reason="the MAP calibration trades Table 4 for "
                                                                      "admissibility (docs/load_sharing.md)")
    res = F.compare(ref, doc(table4__outliers__calibrated=58))
    assert res.ok and len(res.accepted) == 1 and "was 55" in res.accepted[0] and "admissibility" in res.accepted[0]
    # held at the accepted value: worse again fails
    assert not F.compare(ref, doc(table4__outliers__calibrated=59)).ok
    # controls: the same edit of the reference without a reason, with an empty one, with a paragraph
    for bad in (None, "", "first line\nsecond line"):
        r = copy.deepcopy(ref)
        if bad is None:
            del r["figures"]["table4.outliers.calibrated"]["reason"]
        else:
            r["figures"]["table4.outliers.calibrated"]["reason"] = bad
        res = F.compare(r, doc(table4__outliers__calibrated=58))
        assert not res.ok and res.invalid and res.invalid[0].startswith("table4.outliers.calibrated"), bad


def test_a_missing_figure_is_reported():
    cur = doc()
    del cur["figures"]["validation.independent.within"]
    cur["figures"]["muscle.in_vivo_r2"] = F.absent(F.HIGHER, "m.json", "file not in this run")
    res = F.compare(doc(), cur)
    assert not res.ok
    assert [x.split(":")[0] for x in res.missing] == ["validation.independent.within", "muscle.in_vivo_r2"]
    assert "file not in this run" in res.missing[1]
    # absent in both: nothing to hold the run to (a stage off in this configuration)
    assert "landmark_accuracy" not in res.report()


def test_job_times_are_never_compared_and_a_changed_basis_is_a_decision():
    assert F.compare(doc(), doc(job_time_s__calibrate=1000.0)).ok
    cur = doc()
    cur["figures"]["validation.independent.within"]["of"] = 19
    res = F.compare(doc(), cur)
    assert not res.ok and "basis changed" in res.invalid[0]


def test_update_reference_keeps_reasons_and_asks_for_one_when_worse():
    ref = doc()
    ref["figures"]["report.first_page_words"].update(was=220, reason="one line")
    new = F.update_reference(ref, doc(table4__outliers__calibrated=60))
    f = new["figures"]
    assert f["table4.outliers.calibrated"]["value"] == 60 and f["table4.outliers.calibrated"]["was"] == 55
    assert f["table4.outliers.calibrated"]["reason"] == ""            # to be filled in: refused until then
    assert not F.compare(new, doc(table4__outliers__calibrated=60)).ok
    assert f["report.first_page_words"]["reason"] == "one line"      # same value: the reason stays
    assert "job_time_s.calibrate" not in f and "informational" in new["note"]


def test_collect_on_a_run_without_results_gives_absent_entries(tmp_path):
    """Every stage switched off: every figure is an explicit absent entry, never an error. Control: with the
    validation table present its counts are read."""
    root = tmp_path / "results"
    figs = F.collect(root)["figures"]
    assert figs and all(v["value"] is None and v.get("absent") for v in figs.values()), figs
    assert {"validation.independent.within", "table4.outliers", "discovery.library_accuracy", "muscle.in_vivo_r2",
            "admissibility.passed", "landmark_accuracy.group_median_mm", "report.first_page_words",
            "job_time_s.total"} <= set(figs)
    (root / "tables").mkdir(parents=True)
    pd.DataFrame({"quantity": ["q", "q", "r"], "condition": ["a", "b", "c"], "unit": "deg", "sim": [1.0, 2.0, 3.0],
                  "measured": [1.0, 2.5, 9.0], "measured_low": float("nan"), "measured_high": float("nan"),
                  "within": [True, True, False], "tolerance_rule": "measured +- 25 %", "set": "calibrated",
                  "role": ["independent", "independent", "calibration target"], "kind": "x", "source": "y",
                  "note": ""}).to_csv(root / "tables" / "validation_real_data.csv", index=False)
    (root / "benchmarks").mkdir()
    (root / "benchmarks" / "calibrate.tsv").write_text("s\th:m:s\n17.5\t0:00:17\n")
    figs = F.collect(root)["figures"]
    assert figs["validation.independent.within"]["value"] == 2 and figs["validation.independent.within"]["of"] == 2
    assert figs["validation.calibration_target.within"]["value"] == 0
    assert figs["job_time_s.calibrate"] == {"value": 17.5, "direction": "informational", "unit": "s",
                                            "file": (root / "benchmarks" / "calibrate.tsv").as_posix()}


def test_first_page_words_counts_up_to_the_scoreboard_figure():
    page = ('<html><head><title>not counted</title><style>p{x:y}</style></head><body><h1>A title</h1>'
            '<p class="abstract">Five words, one <a href="#x">link</a> - here.</p>'
            '<figure><img data-source="../figures/validation_scoreboard.png" src="x"></figure><p>after</p></body>')
    assert F.first_page_words(page) == 2 + 5                 # "-" is no word
    assert F.first_page_words(page.replace("validation_scoreboard", "other")) is None       # control: no figure


def test_records_file_keeps_one_record_per_commit_and_prints_the_last_two(tmp_path):
    hist = tmp_path / "figures_default.json"
    hist.write_text(json.dumps({"note": "TEST DATA", "records": []}))
    F.write_figures(doc(), hist, commit="aaa1111")
    F.write_figures(doc(table4__outliers__calibrated=50), hist, commit="bbb2222")
    F.write_figures(doc(table4__outliers__calibrated=49), hist, commit="bbb2222")        # the same commit again
    h = json.loads(hist.read_text())
    assert [r["commit"] for r in h["records"]] == ["aaa1111", "bbb2222"]
    md = F.side_by_side(h)
    assert "| figure | better | `aaa1111` | `bbb2222` |" in md
    assert "| `table4.outliers.calibrated` | lower | 55 of 96 | 49 of 96 |" in md
    assert "| `landmark_accuracy.group_median_mm` | lower | absent | absent |" in md
    assert "job_time_s.calibrate" not in md
    # a path without records gets the document itself
    F.write_figures(doc(), tmp_path / "plain.json")
    assert "figures" in json.loads((tmp_path / "plain.json").read_text())


def test_reference_is_valid_and_says_job_times_are_informational():
    ref = json.loads(REFERENCE.read_text())
    assert "informational" in ref["note"] and "machines differ" in ref["note"]
    assert F.compare(ref, ref).ok and not F.compare(ref, ref).invalid
    times = {k: v for k, v in ref["figures"].items() if k.startswith("job_time_s.")}
    assert times and all(v["direction"] == F.INFO for v in times.values())
    compared = [k for k, v in ref["figures"].items() if v["direction"] != F.INFO]
    assert all("tolerance" in ref["figures"][k] for k in compared)


def test_dag_figures_of_record_no_worse_than_the_reference(dag_workdir):
    """The ratchet: the test-config DAG's figures (rule figures_of_record) against the committed reference. On an
    improvement, update the reference in the same commit; on a worse value accepted on purpose, a one-line reason
    beside it (docs/benchmarks.md, "Figures of record")."""
    path = dag_workdir / "results" / "figures_of_record.json"
    cur = json.loads(path.read_text())
    res = F.compare(json.loads(REFERENCE.read_text()), cur)
    how = (f"\nThe run's figures: {path}. Update the reference: python -m lumbar.report.figures_of_record --results "
           f"{dag_workdir / 'results'} --update-reference {REFERENCE.relative_to(ROOT)}")
    assert res.ok, res.report() + how
    if res.improvements or res.new:
        warnings.warn(res.report() + how, stacklevel=1)
    words = cur["figures"]["report.first_page_words"]["value"]
    assert words is not None and words <= F.FIRST_PAGE_MAX_WORDS, words


@pytest.mark.parametrize("name", ["validation.independent.within", "table4.outliers.calibrated",
                                  "report.first_page_words", "job_time_s.total"])
def test_dag_figures_of_record_read_the_run(dag_workdir, name):
    """Every kind of figure of the test-config run has a value (the run builds its stage) read from its file."""
    cur = json.loads((dag_workdir / "results" / "figures_of_record.json").read_text())["figures"]
    assert cur[name]["value"] is not None and (dag_workdir / cur[name]["file"]).exists(), cur[name]


def test_docs_show_the_last_two_release_records_of_the_default_run():
    """docs/benchmarks.md's side-by-side table is the one benchmarks/results/figures_default.json gives (written by
    ``--markdown ... --doc``; it cannot go stale). Control: a doctored history changes the table."""
    hist = json.loads((ROOT / "benchmarks" / "results" / "figures_default.json").read_text())
    assert isinstance(hist["records"], list) and "--out benchmarks/results/figures_default.json" in hist["note"]
    text = (ROOT / "docs" / "benchmarks.md").read_text()
    assert F.doc_with_table(text, hist) == text, "docs/benchmarks.md: rewrite the table with --markdown ... --doc"
    doctored = {"records": hist["records"] + [{"commit": "abc1234", "figures": doc()["figures"]}]}
    assert F.doc_with_table(text, doctored) != text
    with pytest.raises(ValueError, match="no block"):
        F.doc_with_table("no markers", hist)
