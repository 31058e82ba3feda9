"""Shared helpers of the workflow scripts (not part of the library; a script imports it from its own folder).

Every script in this directory runs two ways and reads the same object either way:
  * from Snakemake (``script:`` directive): the global ``snakemake`` object is given;
  * by hand, for debugging (from the repository root, or from another working directory as ``snakemake -s``):
        python workflow/scripts/<rule>.py <rule> [wildcard=value ...] [--configfile F] [--output P ...] [--log F]
    :func:`mock_snakemake` parses the Snakefile with Snakemake's own API and builds the job of ``<rule>``, with the
    rule's real input, output, params, wildcards, threads and config. Paths are written only in the rules
    (workflow/rules/*.smk); a script reads ``snakemake.input.<name>`` / ``snakemake.output.<name>``.

One script per rule, named like it (rules of a family share library functions, not a script); a script is::

    sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
    import _common  # noqa: E402

    def main(snakemake, log):
        ...

    if __name__ == "__main__":
        snakemake, log = _common.start(globals())
        main(snakemake, log)
"""
from __future__ import annotations

import argparse
import inspect
import logging
import os
import sys
from pathlib import Path

#: A script run by hand uses one BLAS/OpenMP thread, as Snakemake gives a rule of one thread (it sets these variables
#: for each job), so that a by-hand run reproduces the workflow's numbers: the last digits of a multithreaded BLAS
#: differ, and a solve at the edge of convergence can turn on them (measured: the muscle model's crate-close posture
#: converged with the machine's default BLAS threads and not with one). Set before numpy is imported (scripts import
#: this module first); a value already in the environment is kept.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
                    "NUMEXPR_NUM_THREADS")
for _name in THREAD_VARIABLES:
    os.environ.setdefault(_name, "1")

ROOT = Path(__file__).resolve().parents[2]
SNAKEFILE = ROOT / "Snakefile"


def _workflow(configfile=None):
    """The Snakefile parsed as ``snakemake [--configfile configfile]`` parses it in the current directory.

    The config is the one a real run gets: the Snakefile's ``configfile:`` extended by ``configfile``, validated
    and completed by workflow/rules/common.smk.
    """
    # Snakemake is imported only here: a script run by Snakemake never calls this module's by-hand path.
    # snakemake.api first: importing snakemake.workflow on its own runs into snakemake's import circle.
    import snakemake.api  # noqa: F401, PLC0415
    from snakemake.logging import LoggerManager, logger  # noqa: PLC0415
    from snakemake.settings.types import (  # noqa: PLC0415
        ConfigSettings,
        DAGSettings,
        OutputSettings,
        ResourceSettings,
        StorageSettings,
        WorkflowSettings,
    )
    from snakemake.workflow import Workflow  # noqa: PLC0415

    if configfile is not None and not Path(configfile).is_file():
        raise FileNotFoundError(f"config file {configfile} not found")
    settings = dict(config_settings=ConfigSettings(configfiles=[Path(configfile)] if configfile else []),
                    resource_settings=ResourceSettings(), workflow_settings=WorkflowSettings(),
                    storage_settings=StorageSettings(), dag_settings=DAGSettings(rerun_triggers=[]),
                    storage_provider_settings={})
    if "logger_manager" in inspect.signature(Workflow).parameters:     # required since snakemake 9.14.6
        settings["logger_manager"] = LoggerManager(logger, OutputSettings())
    workflow = Workflow(**settings)
    workflow.include(SNAKEFILE, overwrite_default_target=True)
    workflow.global_resources = {}
    return workflow


def _rule_script(rule) -> Path | None:
    """The file of a rule's ``script:`` directive (None for a rule without one)."""
    return (Path(str(rule.basedir)) / rule.script).resolve() if rule.is_script else None


def _job(workflow, rule: str, wildcards: dict):
    """The ``snakemake`` object of the job of ``rule`` with ``wildcards`` in the parsed ``workflow``."""
    from snakemake.dag import DAG  # noqa: PLC0415 - see _workflow
    from snakemake.jobs import Job  # noqa: PLC0415
    from snakemake.script import Snakemake  # noqa: PLC0415

    rules = {r.name: r for r in workflow.rules}
    if rule not in rules:
        raise ValueError(f"no rule {rule!r} in {SNAKEFILE}")
    r = rules[rule]
    wildcards = {k: str(v) for k, v in wildcards.items()}
    names = set(r.wildcard_names)
    if set(wildcards) != names:
        missing, unknown = sorted(names - set(wildcards)), sorted(set(wildcards) - names)
        raise ValueError(f"rule {rule} has the wildcards {sorted(names) or 'none'}: "
                         + (f"give {' '.join(f'{w}=...' for w in missing)}" if missing else f"not {unknown}"))
    job = Job(r, DAG(workflow, rules=[r]), wildcards)
    if names and not r.is_producer(str(job.output[0])):
        raise ValueError(f"rule {rule}: {job.output[0]} does not match its wildcard constraints "
                         f"{r.wildcard_constraints}")
    script = _rule_script(r)
    return Snakemake(job.input, job.output, job.params, job.wildcards, job.threads, job.resources, job.log,
                     workflow.config, r.name, None, script.parent if script else None)


def mock_snakemake(rule: str, configfile=None, **wildcards):
    """The ``snakemake`` object Snakemake hands the script of the job of ``rule`` with these ``wildcards``.

    The Snakefile is parsed with ``configfile`` (as ``snakemake --configfile``; None: the Snakefile's own
    ``configfile:``) in the current working directory, and the job is built as Snakemake's scheduler builds it:
    ``input``, ``output``, ``params``, ``log``, ``wildcards``, ``resources`` (snakemake Namedlists, paths as plain
    strings), ``threads``, ``config`` and ``rule``. Nothing is created or run; the inputs need not exist.
    E.g. ``mock_snakemake("muscle_sobol_chunk", "config/test/config.yaml", posture="standing", chunk=0)``.

    The approach of PyPSA-Eur's ``mock_snakemake`` (github.com/PyPSA/pypsa-eur, scripts/_helpers.py, the
    snakemake >= 8 API: a ``Workflow`` from the settings dataclasses, ``include`` of the Snakefile, a ``Job`` of
    the rule in a ``DAG`` of that rule alone, wrapped in ``snakemake.script.Snakemake``), written anew: here the
    working directory is never changed and the paths are kept as the rules write them.
    """
    return _job(_workflow(configfile), rule, wildcards)


def _override(namedlist, paths):
    """``namedlist`` (the job's output or log) with its items replaced by ``paths``, one for one, names kept."""
    new = type(namedlist)(toclone=[str(p) for p in paths])
    if paths:
        new._take_names(namedlist._get_names())
    return new


def from_command_line(script, doc: str | None = "", argv=None):
    """The ``snakemake`` object for running ``script`` by hand: the job of the rule named on the command line.

    ``<rule> [wildcard=value ...] [--configfile F] [--output P ...] [--log F]``. The rule must be one whose
    ``script:`` is ``script``. ``--output`` replaces the job's outputs one for one (their names kept: the same
    number of paths, in the rule's order); the log goes to stderr, and also to ``--log`` when given (the rule's
    own log file is not written by hand). The outputs' folders are created, as Snakemake does.
    """
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("rule", help="a rule whose script: is this file")
    ap.add_argument("wildcards", nargs="*", metavar="WILDCARD=VALUE", help="the job's wildcards, e.g. set=rupp2015")
    ap.add_argument("--configfile", default=None, help="as snakemake --configfile (default: the Snakefile's)")
    ap.add_argument("--output", nargs="+", help="replace the job's outputs, one path per output, in the rule's order")
    ap.add_argument("--log", default=None, help="log file (default: stderr only)")
    args = ap.parse_args(argv)
    wildcards = {}
    for item in args.wildcards:
        key, sep, value = item.partition("=")
        if not sep or not key:
            ap.error(f"wildcard {item!r}: expected NAME=VALUE")
        wildcards[key] = value
    workflow = _workflow(args.configfile)
    own = sorted(r.name for r in workflow.rules if _rule_script(r) == Path(script).resolve())
    if args.rule not in own:
        ap.error(f"rule {args.rule!r} does not run {Path(script).name}; its rules: {', '.join(own)}")
    try:
        smk = _job(workflow, args.rule, wildcards)
    except ValueError as e:
        ap.error(str(e))
    if args.output:
        if len(args.output) != len(smk.output):
            ap.error(f"rule {args.rule} has {len(smk.output)} output(s) ({' '.join(smk.output)}); "
                     f"--output gave {len(args.output)}")
        smk.output = _override(smk.output, args.output)
    smk.log = _override(smk.log, [args.log] if args.log else [])
    for p in smk.output:
        Path(p).parent.mkdir(parents=True, exist_ok=True)
    return smk


def start(script_globals: dict):
    """``(snakemake, log)`` for a script: Snakemake's object when Snakemake runs the script, else the job of the
    command line (:func:`from_command_line`); and the rule's logger (:func:`setup_logging`)."""
    smk = script_globals.get("snakemake")
    if smk is None:
        smk = from_command_line(script_globals["__file__"], script_globals.get("__doc__"))
    # with LUMBAR_PROFILE_DIR set (benchmarks/bench_dag.py), the job's phase times and equilibrium counts are written
    # at exit; start-up and imports end here
    from lumbar.mechanics import profile  # noqa: PLC0415
    profile.start_job(smk.rule, ",".join(f"{k}={v}" for k, v in dict(smk.wildcards.items()).items()))
    return smk, setup_logging(smk)


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


def set_fsu(smk, **kw):
    """(characteristic set name, the configured L4-L5 unit with the job's characteristic set ``{set}``): geometry
    from ``params.geometry``, level and stiffness overrides from ``params.fsu``, the set read from the folder of
    ``input.characteristics`` (a file or the folder); ``kw`` goes to ``lumbar.experiments.fsu.build_fsu``."""
    from lumbar.experiments.fsu import configured_unit  # noqa: PLC0415 - the library only for the jobs that build a unit
    from lumbar.geometry.configured import load_configured  # noqa: PLC0415
    from lumbar.inputs.characteristics import load_characteristic_set  # noqa: PLC0415

    g, f = smk.params.geometry, smk.params.fsu
    data_dir = Path(smk.input.characteristics)
    data_dir = data_dir.parent if data_dir.is_file() else data_dir
    geo = load_configured(g, levels=[f["level"]])
    cs = load_characteristic_set(smk.wildcards.set, data_dir=data_dir)
    fsu = configured_unit(geo, cs, f, **kw)
    return smk.wildcards.set, data_dir, fsu
