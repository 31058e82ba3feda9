"""Command line of the discrepancy discovery: ``python -m lumbar.discovery --config CONFIG --measured FILE.csv
--out DIR`` (writes the outputs of :func:`lumbar.discovery.outputs.run`, prints the result's headline as JSON)."""
from __future__ import annotations

import argparse
import json
import logging
import sys

from ..inputs.config import ConfigError, load_config
from .detect import DiscoveryInputError
from .outputs import run

DESCRIPTION = ("Discrepancy discovery: where do model and measurement disagree, and which missing effect "
               "explains it?")


# ------------------------------------------------------------------ command line
def main(argv=None, prog: str = "python -m lumbar.discovery") -> int:
    ap = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    ap.add_argument("--config", required=True, help="workflow config YAML (config/config.yaml)")
    ap.add_argument("--measured", required=True, help="measured table in a project experiment schema (CSV)")
    ap.add_argument("--out", required=True, help="output directory")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = load_config(a.config)
        r = run(cfg, a.measured, a.out)
    except (DiscoveryInputError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(json.dumps({k: r[k] for k in ("experiment", "named_effect", "parameter_estimate", "gap_before",
                                        "gap_after", "confidence")}, default=float))
    return 0
