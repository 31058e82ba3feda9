"""What the workflow's discovery rules share (workflow/rules/discover.smk; one script per rule): the configuration
a job gets from its inputs, one discovery case run with its outputs checked, and the line its log keeps."""
from __future__ import annotations

import copy
from pathlib import Path

from .outputs import run


def _paths(item) -> list:
    """A job's input entry (a path, a list of paths or nothing) as a list of strings."""
    if item is None:
        return []
    if isinstance(item, (str, Path)):
        return [str(item)]
    return [str(p) for p in item]


def job_config(cfg, inputs) -> dict:
    """A deep copy of the rule's discovery configuration ``cfg`` completed by the job's named ``inputs``
    (``snakemake.input`` or a dict): the nominal IDP model table (``idp_model``), the null banks of virtual
    specimens (``bank`` / ``banks``: files ``specimen_bank_rom.csv`` / ``specimen_bank_idp.csv``), the calibrated
    unit's posterior band (``model_bands``) and the in-vivo segment loads (``segment_loads``)."""
    cfg = copy.deepcopy(dict(cfg))
    idp_model = next(iter(_paths(inputs.get("idp_model"))), None)
    if idp_model and Path(idp_model).is_file():
        cfg["discovery"]["idp_model_table"] = str(idp_model)
    for p in bank_paths(inputs):
        for name in ("rom", "idp"):
            if Path(p).name == f"specimen_bank_{name}.csv":
                cfg["discovery"][f"specimen_bank_{name}"] = p
    model_bands = next(iter(_paths(inputs.get("model_bands"))), None)
    if model_bands:
        cfg["discovery"]["model_bands"] = str(model_bands)
    segment_loads = next(iter(_paths(inputs.get("segment_loads"))), None)
    if segment_loads:
        cfg["discovery"]["in_vivo_segment_loads"] = str(segment_loads)
    return cfg


def bank_paths(inputs) -> list:
    """The job's bank inputs (``bank`` and ``banks``), in that order."""
    return [p for k in ("bank", "banks") for p in _paths(inputs.get(k))]


def fixture_idp_paths(inputs) -> list:
    """The IDP fixture specimens among the job's bank inputs (``fixture_specimens_idp_<part>.csv``), sorted."""
    return sorted(p for p in bank_paths(inputs) if Path(p).name.startswith("fixture_specimens_idp_"))


def run_case(cfg, measured, outputs, out_dir) -> dict:
    """One discovery on the table ``measured`` (:func:`lumbar.discovery.outputs.run`), its files in ``out_dir``;
    every path of ``outputs`` (the rule's) must exist afterwards. Returns the result record."""
    r = run(cfg, measured, out_dir)
    for p in outputs:
        if not Path(p).is_file():
            raise RuntimeError(f"discovery on {measured}: expected output {p} was not written "
                               f"(outputs go to {out_dir})")
    return r


def case_summary(r: dict) -> str:
    """The log line of one discovery's result record: what it named, the estimate, the gaps and the decision."""
    return (f"named {r['named_effect']} (estimate {r['parameter_estimate']}), gap {r['gap_before']:.2f} -> "
            f"{r['gap_after']:.2f}; {r['decision']}")


def run_case_job(job, log) -> dict:
    """The job of one discovery case rule (``discovery_default``, ``_va_artefact``, ``_intact_rom``, ``_in_vivo``):
    the rule's configuration completed by its inputs (:func:`job_config`), the discovery on ``input.measured`` with
    its files beside ``output.discovery`` (:func:`run_case`), one log line (:func:`case_summary`). ``job``: the
    Snakemake object (or the scripts' command-line stand-in)."""
    cfg = job_config(job.params.cfg, job.input)
    r = run_case(cfg, job.input.measured, job.output, Path(job.output.discovery).parent)
    log.info("%s on %s: %s", job.rule, job.input.measured, case_summary(r))
    return r
