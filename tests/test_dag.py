"""The whole default DAG on config/test (fixture ``dag_workdir`` in conftest.py, run once per session):
every final output exists, a second run in a fresh copy is byte-identical, a re-run is a no-op,
a config change re-runs only its dependents, and a deleted intermediate is rebuilt with its dependents only.

Cost: the fixture's run plus one more full run (reproducibility); the rest are dry runs (~3 s each)
and one small resume run.
"""
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import TEST_CONFIG, run_dag, snakemake

# compared byte for byte between two runs (results/benchmarks holds timings and is not compared, nor the figures of
# record, which quote them)
COMPARED = (".csv", ".json", ".png", ".pdf", ".html", ".svg", ".txt", ".tsv")
TIMED = ("figures_of_record.json",)


def dry_jobs(workdir, *args) -> set[tuple[str, str]]:
    """Jobs a dry run would execute, as (rule, wildcards) pairs; empty when nothing is to be done."""
    r = snakemake("-n", "--configfile", TEST_CONFIG, *args, cwd=workdir, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    return parse_jobs(out)


def parse_jobs(out: str) -> set[tuple[str, str]]:
    jobs, current = set(), None
    for line in out.splitlines():
        m = re.match(r"^(?:local)?rule (\S+):$", line)
        if m:
            if current:
                jobs.add(tuple(current))
            current = [m.group(1), ""]
        elif current and line.strip().startswith("wildcards:"):
            current[1] = line.split(":", 1)[1].strip()
    if current:
        jobs.add(tuple(current))
    return jobs


def final_outputs(workdir) -> list[str]:
    """The input files of rule ``all`` (common.smk's final_outputs()), from a forced dry run."""
    r = snakemake("all", "-n", "--forceall", "--configfile", TEST_CONFIG, cwd=workdir, timeout=300)
    m = re.search(r"^(?:local)?rule all:\n\s+input: (.+)$", r.stdout, re.M)
    assert m, r.stdout + r.stderr
    return [s.strip() for s in m.group(1).split(",")]


def result_files(workdir: Path) -> dict[str, bytes]:
    res = workdir / "results"
    return {str(p.relative_to(workdir)): p.read_bytes() for p in sorted(res.rglob("*"))
            if p.is_file() and p.suffix.lower() in COMPARED and "benchmarks" not in p.relative_to(res).parts
            and p.name not in TIMED}


@pytest.fixture
def dag_copy(dag_workdir, tmp_path):
    """A copy of the finished DAG workdir (results, logs and .snakemake metadata, mtimes kept) to modify."""
    dest = tmp_path / "repo"
    shutil.copytree(dag_workdir, dest, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
    return dest


def test_dag_every_final_output_exists_and_is_not_empty(dag_workdir):
    targets = final_outputs(dag_workdir)
    assert len(targets) >= 20, targets
    # a folder output (the OpenSim export's models) counts when it holds files
    missing = [t for t in targets if not ((dag_workdir / t).is_file() or
                                          ((dag_workdir / t).is_dir() and any((dag_workdir / t).iterdir())))]
    empty = [t for t in targets if (dag_workdir / t).is_file() and (dag_workdir / t).stat().st_size == 0]
    assert not missing and not empty, f"missing: {missing}; empty: {empty}"
    leftovers = [str(p) for p in (dag_workdir / "results").rglob("*.tmp")]
    assert leftovers == [], "temporary files of atomic writes left behind"
    # one value per stage's headline table, not only the files: the intact ROM of every set converged and
    # rises with the moment (pure-moment ROM of a passive unit), within 0-20 deg (lumbar L4-L5, 7.5 N*m)
    import pandas as pd
    rom = pd.read_csv(dag_workdir / "results/tables/fsu_rom_intact.csv")
    assert rom["converged"].all() and len(rom) > 0
    for (st, d), g in rom.groupby(["set", "direction"]):
        r = g.sort_values("moment_nm")["rom_deg"].to_numpy()
        assert (np.diff(r) > 0).all() and 0 < r[0] and r[-1] < 20, (st, d, r)
    # Table 5 counts are the synopsis's outlier flags; Table 4 likewise
    for syn, counts, col in (("table4_rom_synopsis", "table4_outlier_counts", "n_outliers"),
                             ("table5_idp_synopsis", "table5_outlier_counts", "outliers")):
        sy = pd.read_csv(dag_workdir / f"results/tables/{syn}.csv")
        co = pd.read_csv(dag_workdir / f"results/tables/{counts}.csv").set_index("set")[col]
        assert co.to_dict() == sy.groupby("set")["outlier"].sum().to_dict(), syn


def test_dag_reproducible_byte_identical(dag_workdir, dag_second_workdir):
    """Two runs of the test-config DAG in two fresh copies (two directories) give identical tables, JSON
    and figure bytes (results/benchmarks, which holds timings, is not compared). The second run builds the model
    chain (conftest.SECOND_RUN_TARGETS: every stage but the muscle sensitivity and Sobol chunks, the discovery
    benchmark and the report, which have their own determinism tests); every file it wrote is compared."""
    a, b = result_files(dag_workdir), result_files(dag_second_workdir)
    assert set(b) <= set(a), sorted(set(b) - set(a))
    assert len(b) >= 50 and len(b) >= len(a) // 3, (len(b), len(a))
    differ = sorted(k for k in b if a[k] != b[k])
    assert differ == [], f"{len(differ)} of {len(b)} result files differ between two runs: {differ}\n" + \
        "\n".join(first_difference(a[k], b[k], k) for k in differ)


def first_difference(x: bytes, y: bytes, name: str) -> str:
    i = next((j for j in range(min(len(x), len(y))) if x[j] != y[j]), min(len(x), len(y)))
    return f"{name}: {len(x)} vs {len(y)} bytes, first difference at byte {i}: {x[max(0, i - 80):i + 80]!r} vs " \
           f"{y[max(0, i - 80):i + 80]!r}"


def test_dag_rerun_is_noop(dag_workdir):
    r = snakemake("-n", "--configfile", TEST_CONFIG, cwd=dag_workdir, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Nothing to be done" in r.stdout + r.stderr, r.stdout + r.stderr
    assert parse_jobs(r.stdout) == set()


def test_dag_changed_characteristic_set_reruns_only_dependents(dag_workdir, tmp_path):
    """Dropping one literature set from characteristics.sets re-runs the jobs that use the set list
    (fsu_rom, table4, the load-sharing summary over the sets and what depends on them), not geometry, calibration,
    surrogates, L2-S1 or the load-sharing curves of the sets kept."""
    cfg = yaml.safe_load((dag_workdir / TEST_CONFIG).read_text())
    assert "rupp2015" in cfg["characteristics"]["sets"]
    cfg["characteristics"]["sets"] = [s for s in cfg["characteristics"]["sets"] if s != "rupp2015"]
    changed = tmp_path / "changed.yaml"
    changed.write_text(yaml.safe_dump(cfg))
    jobs = dry_jobs(dag_workdir, "--configfile", str(changed))
    rules = {r for r, _ in jobs}
    assert {"fsu_rom", "table4"} <= rules, jobs
    dependents = dry_jobs(dag_workdir, "--forcerun", "fsu_rom", "table4", "load_sharing_summary")
    assert jobs <= dependents, f"re-run although independent of characteristics.sets: {sorted(jobs - dependents)}"
    for independent in ("fsu_geometry", "fig1_l4l5_model", "calibrate", "stepwise_reduction_surrogate",
                        "stepwise_reduction_sim", "idp_surrogate", "l2s1_idp", "table5", "load_sharing_curves"):
        assert independent not in rules, jobs


def test_dag_changed_input_file_reruns_only_dependents(dag_copy):
    """An edited cable table (data/cables) re-runs the jobs that read it and their dependents only.
    (Only touching it re-runs nothing: Snakemake compares the checksums of small inputs.)"""
    cables = dag_copy / "data" / "cables" / "wilke1996_cables.csv"
    os.utime(cables)
    assert dry_jobs(dag_copy) == set()
    cables.write_text(cables.read_text() + "\n")           # same rows, new content
    jobs = dry_jobs(dag_copy)
    rules = {r for r, _ in jobs}
    assert {"idp_surrogate", "l2s1_idp", "fig3_l2s1_cables", "table5"} <= rules, jobs
    dependents = dry_jobs(dag_copy, "--forcerun", "idp_surrogate", "l2s1_idp", "fig3_l2s1_cables")
    assert jobs <= dependents, sorted(jobs - dependents)
    assert not rules & {"fsu_geometry", "fsu_rom", "calibrate", "stepwise_reduction_sim", "table4"}, jobs


def test_dag_resume_after_interruption(dag_copy):
    """A run interrupted after some jobs: one set's stepwise-reduction ROM and Table 4 (which needs it) are
    missing. ``snakemake --cores 2`` runs exactly those jobs and their dependents, writes the same bytes,
    and the run is complete afterwards. (A missing intermediate alone, with everything downstream up to
    date, is not rebuilt: nothing is lost, so nothing is to be done.)"""
    target = "results/stepwise_reduction/rom_rupp2015.csv"
    before = result_files(dag_copy)
    (dag_copy / target).unlink()
    assert dry_jobs(dag_copy) == set()
    for t in ("table4_rom_synopsis.csv", "table4_outlier_counts.csv", "table4_vs_paper.csv"):
        (dag_copy / "results" / "tables" / t).unlink()
    jobs = dry_jobs(dag_copy)
    expected = dry_jobs(dag_copy, "--forcerun", target)
    assert ("stepwise_reduction_sim", "set=rupp2015") in jobs, jobs
    assert jobs == expected, (sorted(jobs), sorted(expected))
    assert not {r for r, _ in jobs} & {"calibrate", "stepwise_reduction_surrogate", "l2s1_idp", "fsu_rom"}
    r = run_dag(dag_copy)
    assert parse_jobs(r.stdout + r.stderr) == jobs
    assert dry_jobs(dag_copy) == set()
    after = result_files(dag_copy)
    assert [k for k in before if before[k] != after.get(k)] == []


def test_dag_with_measured_tables_calibrates_admissibly_and_calls_them_measured(dag_copy):
    """The workflow on measured stepwise and in-vitro IDP tables (here: the run's own surrogates distorted by what the
    model does not have, a neutral-zone laxity growing with each removal and a stage-dependent softening, plus intact
    rows at 10 N*m; TEST DATA, not measurements): the final fit is pinned to the table's own intact rows and ends
    admissible; Yamamoto's rows become independent; the IDP rows join the scoreboard as independent checks; Table 4
    and Table 5 say the reference is measured."""
    import pandas as pd

    res = dag_copy / "results"
    s = pd.read_csv(res / "experiments" / "stepwise_reduction_surrogate.csv")
    order = {st: i for i, st in enumerate(["intact", "wo_ssl", "wo_isl", "wo_fl", "wo_cl", "wo_va", "wo_pll",
                                           "wo_all"])}
    k = s["stage"].map(order)
    lax = s["direction"].map({"flexion": 0.9, "extension": 0.7, "lateral_bending": 0.6, "axial_rotation": 0.3})
    shift = lax * (1 + 0.1 * k) * np.minimum(1.0, s["moment_nm"] / 2.5)
    t = s.assign(**{c: s[c] * (1 + 0.04 * k) + shift for c in ("rom_mean_deg", "rom_min_deg", "rom_max_deg")})
    i10 = pd.DataFrame({"stage": "intact", "direction": ["flexion", "extension", "lateral_bending", "axial_rotation"],
                        "moment_nm": 10.0, "rom_mean_deg": [8.2, 5.6, 6.3, 2.7], "n_specimens": 2})
    pd.concat([t, i10], ignore_index=True).assign(kind="measured", source="test data: distorted surrogate").round(
        5).to_csv(dag_copy / "measured_rom.csv", index=False)
    d = pd.read_csv(res / "experiments" / "idp_wilke1996_surrogate.csv")
    d.assign(idp_mean_mpa=(d["idp_mean_mpa"] * 1.2 + 0.08).round(5), idp_sd_mpa=(d["idp_sd_mpa"] * 1.5 + 0.02).round(5),
             n_specimens=7, kind="measured", source="test data: distorted surrogate").to_csv(
        dag_copy / "measured_idp.csv", index=False)
    (dag_copy / "measured.yaml").write_text("stepwise_reduction:\n  measured_table: measured_rom.csv\n"
                                            "l2s1:\n  measured_table: measured_idp.csv\n")
    targets = ["results/calibration/admissibility.csv", "results/tables/validation_real_data.csv",
               "results/tables/table4_outlier_counts.csv", "results/tables/table5_outlier_counts.csv"]
    r = snakemake(*targets, "--cores", "2", "--configfile", TEST_CONFIG, "measured.yaml", cwd=dag_copy, timeout=900)
    assert r.returncode == 0, (r.stdout + r.stderr)[-6000:]
    fitted = pd.read_csv(res / "calibration" / "calibration_targets.csv")
    assert len(fitted) == 4 and (fitted["kind"] == "measured").all()
    adm = pd.read_csv(res / "calibration" / "admissibility.csv")
    assert adm["passed"].all(), adm[~adm["passed"]][["criterion", "direction", "value", "limit", "note"]]
    v = pd.read_csv(res / "tables" / "validation_real_data.csv")
    yam = v[v["source"].str.startswith("Yamamoto") & (v["quantity"] == "L4-L5 ROM") & (v["set"] == "calibrated")]
    assert len(yam) == 4 and (yam["role"] == "independent").all()
    assert (v[v["kind"] == "measured"].groupby("quantity")["role"].first().to_dict() ==
            {"L4-L5 ROM": "calibration target", "L4-L5 IDP in vitro, wire cables": "independent"})
    assert (v["quantity"] == "L4-L5 IDP in vitro, wire cables").sum() == 49
    for table, col in (("table4_outlier_counts.csv", "data_kinds"), ("table5_outlier_counts.csv", "data_kind")):
        c = pd.read_csv(res / "tables" / table)
        assert (c[col] == "measured").all() and c["surrogate_comparison"].str.startswith("none").all(), c
