"""Report section "The calibrated units in OpenSim": what rule export_opensim wrote (its export folder) and its
check in OpenSim 4.6. Every number is read from the stage's result files, found by their roles in the stage manifest
export_opensim (which names this module: report_module)."""
from __future__ import annotations

import pandas as pd

from .sections import ReportBuilder, fmt, report_section


def level_rows(check: pd.DataFrame) -> list[list[str]]:
    """Per level: the largest |difference| of the detailed unit with and without facets [deg], the reduced joint's
    largest relative difference [%], and the scenarios both engines solved."""
    rows = []
    for lv, g in check.groupby("level", sort=True):
        ok = g[g["status"] == "ok"]

        def worst(v, col="difference_deg", scale=1.0, digits=2):
            s = ok.loc[ok["variant"] == v, col].abs()
            return fmt(scale * s.max(), digits) if len(s) else "-"

        rows.append([lv, f"{len(ok)} of {len(g)}", worst("detailed", digits=1),
                     worst("detailed_no_facets", digits=1), worst("reduced", "relative_difference", 100.0)])
    return rows


def check_sentence(check: pd.DataFrame) -> str:
    ok = check[check["status"] == "ok"]
    if not len(ok):
        why = check["status"].iloc[0] if len(check) else "no model exported"
        return f"The OpenSim check did not run ({why}); the models are written all the same."
    det = ok[ok["variant"].str.startswith("detailed")]
    red = ok[ok["variant"] == "reduced"]
    n_lv = check["level"].nunique()
    txt = (f"Loaded in OpenSim 4.6 and solved there under pure moments of {fmt(ok['moment_nm'].min())}-"
           f"{fmt(ok['moment_nm'].max())} N*m (a static solve of OpenSim's own generalised forces), the detailed "
           f"units of {n_lv} level{'s' if n_lv > 1 else ''} have the project's range of motion to within "
           f"{det['difference_deg'].abs().max():.1g} deg with and without their facet joints: the file holds the "
           "model the tables were computed with, facets included (each contact point against its Eq. 4 surface, "
           "not an approximation).")
    if len(red):
        txt += (f" The reduced joint, one bushing per level for a full-body model, is within "
                f"{fmt(100 * red['relative_difference'].abs().max())} % of the detailed unit's range of motion "
                "in every direction, without the coupled rotations the detailed unit shows.")
    bad = check[check["status"] != "ok"]
    if len(bad):
        txt += f" {len(bad)} scenario(s) were not solved by both engines (status column)."
    return txt


@report_section("export_opensim", "The calibrated units in OpenSim", before="discrepancy")
def export_opensim_section(b: ReportBuilder):
    check_file, fig = b.out("export_opensim", "check"), b.out("export_opensim", "figure")
    if not b.has(check_file):
        b.missing("The OpenSim export (export_opensim.run: false)")
        return
    check = pd.read_csv(b.path(check_file))
    b.para("Every level of the configured geometry, with the calibrated (MAP) characteristic set, is written as an "
           "OpenSim 4.6 model (the export folder of the run's results, export/calibrated; vertebrae with their meshes, the disc as two bushings, "
           "every ligament fibre with its law and prestrain, the facet joints), with the calibration's 90 % "
           "posterior intervals beside it and a reduced joint per level (docs/opensim_export.md: frames, "
           "coordinates and how to put the joints into an existing OpenSim model). " + check_sentence(check))
    b.table_block("The exported models checked in OpenSim 4.6", [
        "level", "scenarios solved by both", "detailed unit: largest difference [deg]",
        "without facets: largest difference [deg]", "reduced joint: largest difference [%]"],
        level_rows(check), source=check_file,
        note="Range of motion in OpenSim minus the project's, over the directions and moments of the check; the "
             "reduced joint against the detailed unit as the project solves it. Differences below 1e-6 deg are the "
             "two solvers' tolerances.")
    b.figure(fig, "The OpenSim check: each exported model's range of motion in OpenSim against the project's.")
