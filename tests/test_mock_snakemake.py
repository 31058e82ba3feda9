"""Output paths live only in the rules (workflow/rules/*.smk): the workflow scripts read ``snakemake.input`` /
``snakemake.output``, and by hand (``python workflow/scripts/<rule>.py <rule> [wildcard=value ...]``)
``_common.mock_snakemake`` builds that object from the Snakefile itself, as PyPSA-Eur does.
"""
import importlib.util
import re
import subprocess
import sys

import pytest

from conftest import ROOT

SCRIPTS = ROOT / "workflow" / "scripts"
TEST_CONFIG = "config/test/config.yaml"
STAGE_SCRIPTS = sorted(p for p in SCRIPTS.glob("*.py") if p.name != "_common.py")


@pytest.fixture(scope="module")
def common():
    spec = importlib.util.spec_from_file_location("_common_under_test", SCRIPTS / "_common.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("script", STAGE_SCRIPTS, ids=lambda p: p.name)
def test_scripts_do_not_mirror_their_rules(script):
    text = script.read_text()
    assert not re.search(r"^RULES\s*=", text, re.M), f"{script.name}: a RULES mirror of the rules"
    assert "stand_in" not in text and "importlib" not in text
    paths = re.findall(r"""["'](?:results|logs)/[^"']*""", text)
    assert not paths, f"{script.name} spells result/log paths (they belong to the rules): {paths}"
    assert "snakemake, log = _common.start(globals())" in text
    # one script per rule: rules of a family share library functions
    assert not re.search(r"\brule\s*==", text), f"{script.name} dispatches on snakemake.rule"


def test_one_script_per_rule(common, in_root):
    """Every ``script:`` of the workflow serves one rule, and every script in the folder is some rule's (a family of
    rules shares library functions, not a script). Control: two rules naming one script fail here."""
    workflow = common._workflow(TEST_CONFIG)
    rules_of = {}
    for r in workflow.rules:
        if r.is_script:
            rules_of.setdefault(common._rule_script(r).name, []).append(r.name)
    shared = {script: rules for script, rules in rules_of.items() if len(rules) > 1}
    assert not shared, f"scripts serving several rules: {shared}"
    assert sorted(rules_of) == [p.name for p in STAGE_SCRIPTS]


@pytest.fixture
def in_root(monkeypatch):
    monkeypatch.chdir(ROOT)           # as Snakemake: the rules' relative paths are relative to the working directory


def test_mock_snakemake_gives_the_rules_outputs(common, in_root):
    fsu = common.mock_snakemake("fsu_rom", TEST_CONFIG)
    assert list(fsu.output) == ["results/tables/fsu_rom_intact.csv"]
    assert list(fsu.log) == ["logs/fsu_rom.log"] and fsu.rule == "fsu_rom" and fsu.threads == 1
    assert fsu.params.sets == fsu.config["characteristics"]["sets"]
    assert fsu.config["fsu"]["level"]                              # validated and completed by common.smk

    t5 = common.mock_snakemake("table5", TEST_CONFIG)
    assert t5.output.synopsis == "results/tables/table5_idp_synopsis.csv"
    assert t5.output.fig7 == "results/figures/fig7_idp.png" and len(t5.output) == 6
    assert list(t5.input.sims) == [f"results/l2s1/idp_{s}.csv" for s in t5.config["l2s1"]["sets"]]
    assert t5.params.published == t5.config["paths"]["published_model_results"]

    sob = common.mock_snakemake("muscle_sobol_chunk", TEST_CONFIG, posture="standing", chunk=0)
    assert list(sob.output) == ["results/muscle_model/sobol/standing_0.csv"]
    assert list(sob.log) == ["logs/muscle_sobol_chunk/standing_0.log"]
    assert (sob.wildcards.posture, sob.wildcards.chunk) == ("standing", "0")
    assert sob.input.baseline == "results/muscle_model/baseline.npz" and sob.params.seed == sob.config["seed"]

    # the surrogate's path is written once, in its rule; the calibration reads it through rules.<name>.output
    sur = common.mock_snakemake("stepwise_reduction_surrogate", TEST_CONFIG)
    cal = common.mock_snakemake("calibrate", TEST_CONFIG)
    assert sur.output.table == "results/experiments/stepwise_reduction_surrogate.csv"
    assert cal.input.experiment == sur.output.table
    assert len(cal.output) == 19 and len(cal.output.characteristics) == 6


def test_mock_snakemake_rejects_wrong_wildcards(common, in_root):
    with pytest.raises(ValueError, match="give chunk="):
        common.mock_snakemake("muscle_sobol_chunk", TEST_CONFIG, posture="standing")
    with pytest.raises(ValueError, match="wildcard constraints"):
        common.mock_snakemake("muscle_sobol_chunk", TEST_CONFIG, posture="sitting", chunk=0)
    with pytest.raises(ValueError, match="no rule 'nope'"):
        common.mock_snakemake("nope", TEST_CONFIG)


def test_by_hand_command_line(common, in_root, tmp_path, capsys):
    out = tmp_path / "sub" / "idp.csv"
    smk = common.from_command_line(SCRIPTS / "l2s1_idp.py", "", ["l2s1_idp", "set=rupp2015", "--configfile",
                                                             TEST_CONFIG, "--output", str(out)])
    assert list(smk.output) == [str(out)] and out.parent.is_dir()     # the folder is made, as Snakemake does
    assert smk.wildcards.set == "rupp2015" and list(smk.log) == []      # by hand: stderr unless --log
    t4 = common.from_command_line(SCRIPTS / "table4.py", "", [
        "table4", "--configfile", TEST_CONFIG, "--output", *(str(tmp_path / f"t{i}") for i in range(4)),
        "--log", str(tmp_path / "t4.log")])
    assert t4.output.grid == str(tmp_path / "t3") and list(t4.log) == [str(tmp_path / "t4.log")]  # names kept
    for script, argv, needle in (("l2s1_idp.py", ["fsu_rom"], "does not run l2s1_idp.py; its rules: l2s1_idp"),
                                 ("l2s1_idp.py", ["l2s1_idp"], "give set=..."),
                                 ("table5.py", ["table5", "--output", "a.csv"], "rule table5 has 6 output(s)")):
        with pytest.raises(SystemExit):
            common.from_command_line(SCRIPTS / script, "", argv + ["--configfile", TEST_CONFIG])
        assert needle in capsys.readouterr().err


def _dry_run_jobs():
    """(rule, wildcards, input, output, log) of every job that ``snakemake -n --forceall`` lists."""
    r = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--forceall", "--configfile", TEST_CONFIG],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    jobs = []
    for block in re.split(r"^(?=(?:local)?rule \w+:$)", r.stdout, flags=re.M)[1:]:
        rule = re.match(r"(?:local)?rule (\w+):", block).group(1)
        field = dict(re.findall(r"^    (\w+): (.*)$", block, re.M))

        def items(key, sep=", "):
            return field[key].split(sep) if key in field else []

        wildcards = dict(w.split("=", 1) for w in items("wildcards"))
        jobs.append((rule, wildcards, items("input"), items("output"), items("log")))
    return jobs


@pytest.mark.workflow
def test_every_script_job_by_hand_equals_snakemakes(common, in_root):
    """For every job of a rule with ``script:`` in the test configuration's DAG, the object a by-hand run gets has
    Snakemake's inputs, outputs and log, in Snakemake's order."""
    workflow = common._workflow(TEST_CONFIG)                 # parsed once; mock_snakemake = _workflow + _job
    scripted = {r.name for r in workflow.rules if r.is_script}
    seen = set()
    for rule, wildcards, inputs, outputs, logs in _dry_run_jobs():
        if rule not in scripted:
            continue
        seen.add(rule)
        smk = common._job(workflow, rule, wildcards)
        assert (list(smk.input), list(smk.output), list(smk.log)) == (inputs, outputs, logs), (rule, wildcards)
    assert len(seen) >= 25, sorted(seen)
    rules = {r.name: r for r in workflow.rules}
    for rule in scripted - seen:                  # not in this configuration's DAG (discovery_idp_model): builds
        wildcards = {w: "0" for w in rules[rule].wildcard_names}      # e.g. the part of a fixture stream
        assert list(common._job(workflow, rule, wildcards).output), rule


@pytest.mark.parametrize("preset", [None, "3"])
def test_by_hand_scripts_use_one_blas_thread_as_snakemake_jobs(preset):
    """Importing the scripts' _common sets the BLAS/OpenMP thread variables to 1 (a rule's one thread) before numpy
    is loaded, and keeps a value already set (Snakemake's, or the user's): control, preset 3 stays 3."""
    import os
    env = {k: v for k, v in os.environ.items() if not k.endswith(("_NUM_THREADS", "_MAXIMUM_THREADS"))}
    if preset:
        env["OPENBLAS_NUM_THREADS"] = preset
    code = ("import sys; sys.path.insert(0, 'workflow/scripts'); import _common, os; "
            "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [preset or "1", "1"]
