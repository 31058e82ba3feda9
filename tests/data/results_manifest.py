"""Write tests/data/results_sha256_test_config.json: the SHA-256 of every result table of the test-config DAG
outside the muscle model (whose solver and Sobol method issue 16 changed) and outside the timing files.

Usage, after `snakemake --cores 2 --configfile config/test/config.yaml` in a checkout (or a copy):
    python tests/data/results_manifest.py <repo>/results
Re-write it only when a change is meant to change results, and say which in the commit.
"""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
MANIFEST = HERE / "results_sha256_test_config.json"
# muscle-model tables: changed by issue 16; *_vs_paper: their paper columns come from ../shared
# (paths.published_model_results), which the test DAG's copy of the repository does not have beside it
EXCLUDE = ("benchmarks/", "muscle", "sobol", "sensitivity", "in_vivo", "flexion_relaxation", "_vs_paper")


def covered(results: Path) -> list[str]:
    """Relative paths of the CSV tables the manifest covers."""
    return sorted(str(p.relative_to(results)) for p in results.rglob("*.csv")
                  if not any(e in str(p.relative_to(results)) for e in EXCLUDE))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def main(results):
    results = Path(results)
    out = {rel: digest(results / rel) for rel in covered(results)}
    MANIFEST.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(f"{MANIFEST}: {len(out)} tables")


if __name__ == "__main__":
    main(sys.argv[1])
