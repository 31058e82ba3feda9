"""Where the package's data live: the one owner of that fact.

The hand-curated tables and the embedded geometry live in the repository's ``data/`` and the configuration
schema in ``workflow/schemas/config.schema.yaml``; the Snakemake workflow reads them there. The library finds
them through this module only:

* running from a checkout (``<root>/src/lumbar``, editable install or ``PYTHONPATH=src``): the checkout's
  root, so an edit to ``data/`` is seen at once;
* installed from a wheel: the copies that the build (``setup.py``) put under ``lumbar/_resources/``
  (``data/...`` and ``workflow/schemas/config.schema.yaml``, the same relative layout).

``root()`` is the directory that repository-relative paths (``data/...``, the config's defaults) resolve
against. Nothing here checks that a file exists; the readers report a missing file with its path.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["root", "in_checkout", "data_dir", "schema_path", "SCHEMA_RELPATH"]

SCHEMA_RELPATH = Path("workflow") / "schemas" / "config.schema.yaml"
_PACKAGE = Path(__file__).resolve().parents[1]   # src/lumbar/inputs/resources.py -> src/lumbar
_CHECKOUT = _PACKAGE.parents[1]          # src/lumbar -> repository root
_BUNDLED = _PACKAGE / "_resources"       # written by setup.py's build step into the wheel


def in_checkout() -> bool:
    """True when this package is ``<root>/src/lumbar`` of a repository checkout (it has the schema)."""
    return _PACKAGE.parent.name == "src" and (_CHECKOUT / SCHEMA_RELPATH).is_file()


def root() -> Path:
    """The repository root of a checkout, else the wheel's bundled resource directory."""
    return _CHECKOUT if in_checkout() else _BUNDLED


def data_dir() -> Path:
    """The ``data`` directory (characteristics, geometry, muscles, cables, ...)."""
    return root() / "data"


def schema_path() -> Path:
    """The configuration schema (``workflow/schemas/config.schema.yaml``)."""
    return root() / SCHEMA_RELPATH
