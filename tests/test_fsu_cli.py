"""The `python -m lumbar.fsu` command line: exit codes and messages."""
import subprocess
import sys

import pytest


def run(*args):
    return subprocess.run([sys.executable, "-m", "lumbar.fsu", *args], capture_output=True, text=True, timeout=120)


def test_cli_prints_rom_and_exits_zero_when_all_converge():
    r = run("--moment", "5", "--direction", "flexion,axial_rotation", "--geometry", "synthetic")
    assert r.returncode == 0, r.stderr
    assert "flexion" in r.stdout and "axial_rotation" in r.stdout and "True" in r.stdout


def test_cli_exits_one_and_says_so_when_a_solve_does_not_converge():
    r = run("--moment", "10.5", "--direction", "flexion", "--stage", "wo_all", "--geometry", "synthetic")
    assert r.returncode == 1
    assert "did NOT converge" in r.stderr and "NaN" in r.stdout


@pytest.mark.parametrize("args,needle", [
    (("--moment", "-1"), "--moment"),
    (("--direction", "sideways"), "sideways"),
    (("--stage", "wo_everything"), "wo_everything"),
    (("--geometry", "nonsense"), "nonsense"),
    (("--facet-stiffness", "-5"), "facet stiffness"),
    (("--shear-stiffness", "0"), "shear stiffness"),
])
def test_reject_bad_cli_input_with_a_message_naming_it(args, needle):
    r = run("--geometry", "synthetic", *args) if "--geometry" not in args else run(*args)
    assert r.returncode == 2
    assert needle in r.stderr
