"""The stage manifests (lumbar.inputs.manifests) and the run prefix (config run.name).

Every output is declared once, by role; the workflow's rule outputs, final outputs and the report's look-ups derive
from the manifests, so no ``results/`` path is typed anywhere else. ``run: {name: X}`` moves every output under
``results/X/`` and every log under ``logs/X/``; the empty name keeps today's paths. Adding a stage is four files: a
manifest entry, a rule file, a script and a report section (docs/design.md, "Adding a stage"): the toy-stage test
follows that recipe in a copy of the repository.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import ROOT, copy_repo
from lumbar.inputs import manifests as M

TEST_CONFIG = "config/test/config.yaml"


# ----------------------------------------------------------------------------------------------- helpers
def typed_results_paths(text: str) -> list[str]:
    """Every ``results/`` path typed in a text (what a reviewer greps for)."""
    return re.findall(r"results/[\w{}<>./-]*", text)


def duplicate_paths(manifests: dict) -> list[str]:
    """Paths that two roles declare (a file must have one owner)."""
    seen, dup = {}, []
    for stage, m in manifests.items():
        for role, o in m.outputs.items():
            for p in o.paths():
                if p in seen:
                    dup.append(f"{p}: {seen[p]} and {stage}.{role}")
                seen[p] = f"{stage}.{role}"
    return dup


def dry_run_files(text: str, fields=("output", "log", "benchmark")) -> set[tuple[str, str, str]]:
    """(rule, field, path) of every job of a ``snakemake -n`` listing."""
    rows, rule = set(), None
    for line in text.splitlines():
        m = re.match(r"^(?:local)?(?:rule|checkpoint) (\S+):", line)
        if m:
            rule = m.group(1)
            continue
        m = re.match(r"^\s+(\w+): (.*)$", line)
        if m and rule and m.group(1) in fields:
            rows |= {(rule, m.group(1), p.strip()) for p in m.group(2).split(", ")}
    return rows


def smk(*args, cwd=ROOT, env=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=env)


# ----------------------------------------------------------------------------------------------- the manifests
def test_results_root_follows_the_run_name():
    assert M.results_root({}) == M.results_root({"run": {"name": ""}}) == "results"
    assert M.logs_root({}) == "logs"
    assert M.results_root({"run": {"name": "spec"}}) == "results/spec"
    assert M.logs_root({"run": {"name": "spec"}}) == "logs/spec"
    default, named = M.final_outputs(), M.final_outputs("results/spec")
    assert len(default) == len(named) > 40
    for d, n in zip(default, named):
        assert d.startswith("results/") and not d.startswith("results/spec/")
        assert n == "results/spec/" + d[len("results/"):]
        assert M.reroot(d, "results/spec") == n


def test_reroot_moves_only_results_paths():
    assert M.reroot("results/tables/x.csv", "results/spec") == "results/spec/tables/x.csv"
    assert M.reroot("results/tables/x.csv", "results") == "results/tables/x.csv"
    assert M.reroot("data/experiments/x.csv", "results/spec") == "data/experiments/x.csv"
    assert M.reroot("results_old/x.csv", "results/spec") == "results_old/x.csv"


@pytest.mark.parametrize("name", ["a/b", "..", "../x", ".hidden", "a b", "x/"])
def test_bad_run_name_is_refused_naming_the_key(name):
    with pytest.raises(ValueError, match=r"run\.name.*expected"):
        M.results_root({"run": {"name": name}})


@pytest.mark.parametrize("name", ["spec", "spec_1.v2", "morphable_mean", "A-1"])
def test_good_run_name_is_accepted(name):          # the control of the test above
    assert M.results_root({"run": {"name": name}}) == f"results/{name}"


def test_every_path_has_one_owner_and_every_caption_exists():
    assert duplicate_paths(M.MANIFESTS) == []
    # control: the checker finds a second owner
    fake = dict(M.MANIFESTS, twin=M.Manifest("twin", {"x": M.Output("tables/fsu_geometry.csv", "twin")}))
    assert duplicate_paths(fake) == ["results/tables/fsu_geometry.csv: geometry.table and twin.x"]
    for stage, m in M.MANIFESTS.items():
        assert (ROOT / m.rules_path).is_file(), m.rules_path
        for role, o in m.outputs.items():
            if o.caption:
                assert (ROOT / "workflow" / "report" / f"{o.caption}.rst").is_file(), f"{stage}.{role}"
                assert o.category, f"{stage}.{role}: a report item needs a category"
            assert o.report in (None, "optional"), f"{stage}.{role}"


def test_rule_outputs_of_the_workflow_are_the_manifests():
    """Every rule of a manifest is defined in its stage's rule file and writes its outputs with stage_outputs."""
    for stage, m in M.MANIFESTS.items():
        text = (ROOT / m.rules_path).read_text()
        for rule in m.rules():
            if rule == "docs_numbers":                # one output per doc template: doc_outputs()
                continue
            body = re.search(rf"^rule {rule}:\n(.*?)(?=^\S|\Z)", text, re.M | re.S)
            assert body, f"rule {rule} of stage {stage} is not in {m.rules_path}"
            assert re.search(rf"\*\*(?:stage_outputs\(\s*\"{stage}\",\s*\"{rule}\"|discovery_case_outputs\()",
                             body.group(1)), f"rule {rule}: outputs not from its manifest"


def test_no_results_path_typed_outside_the_manifests():
    """The reviewer's grep: no results/ path in the library (but the manifests) nor in the rule files."""
    found = []
    files = [p for p in (ROOT / "src" / "lumbar").rglob("*.py") if p.name != "manifests.py"]
    files += sorted((ROOT / "workflow" / "rules").glob("*.smk")) + [ROOT / "Snakefile"]
    for p in files:
        found += [f"{p.relative_to(ROOT)}: {x}" for x in typed_results_paths(p.read_text())]
    assert found == []
    # control: the grep sees a typed path
    assert typed_results_paths('T = "results/tables/"\n') == ["results/tables/"]


def test_report_finds_files_by_role_under_the_run_root(tmp_path, monkeypatch):
    """The report reads a stage's table at its role's path under the run's root, not at a typed path."""
    from lumbar.inputs.config import load_config
    from lumbar.report import NOT_BUILT, build_document

    monkeypatch.chdir(tmp_path)
    counts = Path(M.path("stepwise_reduction", "counts", "results/spec"))
    counts.parent.mkdir(parents=True)
    counts.write_text("set,n_scenarios,n_outliers,n_not_converged,data_kinds\ncalibrated,160,17,0,surrogate\n")
    config = load_config(ROOT / TEST_CONFIG)

    def summary(run_name):
        cfg = dict(config, run={"name": run_name})
        doc, _ = build_document([str(counts)], cfg, tmp_path / "out" / "paper.html")
        return " ".join(getattr(x, "text", "") for x in doc.blocks)

    assert "calibrated (this model) 17 of 160" in summary("spec")
    # control: the same file read as the default run's is not its file
    text = summary("")
    assert "calibrated (this model) 17 of 160" not in text
    assert f"Stepwise reduction, forward simulation (Table 4 analog): {NOT_BUILT}" in text


# ----------------------------------------------------------------------------------------------- the run prefix
@pytest.mark.workflow
def test_named_run_dry_run_lists_only_its_own_outputs():
    """run.name spec: the same jobs as the default run, every output, log and benchmark moved under results/spec/ and
    logs/spec/, every result read from there; the default dry run is unchanged (its files under results/ directly)."""
    named = smk("-n", "--forceall", "--configfile", TEST_CONFIG, "--config", "run={name: spec}")
    default = smk("-n", "--forceall", "--configfile", TEST_CONFIG)
    assert named.returncode == 0, named.stdout[-3000:] + named.stderr[-3000:]
    assert default.returncode == 0, default.stdout[-3000:] + default.stderr[-3000:]
    n_files, d_files = dry_run_files(named.stdout), dry_run_files(default.stdout)
    assert len(n_files) == len(d_files) > 100
    assert all(p.startswith(("results/spec/", "logs/spec/")) for _, _, p in n_files)
    moved = {(r, f, M.reroot(p, "results/spec") if f != "log" else "logs/spec/" + p[len("logs/"):])
             for r, f, p in d_files}
    assert moved == n_files
    # every result file a named run reads is its own
    n_inputs = {p for _, _, p in dry_run_files(named.stdout, ("input",))}
    assert {p for p in n_inputs if p.startswith("results/") and not p.startswith("results/spec/")} == set()
    # control: the default run writes under results/ itself, never under results/spec/
    assert not any(p.startswith("results/spec/") for _, _, p in d_files)
    assert any(p == "results/tables/table4_outlier_counts.csv" for _, _, p in d_files)


@pytest.mark.workflow
def test_bad_run_name_fails_the_dry_run_naming_the_key():
    r = smk("-n", "--configfile", TEST_CONFIG, "--config", "run={name: ../elsewhere}")
    assert r.returncode != 0
    assert "run.name = '../elsewhere'" in r.stdout + r.stderr


@pytest.mark.workflow
def test_default_report_skips_other_runs_logs(tmp_path):
    """The default run's Flags list its rules' warnings (logs/<rule>/...), not a named run's (logs/<name>/)."""
    repo = copy_repo(tmp_path / "repo")
    for folder, text in (("muscle_sensitivity", "WARNING own rule's warning"),
                         ("spec", "WARNING another run's warning")):
        (repo / "logs" / folder).mkdir(parents=True)
        (repo / "logs" / folder / "x.log").write_text(text + "\n")
    r = subprocess.run([sys.executable, "workflow/scripts/paper_report.py", "paper_report", "--configfile",
                        TEST_CONFIG, "--output", "out/p.html", "out/p.pdf"], cwd=repo, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    html = (repo / "out" / "p.html").read_text()
    assert "own rule&#x27;s warning" in html or "own rule's warning" in html
    assert "another run" not in html


# ----------------------------------------------------------------------------------------------- a new stage
TOY_MANIFEST = '''    Manifest("toy", {
        "table": _o("toy/toy_table.csv", "toy_stage", final=True),
    }, report_module="lumbar.report.toy_section"),
'''
TOY_RULES = '''rule toy_stage:
    output:
        **stage_outputs("toy", "toy_stage"),
    log:
        log_file("toy_stage"),
    params:
        scale=2.0,
    script:
        "../scripts/toy_stage.py"
'''
TOY_SCRIPT = '''"""Toy stage, rule toy_stage: a one-column table (the recipe of docs/design.md, "Adding a stage")."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402


def main(snakemake, log):
    Path(snakemake.output.table).write_text(f"quantity,value_nm\\ntoy moment,{3 * snakemake.params.scale}\\n")
    log.info("toy table written")


if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
'''
TOY_SECTION = '''"""Report section "Toy stage": its table, found by its manifest role."""
from .sections import ReportBuilder, report_section


@report_section("toy", "Toy stage", after="discrepancy")
def toy_section(b: ReportBuilder):
    b.csv_table(b.out("toy", "table"), "The toy table")
'''


@pytest.mark.workflow
def test_a_toy_stage_is_four_files(tmp_path):
    """The recipe of docs/design.md on a toy stage in a copy of the repository: a manifest entry, a rule file, a
    script and a report section. The dry run lists its output in the default target and the report's inputs; its
    job runs; the report section is found through the registry and shows the table."""
    repo = copy_repo(tmp_path / "repo")
    env = dict(os.environ, PYTHONPATH=str(repo / "src"))
    (repo / "workflow" / "rules" / "toy.smk").write_text(TOY_RULES)
    (repo / "workflow" / "scripts" / "toy_stage.py").write_text(TOY_SCRIPT)
    (repo / "src" / "lumbar" / "report" / "toy_section.py").write_text(TOY_SECTION)
    # control: without its manifest entry the stage is not part of the workflow
    before = smk("-n", "--forceall", "--configfile", TEST_CONFIG, cwd=repo, env=env)
    assert before.returncode == 0, before.stderr[-3000:]
    assert not [f for f in dry_run_files(before.stdout, ("input", "output")) if "toy_table" in f[2]]

    man = repo / "src" / "lumbar" / "inputs" / "manifests.py"
    text = man.read_text()
    anchor = '    Manifest("report", {'
    assert text.count(anchor) == 1
    man.write_text(text.replace(anchor, TOY_MANIFEST + anchor))

    after = smk("-n", "--forceall", "--configfile", TEST_CONFIG, cwd=repo, env=env)
    assert after.returncode == 0, after.stdout[-3000:] + after.stderr[-3000:]
    files = dry_run_files(after.stdout, ("input", "output"))
    assert ("toy_stage", "output", "results/toy/toy_table.csv") in files
    assert ("all", "input", "results/toy/toy_table.csv") in files
    assert ("paper_report", "input", "results/toy/toy_table.csv") in files

    job = smk("results/toy/toy_table.csv", "--cores", "1", "--configfile", TEST_CONFIG, cwd=repo, env=env)
    assert job.returncode == 0, job.stdout[-3000:] + job.stderr[-3000:]
    probe = textwrap.dedent("""
        from lumbar.inputs.config import load_config
        from lumbar.report import SECTIONS, build_document
        anchors = [s.anchor for s in SECTIONS]
        assert anchors.index("toy") == anchors.index("discrepancy") + 1, anchors
        doc, _ = build_document(["results/toy/toy_table.csv"], load_config("config/test/config.yaml"), "out/p.html")
        print([getattr(x, "rows", None) for x in doc.blocks if "toy table" in str(getattr(x, "title", ""))])
    """)
    r = subprocess.run([sys.executable, "-c", probe], cwd=repo, capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "[[['toy moment', '6']]]" in r.stdout
