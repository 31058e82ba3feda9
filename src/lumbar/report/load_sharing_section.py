"""Report section "Load sharing and physical admissibility": how the calibrated unit shares the moment between disc,
facets and ligaments, whether it reaches its range of motion for the reasons real segments have (the admissibility
criteria), where the wire-cable forces go at L4-L5, and the other lumbar levels with the calibrated characteristics
unchanged. Every number is read from the result files (workflow/rules/load_sharing.smk, admissibility.smk,
validation.smk); registered after the posterior section (stage manifest load_sharing, report_module)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from .sections import ReportBuilder, fmt, report_section

#: the files this section reads, by their roles in the stage manifests (lumbar.inputs.manifests)
FILES = {"adm": ("admissibility", "table"), "summary": ("load_sharing", "summary"),
         "compression": ("load_sharing", "compression_summary"), "reduction": ("load_sharing", "reduction"),
         "cables": ("load_sharing", "cables"), "remus": ("admissibility", "remus"),
         "multi": ("validation", "multilevel_rom"), "multi_adm": ("validation", "multilevel_admissibility"),
         "readings": ("validation", "multilevel_readings")}
READING_NAMES = {"as_calibrated": "adopted: laws unchanged", "ligaments_on_strain": "ligament laws on strain",
                 "size_scaled": "disc and facet stiffness scaled with size",
                 "disc_frame_loading": "moments about each disc's own axes"}
STRUCTURES = ("disc", "facet_left", "facet_right", "ALL", "PLL", "FL", "CL", "ITL", "ISL", "SSL")
STRUCTURE_NAMES = {"disc": "disc", "facet_left": "left facet", "facet_right": "right facet"}
DIRECTION_NAMES = {"flexion": "flexion", "extension": "extension", "lateral_bending_right": "lateral bending right",
                   "lateral_bending_left": "lateral bending left", "axial_rotation_left": "axial rotation left",
                   "axial_rotation_right": "axial rotation right"}


def _files(b: ReportBuilder) -> dict[str, str]:
    """This section's files under the run's results root."""
    return {k: b.out(*role) for k, role in FILES.items()}


def human_direction(d: str) -> str:
    return d.replace("_one_side", " (one side)").replace("_", " ")


def _summary_sentence(b: ReportBuilder) -> str:
    files = _files(b)
    parts = []
    if b.has(files["adm"]):
        a = pd.read_csv(b.path(files["adm"]))
        failed = a[~a["passed"].astype(bool)]
        parts.append(f"The calibrated unit passes {len(a) - len(failed)} of {len(a)} admissibility criteria"
                     + (f" (not: {'; '.join(sorted(set(failed['criterion'])))})" if len(failed) else "") + ".")
    if b.has(files["multi"]):
        m = pd.read_csv(b.path(files["multi"]))
        jump = m["largest_jump_deg"].max()
        parts.append(f"With its characteristics unchanged, {int(m['within'].sum())} of {len(m)} ROM values of the "
                     f"other levels lie within 25 % of Yamamoto et al. (1989); the largest rotation jump between two "
                     f"load steps at any level is {fmt(jump)} deg.")
    if b.has(files["cables"]):
        c = pd.read_csv(b.path(files["cables"]))
        n = c[(c["load_case"] == "neutral") & (c["muscle_setup"] == "all")]
        if len(n):
            r = n.iloc[0]
            parts.append(f"Under all five cable pairs in the neutral position the L4-L5 disc carries "
                         f"{fmt(100 * r['disc_share'])} % of the compression that crosses the joint, the facets "
                         f"{fmt(100 * r['facets_share'])} %.")
    return " ".join(parts)


@report_section("load_sharing", "Load sharing and physical admissibility", after="posterior")
def load_sharing_section(b: ReportBuilder):
    """The section, in four parts: admissibility, how the unit shares the moment, the other levels, and the transfer
    readings with the other levels' admissibility."""
    _admissibility_part(b)
    _sharing_part(b)
    _other_levels_part(b)
    _readings_part(b)


def _admissibility_part(b: ReportBuilder):
    """Why reaching the ROM is not enough, and the calibrated set's admissibility criteria with the curves."""
    files = _files(b)
    b.para("Reaching the range of motion is not enough: the unit must reach it for the reasons real segments have "
           "(no clamped facets at rest, no ligament switched off, no snap-through, the disc carrying most of a "
           "compression). Method and criteria: docs/load_sharing.md. " + _summary_sentence(b))
    b.heading("Admissibility of the calibrated set")
    b.csv_table(files["adm"], "Physical admissibility criteria of the calibrated set (value, limit, passed, source)", False,
                columns=["criterion", "direction", "value", "limit", "unit", "passed", "source"])
    b.figure(b.out("load_sharing", "curves_figure"), "Moment-rotation curves of the intact unit.")
    b.figure(b.out("load_sharing", "shares_figure"), "Moment carried by each structure, calibrated unit.")


def _sharing_part(b: ReportBuilder):
    """How the calibrated unit shares the moment: shares at the largest moment, the unloaded unit, the removal of the
    posterior ligaments, axial compression, the cable load paths and the Remus et al. (2021) comparison."""
    files = _files(b)
    b.heading("How the calibrated unit shares the moment")
    if b.has(files["summary"]):
        s = pd.read_csv(b.path(files["summary"]))
        cal = s[(s["set"] == "calibrated") & (s["stage"] == "intact")]
        top = cal[cal["moment_nm"] == cal["moment_nm"].max()]
        cols = [c for c in (f"{k}_share" for k in STRUCTURES) if c in top.columns]
        header = ["direction", "rotation [deg]"] + [f"{STRUCTURE_NAMES.get(c[:-6], c[:-6])} [%]" for c in cols]
        rows = [[DIRECTION_NAMES.get(r["direction"], r["direction"]), fmt(r["rotation_deg"])] +
                [fmt(100 * r[c]) for c in cols] for _, r in top.iterrows()]
        b.table_block(f"Share of the applied {fmt(top['moment_nm'].max())} N*m carried by each structure "
                      "(calibrated, intact)", header, rows, source=files["summary"],
                      note="Moments about the disc centre; a negative share pushes with the applied moment.")
        rest = cal[cal["moment_nm"] == 0.0].head(1)
        if len(rest):
            r = rest.iloc[0]
            forces = [c for c in r.index if c.endswith(("_contact_n", "_tension_n"))] + ["disc_axial_force_n"]
            b.table_block("The unloaded unit (0 N*m, no preload): contact forces, ligament tensions and disc "
                          "compression [N]", ["structure", "force [N]"],
                          [[c.replace("_contact_n", " facet contact").replace("_tension_n", " tension")
                            .replace("disc_axial_force_n", "disc compression").replace("facet_", ""),
                            fmt(r[c])] for c in forces], source=files["summary"])
    else:
        b.missing(f"Load-sharing summary ({Path(files['summary']).name})")
    if b.has(files["reduction"]):
        r = pd.read_csv(b.path(files["reduction"]))
        c = r[r["set"] == "calibrated"]
        if len(c):
            b.table_block("What removing the posterior ligaments does to flexion at 10 N*m (calibrated unit)",
                          ["stage", "ROM from the stage's rest [deg]", "rotation from the intact rest [deg]",
                           "larger than the stage before (own rest / intact rest)"],
                          [[st, fmt(a), fmt(f), "" if pd.isna(i1) else
                            f"{'yes' if bool(i1) else 'no'} / {'yes' if bool(i2) else 'no'}"]
                           for st, a, f, i1, i2 in zip(c["stage"], c["rom_from_stage_rest_deg"],
                                                       c["rotation_from_intact_rest_deg"],
                                                       c["increases_from_stage_rest"], c["increases_from_intact_rest"])],
                          source=files["reduction"], note="A removed pre-tensioned ligament moves the stage's rest state, "
                          "from which the stepwise-reduction tables measure the ROM; the "
                          "rotation from the intact unit's rest shows the structure's own "
                          "share.")
    b.csv_table(files["compression"], "Pure axial (follower) load: shares of disc and facets per characteristic set", False,
                columns=None)
    if b.has(files["cables"]):
        c = pd.read_csv(b.path(files["cables"]))
        n = c[c["load_case"] == "neutral"]
        b.table_block("Where the wire-cable forces go at L4-L5 (neutral position, calibrated set, L2-S1 model)",
                      ["muscle set-up", "cable total [N]", "disc [N]", "facets [N]", "ligaments [N]", "disc share [%]",
                       "facet share [%]", "IDP [MPa]"],
                      [[r["muscle_setup"].replace("_", " "), fmt(r["cable_total_n"]), fmt(r["disc_n"]),
                        fmt(r["facets_n"]), fmt(r["ligaments_n"]), fmt(100 * r["disc_share"]),
                        fmt(100 * r["facets_share"]), fmt(r["idp_mpa"])] for _, r in n.iterrows()],
                      source=files["cables"], note="Forces along the disc normal on L4 (ligaments pull: negative); shares of "
                      "the compression crossing the joint (disc + facets). Every load case: "
                      + files["cables"] + ".")
    else:
        b.missing(f"Cable load paths ({Path(files['cables']).name})")
    b.csv_table(files["remus"], "The calibrated ligaments beside the Remus et al. (2021) model of the same fibres (tension "
                "under both laws at the same deformation)", False)


def _other_levels_part(b: ReportBuilder):
    """The other lumbar levels with the calibrated characteristics unchanged: ROM against Yamamoto et al. (1989)."""
    files = _files(b)
    b.heading("Other lumbar levels, calibrated characteristics unchanged")
    if b.has(files["multi"]):
        m = pd.read_csv(b.path(files["multi"]))
        per = m.groupby("level", sort=False)["within"].agg(["sum", "count"])
        b.para("Within 25 % of Yamamoto et al. (1989), per level: "
               + "; ".join(f"{lv} {int(r['sum'])} of {int(r['count'])}" for lv, r in per.iterrows())
               + ". The shares say how each level reaches its rotation: the levels differ only in their geometry, "
               "so a level whose real segments are more mobile than the others (or stiffer) in one direction "
               "shows it here as a ratio far from 1 with the same structures resisting.")
        from ..experiments.validation import near_limit  # noqa: PLC0415

        edge = near_limit(m)
        if len(edge):
            b.para("Near the 25 % limit (model / measured within 0.05 of 0.75 or 1.25), where a fit that leaves L4-L5 "
                   "as it is can move a row across it (docs/load_sharing.md, \"How firm a count is\"): "
                   + "; ".join(f"{r['level']} {human_direction(r['direction'])} {r['ratio']:.3f} "
                               f"({'inside' if r['within'] else 'outside'})" for _, r in edge.iterrows()) + ".")
        share = [c for c in ("disc_share", "facets_share", "ligaments_share") if c in m.columns]
        b.table_block("ROM at 10 N*m of the other levels against Yamamoto et al. (1989) (independent), and the "
                      "share of the moment each structure resists",
                      ["level", "direction", "model [deg] (90 % posterior band)", "measured [deg]", "model / measured",
                       "within 25 %"] + [f"{c[:-6]} [%]" for c in share] + ["largest step [deg]"],
                      [[r["level"], DIRECTION_NAMES.get(r["direction"], human_direction(r["direction"])),
                        fmt(r["sim_deg"]) + (f" ({fmt(r['sim_band_low'])} to {fmt(r['sim_band_high'])})"
                                             if pd.notna(r.get("sim_band_low")) else ""),
                        fmt(r["measured_deg"]), fmt(r["ratio"]), "yes" if r["within"] else "no"]
                       + [fmt(100 * r[c]) for c in share] + [fmt(r["largest_jump_deg"])] for _, r in m.iterrows()],
                      source=files["multi"], note="Lateral bending and axial rotation: the mean of both sides (the abstract "
                      "gives one-side values). Shares of the applied moment about the disc "
                      "centre; largest step: the largest rotation change between two 0.25 N*m "
                      "load steps (a snap-through shows here).")
    else:
        b.missing(f"Other levels ({Path(files['multi']).name})")
    b.figure(b.out("validation", "multilevel_figure"), "Other levels with the L4-L5 characteristics unchanged.")


def _readings_part(b: ReportBuilder):
    """The other levels under other readings of the transfer, and their admissibility criteria."""
    files = _files(b)
    if b.has(files["readings"]):
        from ..experiments.level_transfer import readings_summary  # noqa: PLC0415

        s = readings_summary(pd.read_csv(b.path(files["readings"])))
        b.para("Is a miss the transfer rule's doing? The same levels under three other readings of \"the calibrated "
               "characteristics at another level\", every factor taken from the geometry (docs/load_sharing.md, "
               "\"Other levels\"): a reading that removed a miss for a physical reason would show it here.")
        b.table_block("Other levels under four readings of the transfer: ROM at 10 N*m within 25 % of Yamamoto et al. "
                      "(1989) (sensitivity of the independent comparison, not a second validation)",
                      ["reading", "other levels within 25 %", "calibrated level within 25 %",
                       "snap-through or not converged", "outside 25 % (model / measured)"],
                      [[READING_NAMES.get(r["reading"], r["reading"]), f"{r['other_within']} of {r['other_n']}",
                        f"{r['calibrated_within']} of {r['calibrated_n']}", str(r["snap_or_not_converged"]),
                        r["misses"] or "none"] for _, r in s.iterrows()],
                      source=files["readings"], note="Readings: " + "; ".join(
                          f"{READING_NAMES.get(k, k)}: {v}" for k, v in
                          zip(s["reading"], s["reading_note"])) + ".")
    else:
        b.missing(f"Transfer readings ({Path(files['readings']).name})")
    if b.has(files["multi_adm"]):
        a = pd.read_csv(b.path(files["multi_adm"]))
        per = a.groupby("level", sort=False)["passed"].agg(["sum", "count"])
        failed = a[~a["passed"].astype(bool)]
        b.table_block("Admissibility criteria per level (calibrated characteristics unchanged)",
                      ["level", "criteria passed", "criteria", "failed"],
                      [[lv, int(r["sum"]), int(r["count"]),
                        "; ".join(sorted(set(failed[failed["level"] == lv]["criterion"]))) or "none"]
                       for lv, r in per.iterrows()], source=files["multi_adm"])


__all__ = ["load_sharing_section"]
