"""Shared helpers of the workflow scripts (not part of the library; import by path).

Every script in this directory runs two ways:
  * from Snakemake (``script:`` directive): the global ``snakemake`` object is given;
  * by hand, for debugging: ``python workflow/scripts/<stage>.py <rule> [--configfile ...]``,
    which builds a stand-in object with the same attributes from the config and argparse.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[2]


class _Named(list):
    """List with attribute access, like snakemake's Namedlist (``snakemake.output[0]``, ``.params.x``)."""

    def __init__(self, items=(), **named):
        super().__init__(list(items) + [v for v in named.values() if v not in items])
        for k, v in named.items():
            setattr(self, k, v)


def _named(spec):
    """Namedlist stand-in from a list (positional) or a dict (named entries)."""
    return _Named(**spec) if isinstance(spec, dict) else _Named(spec)


def stand_in(rules: dict, doc: str = "", argv=None):
    """Build a stand-in ``snakemake`` object from argparse for running a script by hand.

    ``rules`` maps rule name -> function(config) -> dict(output=[...], params={...}, input=[...]),
    mirroring the rule in workflow/rules/; the config is validated and filled by lumbar.config.
    """
    from lumbar.config import load_config

    ap = argparse.ArgumentParser(description=doc)
    ap.add_argument("rule", choices=sorted(rules))
    ap.add_argument("--configfile", default=str(ROOT / "config" / "config.yaml"))
    ap.add_argument("--output", nargs="+", help="override the rule's output path(s)")
    ap.add_argument("--log", default=None, help="log file (default: stderr only)")
    args = ap.parse_args(argv)
    config = load_config(args.configfile)
    spec = rules[args.rule](config)
    return SimpleNamespace(
        rule=args.rule,
        config=config,
        input=_named(spec.get("input", [])),
        output=_Named(args.output) if args.output else _named(spec["output"]),
        params=SimpleNamespace(**spec.get("params", {})),
        log=_Named([args.log] if args.log else []),
        wildcards=SimpleNamespace(),
        threads=1,
    )


def setup_logging(smk) -> logging.Logger:
    """Log to the rule's log file (``snakemake.log[0]``) if it has one, and to stderr."""
    handlers = [logging.StreamHandler(sys.stderr)]
    if len(smk.log):
        Path(smk.log[0]).parent.mkdir(parents=True, exist_ok=True)
        handlers.append(logging.FileHandler(smk.log[0], mode="w"))
    logging.basicConfig(level=logging.INFO, handlers=handlers, force=True,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.captureWarnings(True)
    log = logging.getLogger(f"lumbar.workflow.{smk.rule}")
    previous = sys.__excepthook__       # not sys.excepthook: calling setup_logging twice must not chain

    def log_uncaught(exc_type, exc, tb):   # the failure (file, row, column) goes into the rule's log too
        if not issubclass(exc_type, KeyboardInterrupt):
            log.error("rule %s failed: %s", smk.rule, exc, exc_info=(exc_type, exc, tb))
        previous(exc_type, exc, tb)

    sys.excepthook = log_uncaught
    return log


def as_list(item):
    """Snakemake input entry (str, list or Namedlist) as a list of paths."""
    if item is None:
        return []
    if isinstance(item, (str, bytes)) or hasattr(item, "__fspath__"):
        return [str(item)]
    return [str(x) for x in item]


def first(item):
    """The single path of an input that may be a path, an empty list or a one-element (Named)list."""
    if isinstance(item, (str, Path)):
        return str(item)
    items = list(item)
    return str(items[0]) if items else None
