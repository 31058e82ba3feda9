"""The `lumbar fsu` command line (`python -m lumbar.cli fsu`, lumbar.experiments.fsu.main): exit codes and messages;
the `lumbar` entry point's dispatch (lumbar.cli)."""
import subprocess
import sys

import pytest

from lumbar import cli


def run(*args, module=("lumbar.cli", "fsu")):
    return subprocess.run([sys.executable, "-m", *module, *args], capture_output=True, text=True, timeout=120)


def test_fsu_module_runs_as_a_script_too():
    r = run("--help", module=("lumbar.experiments.fsu",))
    assert r.returncode == 0, r.stderr
    assert "--moment" in r.stdout


@pytest.mark.parametrize("command,needle", [("fsu", "--moment"), ("discovery", "--measured")])
def test_entry_point_delegates_to_the_command_main(command, needle, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main([command, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert needle in out and f"lumbar {command}" in out


def test_entry_point_lists_commands_and_rejects_unknown_ones(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "fsu" in out and "discovery" in out
    assert cli.main([]) == 2
    assert cli.main(["nonsense"]) == 2
    assert "unknown command 'nonsense'" in capsys.readouterr().err


def test_cli_prints_rom_and_exits_zero_when_all_converge():
    """The printed ROM is the library's own ROM in degrees (range_of_motion in this process, same inputs), to the
    printed three decimals: a ROM printed in radians (2.358 deg as 0.041) or from another row fails."""
    r = run("--moment", "5", "--direction", "flexion,axial_rotation", "--geometry", "synthetic")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    head = lines[1].split()
    printed = {(row[head.index("direction")]): row for row in (ln.split() for ln in lines[2:])}
    assert set(printed) == {"flexion", "axial_rotation"}, r.stdout
    from lumbar.experiments.fsu import build_fsu, range_of_motion
    from lumbar.geometry import load_geometry
    from lumbar.inputs.characteristics import resolve_characteristic_set
    fsu = build_fsu(load_geometry("synthetic"), resolve_characteristic_set(
        "calibrated", calibrated_dir="results/calibration/characteristics"), "L4-L5")
    lib = range_of_motion(fsu, [5.0], ("flexion", "axial_rotation")).set_index("direction")
    for d, row in printed.items():
        assert row[head.index("converged")] == "True", r.stdout
        rom = float(row[head.index("rom_deg")])
        assert abs(rom - lib.loc[d, "rom_deg"]) <= 0.0005 + 1e-9, (d, rom, lib.loc[d, "rom_deg"])
        assert lib.loc[d, "rom_deg"] > 1.0          # degrees: 5 N*m moves the unit by more than a degree


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
def test_reject_bad_cli_input_with_a_message_naming_it(args, needle, capsys):
    """In this process (the exit codes of a real process: the two tests above): argparse's exit 2, the message
    naming the bad value, and no ROM printed."""
    argv = ["fsu", "--geometry", "synthetic", *args] if "--geometry" not in args else ["fsu", *args]
    try:
        code = cli.main(argv)                   # a value the solver refuses: "error: ..." and 2
    except SystemExit as e:                     # a flag argparse refuses: its usage message and exit 2
        code = e.code
    assert code == 2
    out, err = capsys.readouterr()
    assert needle in err and out == ""
