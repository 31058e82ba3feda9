"""Write the byte-identity guard of the test-config DAG: tests/data/results_sha256_test_config.json,
the SHA-256 of every result table outside the muscle model (whose solver and Sobol method the speed work changed)
and outside the timing files, and tests/data/results_test_config.tar.gz, the tables themselves (the reference
for the numeric comparison that tests/test_results_identity.py makes where a digest differs: floating-point
round-off differs between CPUs and BLAS builds, so a machine other than the one that wrote the manifest may
not reproduce every byte).

Usage, one line from the repository root: run the test-config DAG in a fresh copy of the checkout, exactly as the
test session does (tests/conftest.py: copy_repo, no results/, .snakemake/ or logs/ carried over, 2 cores), and
write both files from that run:
    python tests/data/results_manifest.py --run
or, after `snakemake --cores 2 --configfile config/test/config.yaml` in a fresh copy:
    python tests/data/results_manifest.py <copy>/results
Re-write it only when a change is meant to change results (or on moving the reference machine), and say which
in the commit.
"""
from __future__ import annotations

import gzip
import hashlib
import io
import json
import sys
import tarfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
MANIFEST = HERE / "results_sha256_test_config.json"
SNAPSHOT = HERE / "results_test_config.tar.gz"
# *_vs_paper: their paper columns come from ../shared (paths.published_model_results), which the test DAG's copy of
# the repository does not have beside it; sobol: the polynomial-chaos fit to 16 samples and its bootstrap quantiles
# amplify the solver's certified tolerance beyond the fit tolerance. The muscle model's other tables (segment loads,
# in-vivo validation, flexion-relaxation, sensitivity, paper 2's claims) are covered: downstream of a certified
# optimum (IPOPT tol 1e-5), compared to the fit tolerance of tests/test_results_identity.py.
EXCLUDE = ("benchmarks/", "sobol", "_vs_paper")


def covered(results: Path) -> list[str]:
    """Relative paths of the CSV tables the manifest covers."""
    return sorted(str(p.relative_to(results)) for p in results.rglob("*.csv")
                  if not any(e in str(p.relative_to(results)) for e in EXCLUDE))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_snapshot(path: Path = SNAPSHOT) -> dict[str, bytes]:
    """{relative path: CSV bytes} of the reference tables."""
    with tarfile.open(path, "r:gz") as t:
        return {m.name: t.extractfile(m).read() for m in t.getmembers() if m.isfile()}


def write_snapshot(results: Path, rels: list[str], path: Path = SNAPSHOT):
    """The tables as a deterministic tar.gz (sorted, no times, owners or modes that vary)."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=tarfile.USTAR_FORMAT) as t:
        for rel in rels:
            data = (results / rel).read_bytes()
            info = tarfile.TarInfo(rel)
            info.size, info.mtime, info.mode = len(data), 0, 0o644
            t.addfile(info, io.BytesIO(data))
    path.write_bytes(gzip.compress(buf.getvalue(), mtime=0))


def main(results):
    results = Path(results)
    rels = covered(results)
    out = {rel: digest(results / rel) for rel in rels}
    MANIFEST.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    write_snapshot(results, rels)
    print(f"{MANIFEST}, {SNAPSHOT}: {len(out)} tables")


def run_and_write():
    """The test session's DAG run (tests/conftest.py: copy_repo, TEST_CONFIG) in a temporary copy, then main()."""
    import subprocess  # noqa: PLC0415
    import tempfile  # noqa: PLC0415
    sys.path.insert(0, str(HERE.parent))
    import conftest  # noqa: PLC0415 - the session's copy rule and configuration, not a mirror of them
    with tempfile.TemporaryDirectory(prefix="lumbar_reference_") as tmp:
        work = conftest.copy_repo(Path(tmp) / "repo")
        subprocess.run([sys.executable, "-m", "snakemake", "--cores", "2", "--configfile", conftest.TEST_CONFIG],
                       cwd=work, check=True)
        main(work / "results")


if __name__ == "__main__":
    if sys.argv[1:] == ["--run"]:
        run_and_write()
    else:
        main(sys.argv[1])
