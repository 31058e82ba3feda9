"""A user's specimen through the workflow (geometry kinds ``meshes`` and ``label_volume``, lumbar.geometry.configured,
workflow/rules/specimen.smk): checks before any job, the stages a specimen cannot feed said once and left out, the
geometry built once and loaded from the content-addressed cache, the embedded morphable lumbar mean through a slice
of the DAG (landmarks and QA, the calibration on its L4-L5 and its admissibility, the other levels), and a 3 mm
label volume through the geometry rule saying what its voxels cannot support."""
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import copy_repo, snakemake
from lumbar.geometry import GeometryError, configured
from lumbar.geometry.synthetic import symmetric_fsu

ROOT = Path(__file__).resolve().parents[1]
MEAN = ROOT / "data" / "geometry" / "morphable_lumbar_mean"
TS_MASKS = ROOT / "tests" / "data" / "totalsegmentator_example"
TEST_CONFIG = "config/test/config.yaml"
MEAN_CONFIG = "config/test/morphable_mean.yaml"
MEAN_G = dict(kind="meshes", path=str(MEAN), units="mm", axes="project")


# ------------------------------------------------------------------ library: checks, arrays, cache address
def test_the_embedded_mean_carries_its_licence_and_attribution():
    assert sorted(p.name for p in MEAN.iterdir()) == ["L2.stl", "L3.stl", "L4.stl", "L5.stl", "LICENSE", "README.md"]
    assert "MIT License" in (MEAN / "LICENSE").read_text()
    assert "Clouthier" in (MEAN / "README.md").read_text()


def test_geometry_arrays_round_trip_and_a_change_shows():
    geo = symmetric_fsu()
    a = configured.geometry_to_arrays(geo)
    back = configured.geometry_to_arrays(configured.geometry_from_arrays(a))
    assert a.keys() == back.keys() and all(np.array_equal(a[k], back[k]) for k in a)
    # control: a moved fibre end is seen by the same comparison
    geo.levels["L4-L5"].ligaments[0].upper[0, 0] += 1e-6
    moved = configured.geometry_to_arrays(geo)
    assert not all(np.array_equal(a[k], moved[k]) for k in a)


def test_select_levels_keeps_the_vertebrae_of_the_units_asked_for():
    geo = symmetric_fsu()
    assert list(configured.select_levels(geo, "L4-L5").vertebrae) == ["L4", "L5"]
    with pytest.raises(GeometryError, match="no unit L2-L3; units present: \\['L4-L5'\\]"):
        configured.select_levels(geo, ["L2-L3"])


def _dummy_folder(tmp_path, names):
    d = tmp_path / "spec"
    d.mkdir()
    for n in names:
        (d / n).write_bytes(b"not a mesh")      # the checks before the build read no mesh
    return d


def test_config_checks_name_the_problem_before_any_mesh_is_read(tmp_path):
    d = _dummy_folder(tmp_path, ["L2.stl", "L4.stl", "L5.stl"])
    g = dict(kind="meshes", path=str(d), units="mm", axes="LPS")
    with pytest.raises(GeometryError, match="L3 missing between L2 and L5"):
        configured.check_config(g)
    (d / "L3.stl").write_bytes(b"x")
    assert ("l2s1", "no sacrum (S1): no L5-S1 unit and no L2-S1 model") in configured.check_config(g)  # control
    with pytest.raises(GeometryError, match=r"fsu.level 'L5-S1'.*one of \['L2-L3', 'L3-L4', 'L4-L5'\]"):
        configured.check_config(g, calibrated_level="L5-S1")
    with pytest.raises(GeometryError, match="units 'cm'"):
        configured.check_config({**g, "units": "cm"})
    with pytest.raises(GeometryError, match="geometry.axes missing"):
        configured.check_config({**g, "axes": None})
    with pytest.raises(GeometryError, match="geometry.axes 'LPS' with kind label_volume"):
        configured.check_config(dict(kind="label_volume", path=str(TS_MASKS), axes="LPS"))
    assert configured.check_config(dict(kind="visible_human")) == []


def test_the_mean_skips_the_stages_that_need_a_sacrum(tmp_path):
    skipped = dict(configured.check_config(MEAN_G, "L4-L5"))
    assert set(skipped) == {"l2s1", "muscle_model", "load_sharing.other_levels L1-L2",
                            "load_sharing.other_levels L5-S1"}
    assert all("no sacrum" in skipped[k] for k in ("l2s1", "muscle_model", "load_sharing.other_levels L5-S1"))
    assert configured.specimen_inputs(MEAN_G).units_present == ["L2-L3", "L3-L4", "L4-L5"]
    # control: the same file names with a sacrum skip only the missing L1-L2
    d = _dummy_folder(tmp_path, ["L2.stl", "L3.stl", "L4.stl", "L5.stl", "sacrum.stl"])
    assert [s for s, _ in configured.check_config(dict(MEAN_G, path=str(d)))] == ["load_sharing.other_levels L1-L2"]


def test_the_cache_address_follows_the_bytes_and_the_settings(tmp_path):
    d = tmp_path / "mean"
    shutil.copytree(MEAN, d)
    g = dict(MEAN_G, path=str(d))
    base = configured.cache_content(configured.specimen_inputs(g))
    assert configured.cache_content(configured.specimen_inputs(dict(g))) == base
    assert configured.cache_content(configured.specimen_inputs(dict(g, axes="RAS"))) != base
    data = bytearray((d / "L3.stl").read_bytes())
    data[200] ^= 1                                          # one bit of one vertex
    (d / "L3.stl").write_bytes(bytes(data))
    assert configured.cache_content(configured.specimen_inputs(g)) != base


def test_level_targets_are_yamamotos_rows_of_that_level():
    from lumbar.experiments.admissibility import yamamoto_level_targets
    from lumbar.experiments.stepwise_reduction import read_experiment_table

    l45 = read_experiment_table(ROOT / "data/experiments/yamamoto1989_intact_rom_original_text.csv")
    want = dict(zip(l45["direction"], l45["rom_mean_deg"]))
    got = yamamoto_level_targets("L4-L5")
    assert dict(zip(got["direction"], got["rom_mean_deg"])) == want
    l34 = yamamoto_level_targets("L3-L4")
    assert dict(zip(l34["direction"], l34["rom_mean_deg"])) != want                 # control: another level
    assert set(l34.columns) == set(l45.columns) and (l34["kind"] == "original_text").all()


def test_discovery_multilevel_units_are_built_on_the_specimen():
    """The discovery's multilevel units (lumbar.discovery.real_data.level_units, rule discovery_multilevel_rom) are
    built on the configured geometry, a user's specimen included: the morphable mean's L3-L4 unit has the mean's own
    disc; control: the embedded Visible Human configuration gives another disc."""
    from lumbar.discovery import real_data as RD
    unit = RD.level_units({"geometry": MEAN_G}, ["L3-L4"])["L3-L4"]
    mean = configured.load_configured(MEAN_G, levels=["L3-L4"]).levels["L3-L4"]
    assert unit.fsu.level.disc_height == pytest.approx(mean.disc_height, rel=1e-9)
    vh = RD.level_units({"geometry": {"kind": "visible_human"}}, ["L3-L4"])["L3-L4"]
    assert vh.fsu.level.disc_height != pytest.approx(mean.disc_height, rel=1e-3)


# ------------------------------------------------------------------ the workflow
def _tree(tmp_path_factory, name):
    return copy_repo(tmp_path_factory.mktemp(name) / "repo")


@pytest.fixture(scope="module")
def smk_tree(tmp_path_factory):
    pytest.importorskip("snakemake")
    return _tree(tmp_path_factory, "specimen_smk")


@pytest.mark.workflow
def test_bad_specimen_is_rejected_before_any_job(smk_tree, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"geometry: {{kind: meshes, path: {MEAN}, units: mm, axes: project}}\nfsu: {{level: L5-S1}}\n")
    r = snakemake("-n", "--configfile", TEST_CONFIG, str(bad), cwd=smk_tree, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode != 0
    assert "Error in config geometry" in out and "fsu.level 'L5-S1'" in out and "['L2-L3', 'L3-L4', 'L4-L5']" in out
    assert not (smk_tree / "results" / "geometry").exists()
    bad.write_text(f"geometry: {{kind: meshes, path: {MEAN}}}\n")         # units and axes are declared, never guessed
    r = snakemake("-n", "--configfile", TEST_CONFIG, str(bad), cwd=smk_tree, timeout=300)
    assert r.returncode != 0 and "geometry.units missing (kind meshes" in r.stdout + r.stderr


@pytest.mark.workflow
def test_default_target_of_the_mean_says_once_what_it_skips(smk_tree):
    r = snakemake("-n", "--configfile", TEST_CONFIG, MEAN_CONFIG, cwd=smk_tree, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert out.count("skipped stages:") == 1 and out.count("l2s1: no sacrum (S1)") == 1
    jobs = dict(line.split() for line in out.split("Job stats:")[1].split("total")[0].splitlines()[3:]
                if len(line.split()) == 2)
    assert jobs.get("specimen_geometry") == "1" and "calibrate" in jobs and "multilevel_validation" in jobs
    assert not {j for j in jobs if "l2s1" in j or "muscle" in j or "discovery" in j
                or j in ("idp_surrogate", "paper_report", "validation_real_data")}
    # on its L4-L5 the calibration reads the default L4-L5 targets (control of the next test)
    assert "yamamoto1989_intact_rom_original_text.csv" in out and "specimen_real_targets" not in out


@pytest.mark.workflow
def test_another_calibrated_unit_takes_its_own_yamamoto_targets(smk_tree, tmp_path):
    cfg = tmp_path / "l34.yaml"
    cfg.write_text("fsu: {level: L3-L4}\n")
    r = snakemake("-n", "-p", "results/morphable_mean/calibration/posterior.csv", "--configfile", TEST_CONFIG,
                  MEAN_CONFIG, str(cfg), cwd=smk_tree, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "rule specimen_real_targets" in out and "results/morphable_mean/geometry/real_targets.csv" in out
    assert "yamamoto1989_intact_rom_original_text.csv" not in out     # control: test_default_target_of_the_mean...


MEAN_TARGETS = ["results/morphable_mean/geometry/levels.csv",
                "results/morphable_mean/calibration/admissibility.csv",
                "results/morphable_mean/tables/multilevel_rom.csv",
                "results/morphable_mean/export/opensim_check.csv"]


@pytest.fixture(scope="module")
def mean_run(tmp_path_factory):
    """The CI slice of the morphable mean's DAG (module doc) in a fresh copy, on the session's geometry cache."""
    pytest.importorskip("snakemake")
    work = _tree(tmp_path_factory, "mean_dag")
    r = snakemake("--cores", "2", *MEAN_TARGETS, "--configfile", TEST_CONFIG, MEAN_CONFIG, cwd=work, timeout=900)
    if r.returncode != 0:
        logs = "".join(f"\n==> {p.name}\n{p.read_text()[-3000:]}" for p in sorted((work / "logs").glob("*.log")))
        pytest.fail(f"snakemake failed\n{(r.stdout + r.stderr)[-8000:]}{logs}", pytrace=False)
    return work


@pytest.mark.workflow
def test_mean_geometry_rule_writes_landmarks_transform_and_qa(mean_run):
    g = mean_run / "results" / "morphable_mean" / "geometry"
    levels = pd.read_csv(g / "levels.csv").set_index("level")
    assert list(levels.index) == ["L2-L3", "L3-L4", "L4-L5"]
    assert ((levels["disc_height_mm"] > 3) & (levels["disc_height_mm"] < 20)).all()
    assert ((levels["disc_csa_mm2"] > 800) & (levels["disc_csa_mm2"] < 3000)).all()
    assert (levels["facet_numbers"] == "measured from the surfaces").all()
    T = np.asarray(pd.read_json(g / "transform.json", typ="series")["input_to_project_m"], float)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9) and np.linalg.det(T[:3, :3]) > 0
    # the source's axes are the project's (README): the detected frame is within a few degrees of the declared one
    assert T[0, 0] > 0.99 and T[1, 1] > 0.99 and T[2, 2] > 0.99
    for u in levels.index:
        assert (g / f"qa_{u}.png").stat().st_size > 10_000
    skipped = pd.read_csv(g / "skipped_stages.csv")
    assert {"l2s1", "muscle_model"} <= set(skipped["stage"])


@pytest.mark.workflow
def test_mean_jobs_load_the_cached_geometry(mean_run):
    """The geometry the jobs loaded is the one the rule built: the cache holds one specimen entry for these inputs,
    and the calibrated unit's disc is the rule's table's."""
    si = configured.specimen_inputs(dict(MEAN_G, path=str(mean_run / "data/geometry/morphable_lumbar_mean")))
    entry = configured.diskcache.entry_for(configured.cache_content(si), configured.CACHE_KIND,
                                           configured.build_tag())
    assert entry is not None and entry.is_file()
    geo = configured.geometry_from_arrays(dict(np.load(entry)))
    row = pd.read_csv(mean_run / "results/morphable_mean/geometry/levels.csv").set_index("level").loc["L4-L5"]
    assert row["disc_height_mm"] == pytest.approx(1e3 * geo.levels["L4-L5"].disc_height, rel=1e-5)
    assert row["disc_height_mm"] != pytest.approx(1e3 * geo.levels["L3-L4"].disc_height, rel=1e-3)   # control


# On the mean shape (config/test settings) every admissibility criterion passes; a parameter at a bound must carry
# its documented reason (BOUND_REASONS; the capsules' prestrain cap bound there before the disc-only rows counted as
# one observation per direction, pushed by the axial-rotation row). A new miss fails this test.
KNOWN_MISSES: set = set()


@pytest.mark.workflow
def test_mean_calibration_admissibility_and_the_other_levels(mean_run):
    adm = pd.read_csv(mean_run / "results/morphable_mean/calibration/admissibility.csv")
    assert len(adm) > 30 and (adm["level"] == "L4-L5").all()
    bad = adm[~adm["passed"].astype(bool)]
    failed = {(c, None if pd.isna(d) else d) for c, d in zip(bad["criterion"], bad["direction"])}
    assert failed == KNOWN_MISSES, bad.to_string()
    post = pd.read_csv(mean_run / "results/morphable_mean/calibration/posterior.csv").set_index("parameter")
    at = post[post["at_bound"].astype(bool)]
    assert (at["bound_reason"].fillna("").astype(str).str.len() > 0).all(), at.to_string()   # no bound without its reason
    if "CL:pre_elongation" in at.index:                                             # the finding, when it is there
        assert "axial_rotation" in str(at.loc["CL:pre_elongation", "moved_by"])
    ml = pd.read_csv(mean_run / "results/morphable_mean/tables/multilevel_rom.csv")
    assert {"L2-L3", "L3-L4"} == set(ml["level"])          # L1-L2 and L5-S1: no such unit in the mean shape
    assert ml["converged"].astype(bool).all()


@pytest.mark.workflow
def test_mean_units_exported_to_opensim_and_checked_there(mean_run):
    """The mean shape's calibrated L4-L5 as an OpenSim 4.6 model: loaded and solved in OpenSim (in the rule), the
    detailed unit within 0.01 deg of the project's solver, the reduced joint within 10 %."""
    chk = pd.read_csv(mean_run / "results/morphable_mean/export/opensim_check.csv")
    assert set(chk["level"]) == {"L4-L5"} and (chk["status"] == "ok").all(), chk.to_string()
    assert chk.loc[chk["variant"].str.startswith("detailed"), "difference_deg"].abs().max() < 0.01
    assert chk.loc[chk["variant"] == "reduced", "relative_difference"].abs().max() < 0.10
    assert (mean_run / "results/morphable_mean/export/calibrated/morphable_lumbar_mean_L4-L5.osim").is_file()


@pytest.mark.workflow
def test_label_volume_through_the_geometry_rule_says_what_3mm_voxels_cannot_support(tmp_path_factory, tmp_path):
    pytest.importorskip("snakemake")
    work = _tree(tmp_path_factory, "label_volume_dag")          # its own tree: the dry-run tests see no results/
    cfg = tmp_path / "ts.yaml"
    cfg.write_text(f"geometry: {{kind: label_volume, path: {TS_MASKS}}}\n")
    r = snakemake("--cores", "2", "results/geometry/levels.csv", "--configfile", TEST_CONFIG, str(cfg),
                  cwd=work, timeout=600)
    assert r.returncode == 0, (r.stdout + r.stderr)[-6000:]
    g = work / "results" / "geometry"
    limits = pd.read_csv(g / "meshes" / "resolution_limits.csv")
    facet = limits[limits["feature"].str.startswith("facet")].iloc[0]
    assert not facet["supported"] and "3 mm" in facet["reason"]
    levels = pd.read_csv(g / "levels.csv").set_index("level")
    assert list(levels.index) == ["L4-L5", "L5-S1"]
    gap_cols = [c for c in levels.columns if c.startswith("facet_") and c.endswith(("bone_gap_mm", "mean_p00"))]
    assert gap_cols and levels[gap_cols].isna().all().all()       # no precise-looking facet numbers
    assert levels["facet_numbers"].str.startswith("not supported: largest voxel edge 3 mm").all()
    assert levels["disc_height_mm"].notna().all()                 # what 3 mm voxels do support stays
    skipped = pd.read_csv(g / "skipped_stages.csv")
    assert "l2s1" in set(skipped["stage"]) and "muscle_model" not in set(skipped["stage"])   # L2, L3 absent; S1 there
