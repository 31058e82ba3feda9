"""L2-S1 IDP stage: rules idp_surrogate (virtual_experiment.smk), l2s1_idp (one characteristic set,
49 scenarios), table5 (synopsis, outlier counts, comparison with the paper, internal loads, Table 5 grid,
Fig. 7) and fig3_l2s1_cables.

By hand: python workflow/scripts/l2s1.py l2s1_idp set=rupp2015 --configfile config/test/config.yaml \
    --output /tmp/idp_rupp2015.csv
"""
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))   # this folder, for _common.py
import _common  # noqa: E402

snakemake, log = _common.start(globals())

from lumbar.experiments import l2s1  # noqa: E402
from lumbar.inputs.characteristics import load_characteristic_set, resolve_characteristic_set  # noqa: E402
from lumbar.geometry import load_geometry  # noqa: E402
from lumbar.inputs.io import write_table_atomic  # noqa: E402
from lumbar.plots import l2s1 as L2P  # noqa: E402


def _geometry(g):
    return load_geometry(g["kind"], path=g["path"] if g["kind"] == "visible_human" else None, levels=list(l2s1.LEVELS))


def _chardir(p):
    p = Path(p)
    return p if p.is_dir() else p.parent


rule = snakemake.rule
if rule == "idp_surrogate":
    from lumbar.experiments.virtual_experiment import idp_table

    p = snakemake.params.l2s1
    cal = _common.as_list(snakemake.input.calibrated)
    cs = resolve_characteristic_set(p["generator_set"], data_dir=snakemake.input.characteristics,
                                    calibrated_dir=Path(cal[0]).parent if cal else None)
    log.info("generator set %s from %s", p["generator_set"],
             Path(cal[0]).parent if cal and p["generator_set"] == "calibrated" else snakemake.input.characteristics)
    geo = _geometry(snakemake.params.geometry)
    df = idp_table(geo, cs, snakemake.params.seed, n_specimens=p["n_specimens"], variation=p["variation"],
                   noise_sd_mpa=p["noise_sd_mpa"], cables=l2s1.derive_cables(snakemake.input.cables),
                   idp_formula=p["idp_formula"], k_shear=snakemake.params.fsu.get("disc_shear_stiffness_n_per_m"),
                   max_iter=snakemake.params.solver["max_iter"])
    log.info("SURROGATE IDP table: %d rows from %d virtual specimens of set %s", len(df), p["n_specimens"],
             p["generator_set"])
    write_table_atomic(df, snakemake.output[0])
elif rule == "l2s1_idp":
    name = snakemake.wildcards.set
    p, s = snakemake.params.l2s1, snakemake.params.solver
    d = _chardir(snakemake.input.characteristics)
    log.info("set %s: characteristics from %s", name, d)
    cs = load_characteristic_set(name, data_dir=d)
    geo = _geometry(snakemake.params.geometry)
    df, sol = l2s1.run_set(geo, cs, l2s1.derive_cables(snakemake.input.cables), idp_formula=p["idp_formula"],
                           idp_kwargs={"area_m2": p["disc_area_m2"]} if p["idp_formula"] == "paper2" else None,
                           facet_stiffness=snakemake.params.fsu["facet_stiffness_n_per_m"],
                           k_shear=snakemake.params.fsu.get("disc_shear_stiffness_n_per_m"),
                           load_steps=s["load_steps"], max_iter=s["max_iter"],
                           tol=min(s["tol_force_n"], s["tol_moment_nm"]), moment_nm=p["moment_nm"])
    rf, rm = l2s1.equilibrium_residual(sol)
    df.insert(0, "set", name)
    df.insert(1, "geometry", geo.name)
    df["residual_force_n"], df["residual_moment_nm"] = rf, rm
    log.info("set %s: %d scenarios, %d not converged, max residual %.2e N %.2e N*m", name, len(df),
             int((~df["converged"]).sum()), rf[sol.converged].max(initial=0), rm[sol.converged].max(initial=0))
    write_table_atomic(df, snakemake.output[0])
elif rule == "table5":
    ref = l2s1.read_idp_table(snakemake.input.reference)   # the user's table first: fail fast on bad input
    sims = pd.concat([pd.read_csv(f) for f in snakemake.input.sims], ignore_index=True)
    kinds = sorted(set(ref["kind"]))
    log.info("reference IDP table %s, kind(s) %s%s", snakemake.input.reference, kinds,
             " -- SURROGATE, not measured" if "surrogate" in kinds else "")
    syn = l2s1.synopsis(sims, ref)
    # the calibrated set's 90 % posterior band beside its MAP value (the outlier count stays on the MAP value)
    syn = l2s1.with_bands(syn, pd.read_csv(snakemake.input.bands), "calibrated")
    counts = l2s1.outlier_counts(syn)
    vs = l2s1.versus_paper(counts, snakemake.params.published)
    out = snakemake.output
    write_table_atomic(syn, out.synopsis)
    write_table_atomic(counts, out.counts)
    write_table_atomic(vs, out.vs_paper)
    internal = sims.drop(columns=["idp_mpa"]).merge(syn[["set", "muscle_setup", "load_case", "idp_sim_mpa",
                                                         "outlier", "data_kind"]], on=["set", "muscle_setup", "load_case"])
    write_table_atomic(internal, out.internal)
    L2P.plot_table5_grid(syn, out.grid)
    L2P.plot_fig7(syn, out.fig7)
    for _, r in vs.iterrows():
        log.info("set %s: %d outliers of %d (paper: %s) [reference %s]", r["set"], r["n_outliers"],
                 r["n_scenarios"], r["paper_n_outliers"], r["data_kind"])
elif rule == "fig3_l2s1_cables":
    from lumbar.plots.render_spine import render_spine

    geo = _geometry(snakemake.params.geometry)
    cab = l2s1.build_l2s1(geo, load_characteristic_set("rupp2015"), l2s1.derive_cables(snakemake.input.cables)).cables
    used = render_spine(geo, l2s1.LEVELS, snakemake.output[0], cables=cab, backend=snakemake.params.render["backend"])
    log.info("rendered %s with %s", snakemake.output[0], used)
log.info("done: %s", ", ".join(map(str, snakemake.output)))
