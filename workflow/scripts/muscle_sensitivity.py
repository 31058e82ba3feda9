"""Muscle-driven model (paper 2), rule muscle_sensitivity: one Paramspace chunk of the sensitivity study (one
parameter, one fixed SSL or none), every value x muscle-group scope x posture solved from the baseline postures.

By hand: python workflow/scripts/muscle_sensitivity.py muscle_sensitivity parameter=spt_n_per_cm2 ssl_um=none \
    --configfile config/test/config.yaml      (the rule's wildcards as name=value; --output to redirect)
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402
import time  # noqa: E402

from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.muscles import muscle_model as mm  # noqa: E402
from lumbar.muscles import muscle_sensitivity as sens  # noqa: E402


def main(snakemake, log):
    p = snakemake.params.muscle_model
    param, ssl = snakemake.wildcards.parameter, snakemake.wildcards.ssl_um
    s = p["sensitivity"]
    rows = sens.sensitivity_rows(param, None if ssl == "none" else float(ssl), s[param], s["scopes"], s["postures"])
    model = mm.model_from_config(p, Path(_common.as_list(snakemake.input.passive)[0]).parent)
    solver = mm.make_solver(model, p["solver"])
    t0 = time.perf_counter()
    log.info("chunk %s (ssl %s): %d scenarios", param, ssl, len(rows))
    out = sens.run_sensitivity(model, solver, rows, mm.read_baseline(snakemake.input.baseline), p["disc_area_m2"],
                             label=f"sensitivity {param} (ssl {ssl})")
    log.info("chunk %s (ssl %s): %d scenarios in %.1f s, %d not reached, %d reached but not certified "
             "(max KKT residual %.1e)", param, ssl, len(out), time.perf_counter() - t0, int((~out["reached"]).sum()),
             int((out["reached"] & ~out["certified"]).sum()), out["kkt_residual"].max())
    # the study's one WARNING for uncertified scenarios comes from rule muscle_sensitivity_table (all chunks)
    write_table_atomic(out, snakemake.output[0])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
