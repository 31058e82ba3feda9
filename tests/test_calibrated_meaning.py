"""One meaning of "calibrated": the workflow's own calibration output (characteristics.calibrated_dir).

* The real-data discovery compares with the model the config names: with ``discovery.characteristic_set:
  calibrated`` the rule's configuration carries the calibration output, and the model ROM of the intact L4-L5 rows
  is the calibrated unit's own ROM (the functional-unit stage's computation), facet and disc shear stiffness included.
* The muscle model's passive set is named explicitly (``muscle_model.passive_set``): the workflow's calibrated set
  (the calibration output, a declared input of the muscle rules), paper 1's published Table 3 set, or a literature
  set; "calibrated" alone is rejected as ambiguous.

The calibration output here is a TEST FIXTURE: the published tables with a facet stiffness and a disc shear
stiffness row of the kind the calibration writes (values typed for the test, not a fit), so that it differs from the
published set where the discovery used to read it.
"""
import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from conftest import ROOT

SCRIPTS = ROOT / "workflow" / "scripts"
TEST_CONFIG = ROOT / "config" / "test" / "config.yaml"
YAMAMOTO = ROOT / "data" / "experiments" / "yamamoto1989_intact_rom_original_text.csv"
FIXTURE_FACET_N_PER_M = 4.0e5        # the published 12000 N/m x ~33: a calibration-like stiff facet
FIXTURE_SHEAR_N_PER_M = 1.3e5        # inside the sourced 53-140 N/mm


@pytest.fixture(scope="module")
def calibrated_dir(tmp_path_factory):
    """A calibration-output folder (TEST FIXTURE): the published tables with the facet stiffness and the disc shear
    stiffness replaced as rule calibrate writes them."""
    d = tmp_path_factory.mktemp("calibration") / "characteristics"
    shutil.copytree(ROOT / "data" / "characteristics", d)
    facet = pd.read_csv(d / "facet.csv", dtype=str, keep_default_na=False)
    facet.loc[facet["parameter"] == "stiffness", ["value", "kind", "source"]] = [
        str(FIXTURE_FACET_N_PER_M), "surrogate", "TEST FIXTURE"]
    facet.to_csv(d / "facet.csv", index=False)
    disc = pd.read_csv(d / "disc.csv", dtype=str, keep_default_na=False)
    row = {c: "" for c in disc.columns} | {"parameter": "shear_stiffness", "direction": "shear",
                                           "value": str(FIXTURE_SHEAR_N_PER_M), "unit": "N/m", "kind": "surrogate",
                                           "source": "TEST FIXTURE"}
    pd.concat([disc, pd.DataFrame([row])], ignore_index=True).to_csv(d / "disc.csv", index=False)
    return d


@pytest.fixture(scope="module")
def common():
    spec = importlib.util.spec_from_file_location("_common_calibrated_meaning", SCRIPTS / "_common.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _config_with(tmp_path, calibrated_dir, **sections):
    cfg = yaml.safe_load(TEST_CONFIG.read_text())
    cfg.setdefault("characteristics", {})["calibrated_dir"] = str(calibrated_dir)
    for k, v in sections.items():
        cfg.setdefault(k, {}).update(v)
    p = tmp_path / "config.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def _unit_rom(charset, config, keys):
    """The calibrated unit's own ROM as the functional-unit stage computes it (workflow/scripts/fsu.py)."""
    from lumbar.experiments.fsu import build_fsu, range_of_motion
    from lumbar.geometry import load_geometry

    g, f = config["geometry"], config.get("fsu") or {}
    level = f.get("level", "L4-L5")
    geo = load_geometry(g["kind"], path=g.get("path") if g["kind"] == "visible_human" else None, levels=[level])
    fsu = build_fsu(geo, charset, level, facet_stiffness_n_per_m=f.get("facet_stiffness_n_per_m"),
                    disc_shear_stiffness_n_per_m=f.get("disc_shear_stiffness_n_per_m"))
    rom = range_of_motion(fsu, sorted(set(keys["moment_nm"])), list(dict.fromkeys(keys["direction"])),
                          stages=["intact"], tol=1e-8)
    m = rom.set_index(["direction", "moment_nm"])["rom_deg"]
    return np.array([m[(d, float(mo))] for d, mo in zip(keys["direction"], keys["moment_nm"])])


@pytest.mark.workflow
def test_intact_rom_discovery_compares_with_the_calibrated_unit(common, calibrated_dir, tmp_path, monkeypatch):
    """The model ROM the real-data discovery puts in scenarios.csv (model_before: the nominal model, no effect) equals
    the calibrated unit's own ROM to 1e-6 deg. Control: the published Table 3 set's ROM differs by more than 0.1 deg
    (what the discovery compared with while the rule's configuration dropped characteristics.calibrated_dir)."""
    from lumbar.discovery import problems as P
    from lumbar.discovery.detect import read_measured
    from lumbar.inputs.characteristics import resolve_characteristic_set

    monkeypatch.chdir(ROOT)
    smk = common.mock_snakemake("discovery_intact_rom", str(_config_with(tmp_path, calibrated_dir)))
    cfg = dict(smk.params.cfg)
    assert cfg["discovery"]["characteristic_set"] == "calibrated"
    # the calibration output is a declared input of the rule and the folder the discovery reads
    assert {str(calibrated_dir / n) for n in ("disc.csv", "facet.csv")} <= set(map(str, smk.input.calibrated))
    _, df = read_measured(YAMAMOTO)
    keys = df[["stage", "direction", "moment_nm"]].reset_index(drop=True)
    rom, conv, _, _ = P.fsu_variants_from_config(cfg).simulate(keys, {})
    assert np.all(conv)
    model = np.asarray(rom, float).reshape(-1)
    calibrated = resolve_characteristic_set("calibrated", data_dir=cfg["characteristics"]["data_dir"],
                                            calibrated_dir=calibrated_dir)
    assert calibrated.facet.stiffness == FIXTURE_FACET_N_PER_M and calibrated.disc.k_shear == FIXTURE_SHEAR_N_PER_M
    own = _unit_rom(calibrated, cfg, keys)
    np.testing.assert_allclose(model, own, atol=1e-6, rtol=0)
    published = _unit_rom(resolve_characteristic_set("calibrated", data_dir=cfg["characteristics"]["data_dir"]), cfg,
                          keys)
    assert np.max(np.abs(published - own)) > 0.1          # control: the two sets are told apart
    assert "calibrated" in P.nominal_model_label(cfg) and str(calibrated_dir) in P.nominal_model_label(cfg)


def test_muscle_passive_set_is_named_explicitly(calibrated_dir):
    """workflow_calibrated reads the calibration output (its facet and disc shear stiffness), published_table3 the
    published tables; "calibrated" alone and a missing calibration output are errors naming the config key.
    Control: the two named sets differ in the facet stiffness."""
    from lumbar.muscles.muscle_model import passive_characteristics, passive_set_names

    cal = passive_characteristics("workflow_calibrated", calibrated_dir=calibrated_dir)
    pub = passive_characteristics("published_table3", data_dir=ROOT / "data" / "characteristics")
    assert cal.facet.stiffness == FIXTURE_FACET_N_PER_M and cal.disc.k_shear == FIXTURE_SHEAR_N_PER_M
    assert pub.facet.stiffness == 12000.0 and pub.facet.stiffness != cal.facet.stiffness
    assert passive_characteristics("rupp2015").name == "rupp2015"
    assert "calibrated" not in passive_set_names()
    with pytest.raises(ValueError, match="muscle_model.passive_set.*ambiguous"):
        passive_characteristics("calibrated")
    with pytest.raises(FileNotFoundError, match="workflow_calibrated.*calibrate"):
        passive_characteristics("workflow_calibrated", calibrated_dir=calibrated_dir.parent / "missing")


@pytest.mark.workflow
@pytest.mark.parametrize("passive_set,folder", [("workflow_calibrated", None),
                                                ("published_table3", "data/characteristics")])
def test_muscle_rules_declare_the_passive_set_they_read(common, calibrated_dir, tmp_path, monkeypatch, passive_set,
                                                        folder):
    """The muscle rules' input ``passive`` is the named set's tables: the calibration output for workflow_calibrated
    (so the DAG runs the calibration first), the published tables for published_table3; the script reads the set from
    that folder."""
    monkeypatch.chdir(ROOT)
    cfg = _config_with(tmp_path, calibrated_dir, muscle_model={"passive_set": passive_set})
    want = str(calibrated_dir) if folder is None else folder
    for rule, wc in (("muscle_validation", {}), ("muscle_sobol_chunk", {"posture": "standing", "chunk": 0})):
        smk = common.mock_snakemake(rule, str(cfg), **wc)
        folders = {str(Path(p).parent) for p in smk.input.passive}
        assert folders == {want}, (rule, folders)
        assert smk.params.muscle_model["passive_set"] == passive_set


def test_facet_contact_follows_the_gap_and_the_set_stiffness(model):
    """The muscle model's facet-contact table at rest, on its detailed passive chain: a surface carries force
    exactly where its contact points lie beyond it (gap < 0), none where they are off it (the myo-sim levels as
    carried, before their rest overlap is cleared, have both), and the force is linear in the set's facet stiffness
    (the penalty beyond its smoothing band). Control: doubling the stiffness doubles it; the default model (paper 2's
    springs) has no facet joints and no rows; with the overlap cleared (the default of the detailed chain) no facet
    carries force at rest."""
    import dataclasses
    from types import SimpleNamespace

    from lumbar.muscles.muscle_model import LumbarMuscleModel
    from lumbar.muscles.muscle_validation import facet_contact

    x0, R0 = model.reference_state()
    rest = [SimpleNamespace(x=x0[0], R=R0[0], reached=True)]
    assert facet_contact(model, rest, ["rest"]).empty and model.passive_model == "springs"
    cleared = facet_contact(LumbarMuscleModel(passive_model="detailed", in_situ_posture="reference"), rest, ["rest"])
    assert (cleared["contact_n"] < 1e-9).all() and cleared["rest_min_gap_mm"].min() > -1e-9   # round-off only
    assert cleared["surface_moved_mm"].max() > 1.0                                  # L3-L4's faces crossed by mm
    model = LumbarMuscleModel(passive_model="detailed", in_situ_posture="reference", clear_facet_overlap=False)
    t = facet_contact(model, rest, ["rest"])
    assert len(t) == 2 * len(model.levels) and set(t["side"]) == {"left", "right"}
    np.testing.assert_allclose(t["min_gap_mm"], t["rest_min_gap_mm"], atol=1e-12)
    assert ((t["contact_n"] > 0) == (t["min_gap_mm"] < 0)).all()
    assert (t["min_gap_mm"] > 0.1).any() and (t["min_gap_mm"] < -0.1).any()     # both cases occur here
    stiff = dataclasses.replace(model.charset, facet=dataclasses.replace(model.charset.facet,
                                                                         stiffness=2 * model.charset.facet.stiffness))
    t2 = facet_contact(LumbarMuscleModel(charset=stiff, passive_model="detailed", in_situ_posture="reference",
                                         clear_facet_overlap=False), rest, ["rest"])
    deep = t["min_gap_mm"] < -0.5                     # beyond the smoothing band at every contact point that touches
    assert deep.any()
    np.testing.assert_allclose(t2.loc[deep, "contact_n"], 2 * t.loc[deep, "contact_n"], rtol=0.05)
    assert (t2.loc[deep, "contact_n"] > 1.5 * t.loc[deep, "contact_n"]).all()
    assert (t2["facet_stiffness_n_per_m"] == 2 * t["facet_stiffness_n_per_m"]).all()


@pytest.mark.parametrize("space_mm", [0.5, 2.0, 6.0])
def test_face_separation_is_the_joint_space_of_the_landmarks(space_mm):
    """Two parallel landmark faces ``space_mm`` apart along their normal: face_separation returns that distance
    (the quantity the facet-contact table compares with the anatomical joint space)."""
    from lumbar.mechanics.elements.facet import fit_surface
    from lumbar.muscles.muscle_validation import face_separation

    u, v = np.meshgrid([-4e-3, 0.0, 4e-3], [-5e-3, 0.0, 5e-3])
    n = np.array([0.3, -0.9, 0.3]) / np.linalg.norm([0.3, -0.9, 0.3])
    a = np.cross(n, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    sup = np.array([0.0, 0.02, 0.03]) + u.reshape(-1, 1) * a + v.reshape(-1, 1) * b
    inf = sup + 1e-3 * space_mm * n
    surf = fit_surface(sup, inf, medial_hint=n)
    assert face_separation(surf, SimpleLandmarks(sup, inf)) == pytest.approx(1e-3 * space_mm, rel=1e-6)


class SimpleLandmarks:
    def __init__(self, superior, inferior):
        self.superior, self.inferior = superior, inferior
