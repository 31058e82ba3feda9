"""lumbar.inputs.config: the workflow schema validates, fills defaults and names the bad key."""
import copy
import re
from pathlib import Path

import pytest
import yaml
from jsonschema import Draft202012Validator

from lumbar.inputs.config import ConfigError, default_schema_path, load_config

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "workflow" / "schemas" / "config.schema.yaml"


def test_schema_found_via_package():
    assert default_schema_path() == SCHEMA


def test_defaults_filled_from_empty():
    cfg = load_config({})
    assert cfg["geometry"] == {"kind": "visible_human", "path": "data/geometry/visible_human_lss", "units": None,
                               "axes": None, "pattern": None, "turn_inside_out": False,
                               "label_table": None}   # the last five: a specimen's
    assert cfg["characteristics"]["sets"] == [
        "calibrated", "chazal1985", "shirazi_adl1986", "white_panjabi1990", "nolte1990", "rupp2015"]
    assert cfg["fsu"] == {"level": "L4-L5", "moments_nm": [1, 2.5, 5, 7.5, 10], "beyond_experiment": False,
                          "directions": ["flexion", "extension", "lateral_bending", "axial_rotation"],
                          "facet_stiffness_n_per_m": None, "disc_shear_stiffness_n_per_m": None}
    assert cfg["solver"] == {"tol_force_n": 1e-6, "tol_moment_nm": 1e-7, "max_iter": 50, "load_steps": 1}
    assert cfg["seed"] == 20261123


def test_main_config_equals_schema_defaults():
    """config/config.yaml spells out the defaults: the two cannot drift apart."""
    assert load_config(ROOT / "config" / "config.yaml") == load_config({})


def test_partial_section_keeps_given_values_and_fills_the_rest():
    cfg = load_config(ROOT / "config" / "test" / "config.yaml")
    assert cfg["fsu"]["moments_nm"] == [2.5, 7.5]
    assert cfg["fsu"]["facet_stiffness_n_per_m"] is None      # null = the characteristic set's facet.csv value
    assert cfg["solver"]["tol_force_n"] == 1e-6 and cfg["solver"]["max_iter"] == 50
    mcfg = cfg["muscle_model"]["solver"]                        # given: ipopt_max_iter 10 (default 50)
    assert mcfg["ipopt_max_iter"] == 10 and mcfg["multistart"] is False
    assert mcfg["max_iter"] == 150 and mcfg["batch_size"] == 64   # not given: the schema's defaults


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
    assert "geometry.kind" in msg and "myo_sim" in msg and "visible_human" in msg


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


def test_muscle_passive_set_is_explicit():
    """The muscle model's passive set defaults to the workflow's calibration and is one name, never the ambiguous
    "calibrated" (the published Table 3 set is published_table3); the schema's names are the library's."""
    from lumbar.muscles.muscle_model import passive_set_names

    assert load_config({})["muscle_model"]["passive_set"] == "workflow_calibrated"
    assert "characteristics" not in load_config({})["muscle_model"]
    assert load_config({"muscle_model": {"passive_set": "published_table3"}})["muscle_model"]["passive_set"] == \
        "published_table3"
    assert "muscle_model.passive_set" in _error({"muscle_model": {"passive_set": "calibrated"}})
    assert "muscle_model.characteristics" in _error({"muscle_model": {"characteristics": "calibrated"}})
    import yaml
    schema = yaml.safe_load(SCHEMA.read_text())
    enum = schema["properties"]["muscle_model"]["properties"]["passive_set"]["enum"]
    assert set(enum) == set(passive_set_names())


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


# ---------------------------------------------------------------- every key of the schema, walked
# (sections added later are checked too)
_UNIT = re.compile(r"\[[^\]]+\]")                       # a unit in brackets: [N/m], [deg], [-], [count]
_UNIT_SUFFIX = re.compile(r"_(n|nm|m|m2|mm|mpa|deg|rad|pct|kg|s|hz|n_per_m|n_per_rad|um|cm2)$")


def _schema():
    return yaml.safe_load(SCHEMA.read_text())


def _types(node) -> set:
    t = node.get("type", [])
    return set(t if isinstance(t, list) else [t])


def _walk(node, path=()):
    """(key path tuple, property schema) for every property at every level, depth first."""
    for name, sub in node.get("properties", {}).items():
        yield path + (name,), sub
        if "object" in _types(sub):
            yield from _walk(sub, path + (name,))


def _numeric(sub):
    """The schema node holding the numeric bounds (the property or its array items), or None."""
    if _types(sub) & {"number", "integer"}:
        return sub
    if "array" in _types(sub) and _types(sub.get("items", {})) & {"number", "integer"}:
        return sub["items"]
    return None


def test_every_schema_key_has_description_type_default_unit_and_bounds():
    problems = []
    root = _schema()
    if root.get("additionalProperties") is not False:
        problems.append("<root>: additionalProperties is not false")
    for path, sub in _walk(root):
        key = ".".join(path)
        for field in ("description", "type", "default"):
            if field not in sub:
                problems.append(f"{key}: no {field}")
        if "object" in _types(sub) and sub.get("additionalProperties") is not False:
            problems.append(f"{key}: object without additionalProperties: false")
        num = _numeric(sub)
        if num is not None:
            if not _UNIT.search(sub.get("description", "")):
                problems.append(f"{key}: numeric key without a [unit] in its description")
            if not ({"minimum", "exclusiveMinimum"} & set(num)):
                problems.append(f"{key}: numeric key without a lower bound")
        if _UNIT_SUFFIX.search(path[-1]) and num is None and "object" not in _types(sub):
            problems.append(f"{key}: unit-suffixed key is not numeric")
        if "default" in sub and "object" not in _types(sub):
            try:
                Draft202012Validator({k: v for k, v in sub.items() if k != "default"}).validate(sub["default"])
            except Exception as exc:  # noqa: BLE001
                problems.append(f"{key}: default {sub['default']!r} violates its own schema ({exc.message})")
    assert problems == [], "\n".join(problems)


def _nest(path, value):
    out = value
    for name in reversed(path):
        out = {name: out}
    return out


def _invalid_cases():
    """One invalid value per constraint of every key: (id, config, key path in the message, text the
    message must contain)."""
    cases = []
    for path, sub in _walk(_schema()):
        key = ".".join(path)
        if "object" in _types(sub):
            cases.append((f"{key}-unknown-key", _nest(path, {"no_such_key": 1}), f"{key}.no_such_key",
                          ["unknown key 'no_such_key'"] + [f"{k}" for k in sub.get("properties", {})]))
            continue
        is_array = "array" in _types(sub)
        item = sub.get("items", {}) if is_array else sub
        at = f"{key}[0]" if is_array else key
        wrap = (lambda v: [v]) if is_array else (lambda v: v)
        if "enum" in item:
            cases.append((f"{key}-enum", _nest(path, wrap("not_a_valid_value")), at,
                          ["is not allowed; allowed values"] + [str(e) for e in item["enum"] if e is not None]))
        num = _numeric(sub)
        if num is not None:
            for bound, op, delta in (("minimum", ">=", -1), ("exclusiveMinimum", ">", 0),
                                     ("maximum", "<=", 1), ("exclusiveMaximum", "<", 0)):
                if bound in num:
                    bad = num[bound] + delta
                    if "integer" in _types(num) and "number" not in _types(num):
                        bad = int(bad)
                    cases.append((f"{key}-{bound}", _nest(path, wrap(bad)), at,
                                  ["is out of range", f"expected a value {op} {num[bound]}"]))
            cases.append((f"{key}-type", _nest(path, wrap("text")), at, ["has the wrong type"]))
    return cases


@pytest.mark.parametrize("cfg,where,texts", [c[1:] for c in _invalid_cases()],
                         ids=[c[0] for c in _invalid_cases()])
def test_reject_invalid_config_names_key_and_allowed_values(cfg, where, texts):
    """load_config names the key path and the allowed values/bound; snakemake's validate rejects it too."""
    msg = _error(cfg)
    line = next((ln for ln in msg.splitlines() if ln.strip().startswith(where + ":")), None)
    assert line is not None, f"no error line for {where}:\n{msg}"
    for t in texts:
        assert t in line, f"{t!r} missing from {line!r}"


_ONE_PER_CONSTRAINT = {}
for _c in _invalid_cases():
    _ONE_PER_CONSTRAINT.setdefault(_c[0].rsplit("-", 1)[-1], _c)


@pytest.mark.parametrize("cfg,where", [c[1:3] for c in _ONE_PER_CONSTRAINT.values()], ids=list(_ONE_PER_CONSTRAINT))
def test_reject_invalid_config_in_snakemake_validate(cfg, where):
    """The workflow's validate (common.smk) rejects the same configs and names the key (one per constraint kind)."""
    validate = pytest.importorskip("snakemake.utils").validate
    with pytest.raises(Exception) as exc:   # snakemake.exceptions.WorkflowError
        validate(copy.deepcopy(cfg), schema=str(SCHEMA))
    assert "Error validating config file" in str(exc.value) and path_tail(where) in str(exc.value)


def path_tail(where: str) -> str:
    """The last key name of a path (snakemake's message quotes the schema path, not ours)."""
    return re.sub(r"\[\d+\]$", "", where).rsplit(".", 1)[-1]
