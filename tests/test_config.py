"""lumbar.config: the workflow schema validates, fills defaults and names the bad key."""
import copy
from pathlib import Path

import pytest
import yaml

from lumbar.config import ConfigError, default_schema_path, load_config

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "workflow" / "schemas" / "config.schema.yaml"


def test_schema_found_via_package():
    assert default_schema_path() == SCHEMA


def test_defaults_filled_from_empty():
    cfg = load_config({})
    assert cfg["geometry"] == {"kind": "default", "path": "../shared/geometry/visible_human_lss"}
    assert cfg["characteristics"]["sets"] == [
        "calibrated", "chazal1985", "shirazi_adl1986", "white_panjabi1990", "nolte1990", "rupp2015"]
    assert cfg["fsu"] == {"level": "L4-L5", "moments_nm": [1, 2.5, 5, 7.5, 10],
                          "directions": ["flexion", "extension", "lateral_bending", "axial_rotation"],
                          "facet_stiffness_n_per_m": 12000, "disc_shear_stiffness_n_per_m": None}
    assert cfg["solver"] == {"tol_force_n": 1e-8, "tol_moment_nm": 1e-8, "max_iter": 50, "load_steps": 1}
    assert cfg["seed"] == 20261123


def test_main_config_equals_schema_defaults():
    """config/config.yaml spells out the defaults: the two cannot drift apart."""
    assert load_config(ROOT / "config" / "config.yaml") == load_config({})


def test_partial_section_keeps_given_values_and_fills_the_rest():
    cfg = load_config(ROOT / "config" / "test" / "config.yaml")
    assert cfg["fsu"]["moments_nm"] == [2.5, 7.5]
    assert cfg["fsu"]["facet_stiffness_n_per_m"] == 12000
    assert cfg["solver"]["tol_force_n"] == 1e-8 and cfg["solver"]["max_iter"] == 30


def test_input_dict_not_modified_and_defaults_not_shared():
    given = {"fsu": {"level": "L3-L4"}}
    before = copy.deepcopy(given)
    a = load_config(given)
    assert given == before
    a["fsu"]["moments_nm"].append(99)
    assert load_config({})["fsu"]["moments_nm"] == [1, 2.5, 5, 7.5, 10]


def test_snakemake_validate_agrees_with_load_config():
    validate = pytest.importorskip("snakemake.utils").validate
    raw = yaml.safe_load((ROOT / "config" / "test" / "config.yaml").read_text())
    validate(raw, schema=str(SCHEMA))
    assert raw == load_config(ROOT / "config" / "test" / "config.yaml")


def _error(cfg) -> str:
    with pytest.raises(ConfigError) as exc:
        load_config(cfg)
    return str(exc.value)


def test_reject_unknown_key():
    msg = _error({"fsu": {"moment_nm": [1]}})
    assert "fsu.moment_nm" in msg and "moments_nm" in msg  # names the key and the allowed keys


def test_reject_unknown_top_level_section():
    assert "solvr" in _error({"solvr": {}})


def test_reject_negative_stiffness():
    msg = _error({"fsu": {"facet_stiffness_n_per_m": -12000}})
    assert "fsu.facet_stiffness_n_per_m" in msg and "> 0" in msg


def test_reject_negative_moment_names_index():
    msg = _error({"fsu": {"moments_nm": [1, 2.5, -5]}})
    assert "fsu.moments_nm[2]" in msg and "> 0" in msg


def test_reject_unknown_geometry_kind():
    msg = _error({"geometry": {"kind": "visible_female"}})
    assert "geometry.kind" in msg and "default" in msg and "visible_human" in msg


def test_invalid_type():
    msg = _error({"solver": {"max_iter": "fifty"}})
    assert "solver.max_iter" in msg and "integer" in msg


def test_invalid_bool_is_not_a_number():
    assert "fsu.moments_nm[0]" in _error({"fsu": {"moments_nm": [True]}})


def test_invalid_empty_directions():
    msg = _error({"fsu": {"directions": []}})
    assert "fsu.directions" in msg and "at least 1" in msg


def test_invalid_direction_name():
    msg = _error({"fsu": {"directions": ["flexion", "torsion"]}})
    assert "fsu.directions[1]" in msg and "axial_rotation" in msg


def test_invalid_characteristic_set():
    assert "characteristics.sets[0]" in _error({"characteristics": {"sets": ["nolte1991"]}})


def test_invalid_all_errors_reported():
    err = pytest.raises(ConfigError, load_config, {"seed": -1, "solver": {"load_steps": 0}}).value
    assert {p for p, _ in err.errors} == {"seed", "solver.load_steps"}


def test_invalid_yaml_file(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("fsu: [unclosed\n")
    assert "not valid YAML" in _error(p)


def test_invalid_root_not_mapping(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("- a\n- b\n")
    assert "<root>" in _error(p)


def test_every_schema_property_documented():
    """Every property has description, type and default; every object forbids unknown keys."""
    schema = yaml.safe_load(SCHEMA.read_text())

    def walk(node, where):
        if node.get("type") == "object":
            assert node.get("additionalProperties") is False, where
            for name, sub in node["properties"].items():
                for field in ("description", "type", "default"):
                    assert field in sub, f"{where}.{name} lacks {field}"
                walk(sub, f"{where}.{name}")

    walk(schema, "<root>")
