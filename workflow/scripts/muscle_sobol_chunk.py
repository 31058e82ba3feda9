"""Muscle-driven model (paper 2), rule muscle_sobol_chunk: one posture, one chunk of the PCE training samples of the
Sobol study, solved from the baseline posture.

By hand: python workflow/scripts/muscle_sobol_chunk.py muscle_sobol_chunk posture=standing chunk=0 \
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
    posture, k = snakemake.wildcards.posture, int(snakemake.wildcards.chunk)
    sb = p["sobol"]
    X = sens.sobol_samples(sb["n_train"], snakemake.params.seed)
    rows = sens.sobol_chunk_rows(len(X), sb.get("chunks", 1), k)
    model = mm.model_from_config(p, Path(_common.as_list(snakemake.input.passive)[0]).parent)
    solver = mm.make_solver(model, p["solver"])
    t0 = time.perf_counter()
    log.info("Sobol %s, chunk %d of %d: samples %d-%d of %d (PCE training design, n_train %d)", posture, k + 1,
             sb.get("chunks", 1), rows[0], rows[-1], len(X), sb["n_train"])
    out = sens.sobol_evaluate(model, solver, mm.read_baseline(snakemake.input.baseline), X, rows, posture, sb["scope"],
                            p["disc_area_m2"], label=f"sobol {posture} chunk {k + 1}/{sb.get('chunks', 1)}")
    # one summary line: samples not reached are left out of the expansion, reached but uncertified ones are kept
    # (n_failed / n_uncertified of sobol_indices.csv): results of the study, not something to act on
    unc = out["reached"] & ~out["certified"]
    log.info("Sobol %s chunk %d: %d samples in %.1f s, %d not reached, %d reached but not certified%s", posture, k + 1,
             len(out), time.perf_counter() - t0, int((~out["reached"]).sum()), int(unc.sum()),
             f" (IPOPT: {', '.join(sorted(set(out.loc[unc, 'ipopt_status'].astype(str))))}; left out of the expansion)"
             if unc.any() else "")
    write_table_atomic(out, snakemake.output[0])

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
