"""L2-S1 IDP stage, rule l2s1_idp: one characteristic set, 49 scenarios (7 muscle set-ups x 7 load cases) of the
L2-S1 spine with wire-cable muscles (lumbar.experiments.l2s1).

By hand: python workflow/scripts/l2s1_idp.py l2s1_idp set=rupp2015 --configfile config/test/config.yaml \
    --output /tmp/idp_rupp2015.csv
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

from lumbar.experiments import l2s1  # noqa: E402
from lumbar.experiments.fsu import unit_options  # noqa: E402
from lumbar.geometry.configured import load_configured  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402


def main(snakemake, log):
    name = snakemake.wildcards.set
    p, s = snakemake.params.l2s1, snakemake.params.solver
    d = Path(snakemake.input.characteristics)
    d = d if d.is_dir() else d.parent
    log.info("set %s: characteristics from %s", name, d)
    cs = load_characteristic_set(name, data_dir=d)
    g = snakemake.params.geometry
    geo = load_configured(g, levels=list(l2s1.LEVELS))
    df, sol = l2s1.run_set(geo, cs, l2s1.derive_cables(snakemake.input.cables), idp_formula=p["idp_formula"],
                           idp_kwargs={"area_m2": p["disc_area_m2"]} if p["idp_formula"] == "paper2" else None,
                           **unit_options(snakemake.params.fsu),
                           load_steps=s["load_steps"], max_iter=s["max_iter"],
                           tol=min(s["tol_force_n"], s["tol_moment_nm"]), moment_nm=p["moment_nm"])
    rf, rm = l2s1.equilibrium_residual(sol)
    df.insert(0, "set", name)
    df.insert(1, "geometry", geo.name)
    df["residual_force_n"], df["residual_moment_nm"] = rf, rm
    log.info("set %s: %d scenarios, %d not converged, max residual %.2e N %.2e N*m", name, len(df),
             int((~df["converged"]).sum()), rf[sol.converged].max(initial=0), rm[sol.converged].max(initial=0))
    write_table_atomic(df, snakemake.output[0])
    log.info("done: %s", ", ".join(map(str, snakemake.output)))

if __name__ == "__main__":
    snakemake, log = _common.start(globals())
    main(snakemake, log)
