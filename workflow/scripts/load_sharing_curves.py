"""Load-sharing stage, rule load_sharing_curves: for one characteristic set, the moment-rotation curves of every
stage and direction with the internal loads, and the follower-load compression curve (lumbar.experiments.load_sharing).

By hand: python workflow/scripts/load_sharing_curves.py load_sharing_curves set=calibrated \
    --configfile config/test/config.yaml
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

import numpy as np  # noqa: E402

from lumbar.experiments import load_sharing as LS  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    s, ls = snakemake.params.solver, snakemake.params.ls
    set_name, _, fsu = _common.set_fsu(snakemake, follower=True)
    moments = np.round(np.arange(0.0, ls["max_moment_nm"] + 1e-9, ls["moment_step_nm"]), 6)
    curves = LS.moment_rotation_curves(fsu, moments_nm=moments, stages=ls["stages"], max_iter=s["max_iter"])
    curves.insert(0, "set", set_name)
    comp = LS.axial_compression_curve(fsu, forces_n=np.arange(0.0, ls["compression_max_n"] + 1e-9,
                                                              ls["compression_step_n"]), max_iter=s["max_iter"])
    comp.insert(0, "set", set_name)
    bad = curves[curves["converged"] & (curves["moment_balance_residual_nm"] > 1e-6)]
    if len(bad):
        raise RuntimeError(f"set {set_name}: the structures' moments do not balance the applied moment in {len(bad)} "
                           f"converged steps (largest residual {bad['moment_balance_residual_nm'].max():.3g} N*m)")
    n_jump, n_bad = int(curves["jump"].sum()), int((~curves["converged"]).sum())
    log.info("set %s: %d curve steps (%d stages x %d directions), %d jumps >= %g deg, %d not converged; moment "
             "balance of the converged steps <= %.1e N*m; facet share of a %g N follower load %.3f", set_name,
             len(curves), len(ls["stages"]), len(LS.CURVE_DIRECTIONS), n_jump, LS.JUMP_DEG, n_bad,
             curves.loc[curves["converged"], "moment_balance_residual_nm"].max(), comp["force_n"].iloc[-1],
             comp["facet_share"].iloc[-1])
    write_table_atomic(curves, snakemake.output.curves)
    write_table_atomic(comp, snakemake.output.compression)

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
