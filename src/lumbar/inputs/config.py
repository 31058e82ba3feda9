"""Workflow configuration: load, validate against the JSON schema, fill defaults.

The schema is ``workflow/schemas/config.schema.yaml``, the same file the Snakemake
workflow validates against (``workflow/rules/common.smk``), so the library and the
workflow cannot disagree about what a valid configuration is. Usable without Snakemake::

    from lumbar.inputs.config import load_config
    cfg = load_config("config/config.yaml")      # or a dict
    cfg["fsu"]["moments_nm"]                     # defaults filled

Invalid input raises :class:`ConfigError`, whose message names the key path
(``fsu.moments_nm[2]``) and the allowed values or form.
"""
from __future__ import annotations

import copy
import functools
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from jsonschema import Draft202012Validator, validators

from . import resources

__all__ = ["ConfigError", "load_config", "default_schema_path", "key_path", "resolve_path", "default_geometry_path",
           "schema_defaults"]

_SCHEMA_RELPATH = resources.SCHEMA_RELPATH


class ConfigError(ValueError):
    """Invalid configuration; ``errors`` lists (key path, message) pairs."""

    def __init__(self, errors: list[tuple[str, str]]):
        self.errors = errors
        lines = [f"{path}: {msg}" for path, msg in errors]
        super().__init__("invalid configuration:\n  " + "\n  ".join(lines))


def default_schema_path() -> Path:
    """The workflow schema: the checkout's, or the copy shipped in the wheel (:mod:`lumbar.inputs.resources`)."""
    path = resources.schema_path()
    if not path.is_file():
        raise ConfigError([("<schema>", f"config schema not found at {path}; "
                            "pass schema=<path to workflow/schemas/config.schema.yaml>")])
    return path


def key_path(parts) -> str:
    """Render a jsonschema path deque as ``a.b[2].c`` (``<root>`` when empty)."""
    out = ""
    for p in parts:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            out += ("." if out else "") + str(p)
    return out or "<root>"


def _with_defaults(validator_class):
    """Validator that fills ``default`` values (deep-copied, so the schema stays pristine)."""
    validate_properties = validator_class.VALIDATORS["properties"]

    def set_defaults(validator, properties, instance, schema):
        if isinstance(instance, dict):
            for name, sub in properties.items():
                if "default" in sub and name not in instance:
                    instance[name] = copy.deepcopy(sub["default"])
        yield from validate_properties(validator, properties, instance, schema)

    return validators.extend(validator_class, {"properties": set_defaults})


_DefaultFilling = _with_defaults(Draft202012Validator)


def _describe(error) -> tuple[str, str]:
    """(key path, human message with the allowed values/form) for one jsonschema error."""
    path = list(error.absolute_path)
    sch = error.schema if isinstance(error.schema, dict) else {}
    v = error.validator
    if v == "additionalProperties":
        allowed = sorted(sch.get("properties", {}))
        extra = sorted(set(error.instance) - set(allowed)) if isinstance(error.instance, dict) else []
        key = key_path(path + [extra[0]]) if extra else key_path(path)
        return key, f"unknown key {', '.join(map(repr, extra))}; allowed keys: {', '.join(allowed)}"
    if v == "enum":
        return key_path(path), f"{error.instance!r} is not allowed; allowed values: {', '.join(map(str, error.validator_value))}"
    if v == "type":
        return key_path(path), f"{error.instance!r} has the wrong type; expected {error.validator_value}"
    if v in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        op = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=", "exclusiveMaximum": "<"}[v]
        desc = sch.get("description", "")
        return key_path(path), f"{error.instance!r} is out of range; expected a value {op} {error.validator_value}" + (
            f" ({desc})" if desc else "")
    if v == "minItems":
        return key_path(path), f"must list at least {error.validator_value} item(s); got {error.instance!r}"
    if v == "uniqueItems":
        return key_path(path), f"items must be unique; got {error.instance!r}"
    if v == "minLength":
        return key_path(path), "must be a non-empty string"
    return key_path(path), error.message


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that rejects a key repeated in one mapping (PyYAML keeps the last one silently: a second
    ``fsu:`` section would replace the first)."""

    def construct_mapping(self, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen and key != "<<":
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first at line {seen[key] + 1}); each key may appear once "
                    "per mapping: the later one would silently replace the earlier", key_node.start_mark)
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def check_unique_keys(path) -> None:
    """Raise ConfigError "line L: duplicate key 'k' (first at line F); ..." when a YAML config file repeats a
    key in one mapping (used by the workflow on every --configfile, whose own loader keeps the last key)."""
    with open(path) as fh:
        try:
            yaml.load(fh, Loader=_UniqueKeyLoader)
        except yaml.constructor.ConstructorError as exc:
            mark = exc.problem_mark
            raise ConfigError([("<file>", f"line {mark.line + 1}: {exc.problem}")]) from None


def _read(path_or_dict) -> dict:
    if isinstance(path_or_dict, Mapping):
        return copy.deepcopy(dict(path_or_dict))
    path = Path(path_or_dict)
    try:
        with open(path) as fh:
            data = yaml.load(fh, Loader=_UniqueKeyLoader)
    except OSError as exc:
        raise ConfigError([("<file>", f"cannot read {path}: {exc}")]) from exc
    except yaml.YAMLError as exc:
        raise ConfigError([("<file>", f"{path} is not valid YAML: {exc}")]) from exc
    return {} if data is None else data


_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


@functools.lru_cache(maxsize=8)
def _schema_doc(path: str, mtime_ns: int) -> dict:
    """The parsed schema, cached by path and modification time (never modified: defaults are deep-copied)."""
    with open(path) as fh:
        return yaml.load(fh, Loader=_SafeLoader)


def resolve_path(path: str | Path) -> Path:
    """A config path (relative to the working directory, normally the repository root): as given when it exists
    there or is absolute, else relative to :func:`lumbar.inputs.resources.root` (the checkout root, or the wheel's
    bundled copy of ``data/``; for library and CLI use from another directory)."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    root = resources.root() / p
    return root if root.exists() else p


@functools.lru_cache(maxsize=1)
def _all_defaults() -> dict:
    return load_config({})


def schema_defaults(*keys: str):
    """The schema's default of a configuration key (``schema_defaults("discovery")``: the section with every
    default filled; no key: the whole default configuration). The schema is the one owner of the defaults; the
    library reads them here instead of repeating them. Returns a new object (deep copy)."""
    d = _all_defaults()
    for k in keys:
        d = d[k]
    return copy.deepcopy(d)


def default_geometry_path() -> Path:
    """The configuration's default ``geometry.path`` (the Visible Human folder), resolved by :func:`resolve_path`."""
    return resolve_path(schema_defaults("geometry", "path"))


def load_config(path_or_dict: str | Path | Mapping[str, Any], schema: str | Path | None = None) -> dict:
    """Load a YAML file (or copy a dict), validate it against the schema, fill defaults.

    Returns a new dict; the input mapping is not modified. Raises :class:`ConfigError`
    listing every problem, each with its key path.
    """
    data = _read(path_or_dict)
    if not isinstance(data, dict):
        raise ConfigError([("<root>", f"expected a mapping of sections, got {type(data).__name__}")])
    schema_path = Path(schema) if schema is not None else default_schema_path()
    validator = _DefaultFilling(_schema_doc(str(schema_path.resolve()), schema_path.stat().st_mtime_ns))
    errors = sorted(validator.iter_errors(data), key=lambda e: (key_path(e.absolute_path), e.validator))
    if errors:
        raise ConfigError([_describe(e) for e in errors])
    return data
