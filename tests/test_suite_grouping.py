"""The suite's own machinery: the xdist groups of tests/conftest.py keep the tests of an expensive module-scoped fixture
on one worker, so the fixture is built once. Under pytest 9.2 with pytest-xdist 3.8 the groups were silently ignored
(the group suffix in the node id no longer took effect; pytest-dev/pytest-xdist#1386): every module fixture was built
on both workers, which nearly doubled the suite's time without any test failing. This test runs the pinned stack on a
small module whose fixture records each build."""
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("xdist")

MODULE = textwrap.dedent('''
    import os
    import pytest

    @pytest.fixture(scope="module")
    def expensive():
        with open(os.environ["BUILDS"], "a") as f:
            f.write("built\\n")
        return 1

    @pytest.mark.xdist_group("{group}")
    @pytest.mark.parametrize("i", range(8))
    def test_reads_it(expensive, i):
        assert expensive == 1
''')


def _builds(tmp_path, group: str, dist: str) -> int:
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "test_grouped.py").write_text(MODULE.format(group=group))
    builds = tmp_path / "builds.txt"
    builds.unlink(missing_ok=True)
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2", "--dist", dist,
                        "-c", str(tmp_path / "pytest.ini"), "--rootdir", str(tmp_path), str(tmp_path)],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env={**__import__("os").environ, "BUILDS": str(builds), "PYTEST_ADDOPTS": ""})
    assert r.returncode == 0, r.stdout + r.stderr
    return builds.read_text().count("built")


def test_a_grouped_module_fixture_is_built_once_on_two_workers(tmp_path):
    assert _builds(tmp_path, "one", "loadgroup") == 1
    # control: plain load balancing spreads the eight tests over both workers, each building the fixture
    assert _builds(tmp_path, "one", "load") == 2
