"""The ``lumbar`` command: one entry point for the package's command lines.

::

    lumbar fsu --moment 10 --direction all          # range of motion of one motion segment (lumbar.experiments.fsu)
    lumbar discovery --config CONFIG --measured FILE.csv --out DIR   # discrepancy discovery (lumbar.discovery.cli)
    lumbar landmarks MESH_DIR --units mm --axes LPS --out DIR        # a specimen's landmarks (lumbar.plots.specimen)
    lumbar export-opensim --set calibrated --levels L4-L5            # units as OpenSim models (lumbar.experiments.export_opensim)

``python -m lumbar.cli ...`` is the same without the installed script. Each subcommand delegates its arguments
unchanged to the ``main()`` of its module (``lumbar <command> --help`` shows them), and its exit status is the
command's.
"""
from __future__ import annotations

import sys

from .discovery import cli as discovery_cli
from .experiments import fsu


def _landmarks(argv, prog):
    from .plots import specimen  # noqa: PLC0415 - matplotlib and the mesh code only for this command (fsu starts fast)
    return specimen.main(argv, prog=prog)


def _export_opensim(argv, prog):
    from .experiments import export_opensim  # noqa: PLC0415
    return export_opensim.main(argv, prog=prog)


#: subcommand -> (main(argv, prog), one-line summary)
COMMANDS = {
    "fsu": (fsu.main, "range of motion of one functional spinal unit under pure moments"),
    "discovery": (discovery_cli.main, "discrepancy discovery: which missing effect explains a measured table"),
    "landmarks": (_landmarks, "a specimen's project frame, landmarks, tables and QA figures from its meshes"),
    "export-opensim": (_export_opensim, "a characteristic set's units as OpenSim 4.6 models, checked in OpenSim"),
}


def _usage(prog: str) -> str:
    width = max(map(len, COMMANDS))
    lines = [f"usage: {prog} {{{','.join(COMMANDS)}}} [ARGS ...]", "", "commands:"]
    lines += [f"  {name:<{width}}  {summary}" for name, (_, summary) in COMMANDS.items()]
    lines += ["", f"`{prog} <command> --help` lists a command's arguments."]
    return "\n".join(lines)


def main(argv=None, prog: str = "lumbar") -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(_usage(prog))
        return 0 if args else 2
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        print(_usage(prog), file=sys.stderr)
        print(f"\n{prog}: error: unknown command {name!r}", file=sys.stderr)
        return 2
    return COMMANDS[name][0](rest, prog=f"{prog} {name}")


if __name__ == "__main__":
    sys.exit(main(prog="python -m lumbar.cli"))
