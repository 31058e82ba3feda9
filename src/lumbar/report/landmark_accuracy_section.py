"""Report section "Automatic landmarks where the truth is known": the landmark accuracy on the embedded Visible Human
meshes given as a user gives them (leave one out) and what the remaining error does to the calibrated unit. Every
number is read from the result files of rule landmark_accuracy (workflow/rules/landmark_accuracy.smk), found by
their roles in the stage manifest landmark_accuracy (which names this module: report_module)."""
from __future__ import annotations

import numpy as np
import pandas as pd

from .sections import ReportBuilder, fmt, report_section

#: the must-show thresholds of the specimen path (docs/specimen.md): overall median, per-structure median [mm],
#: facet faces [mm], L4-L5 fibre length [relative]
OVERALL_MEDIAN_MM, STRUCTURE_MEDIAN_MM, FACET_MM, LENGTH_REL = 2.0, 4.0, 2.0, 0.15


def accuracy_sentence(s: pd.DataFrame, lengths: pd.DataFrame) -> str:
    """The accuracy in words against the specimen path's targets, read from the summary and length tables."""
    by = s.set_index("structure")
    allg = by.loc["all ligament groups"]
    kinds = s[~s["structure"].isin(["all ligament groups", "facet faces vs cartilage nodes",
                                    "facet faces vs their bone points"])]
    worst = kinds.loc[kinds["median_mm"].idxmax()]
    fac = by.loc["facet faces vs cartilage nodes"]
    off = lengths[lengths["relative_error"].abs() > LENGTH_REL]
    txt = (f"Insertion-group centroids are a median {fmt(allg['median_mm'], 2)} mm from the reference model's "
           f"(target {fmt(OVERALL_MEDIAN_MM)} mm; largest {fmt(allg['max_mm'], 2)} mm); the worst structure, the "
           f"{worst['structure']}, has a median of {fmt(worst['median_mm'], 2)} mm (target {fmt(STRUCTURE_MEDIAN_MM)} "
           f"mm). Facet faces are a median {fmt(fac['median_mm'], 2)} mm from the cartilage nodes (target "
           f"{fmt(FACET_MM)} mm). ")
    if len(off):
        txt += ("At L4-L5 the straight fibre length is off by more than "
                f"{fmt(100 * LENGTH_REL)} % for " + ", ".join(
                    f"{r.structure} ({fmt(100 * r.relative_error)} %)" for r in off.itertuples()) + ".")
    else:
        txt += f"Every L4-L5 fibre length is within {fmt(100 * LENGTH_REL)} % of the reference."
    return txt


def contact_sentence(facets: pd.DataFrame) -> str:
    """The orientation of the joints' contact surfaces against the reference's, read from the facets table."""
    if "contact_normal_angle_deg" not in facets or not len(facets):
        return ""
    joints = facets.drop_duplicates(["level", "side"])
    parts = []
    for name, sel in (("above L5-S1", joints["level"] != "L5-S1"), ("at L5-S1", joints["level"] == "L5-S1")):
        a = joints.loc[sel, "contact_normal_angle_deg"]
        if len(a):
            parts.append(f"{fmt(a.min(), 2)}-{fmt(a.max(), 2)} deg {name}")
    return (" The joints' contact surfaces (Eq. 4, fitted to these faces) are turned " + " and ".join(parts)
            + " from the reference's: the direction the facet force acts along, which the distances do not score.")


def voxelised_rows(vox: pd.DataFrame) -> list[list[str]]:
    """Table G2's rows: per input (the surface meshes, each label volume) the group and facet-face distances."""
    rows = []
    for (inp, h), g in vox.groupby(["input", "voxel_mm"], dropna=False, sort=False):
        by = g.set_index("structure")
        name = "surface meshes" if inp == "surface meshes" else f"label volume, {fmt(h, 2)} mm voxels"
        allg, bone, cart = (by.loc[k] for k in ("all ligament groups", "facet faces vs their bone points",
                                                 "facet faces vs cartilage nodes"))
        rows.append([name, fmt(allg["median_mm"], 2), fmt(allg["max_mm"], 2), fmt(bone["median_mm"], 2),
                     fmt(bone["max_mm"], 2), fmt(cart["median_mm"], 2),
                     "yes" if bool(g["facet_surfaces_supported"].iloc[0]) else "no"])
    return rows


def voxelised_sentence(vox: pd.DataFrame) -> str:
    """The label volumes' accuracy in words beside the surface meshes', read from the voxelised table."""
    lab = vox[vox["input"] == "label volume"]
    if not len(lab):
        return ""
    groups = lab[lab["structure"] == "all ligament groups"]["median_mm"]
    bone = lab[lab["structure"] == "facet faces vs their bone points"]["median_mm"]
    mesh = vox[(vox["input"] == "surface meshes") & (vox["structure"] == "all ligament groups")]["median_mm"]
    edges = [fmt(h, 2) for h in lab["voxel_mm"].unique()]
    sizes = edges[0] if len(edges) == 1 else ", ".join(edges[:-1]) + " and " + edges[-1]

    def rng(a):
        lo, hi = fmt(a.min(), 2), fmt(a.max(), 2)
        return lo if lo == hi else f"{lo}-{hi}"
    return (f"Given as a CT segmentation instead (the same posed bones voxelised at {sizes} mm in the scanner's axes, "
            "one multi-label NIfTI file, meshed by the label-volume path: staircased, smoothed, separated at the "
            f"joints), the insertion-group centroids are a median {rng(groups)} mm from the reference"
            + (f" (surface meshes: {fmt(mesh.iloc[0], 2)} mm)" if len(mesh) else "")
            + f" and the facet faces a median {rng(bone)} mm from their bone points (Table G2).")


@report_section("landmark_accuracy", "Automatic landmarks where the truth is known", after="models")
def landmark_accuracy_section(b: ReportBuilder):
    summary, lengths_table, effect, facets_table = (b.out("landmark_accuracy", role)
                                                    for role in ("summary", "lengths", "effect", "facets"))
    if not b.has(summary):
        b.missing("Landmark accuracy on the Visible Human meshes (landmark_accuracy.run: false)")
        return
    s = pd.read_csv(b.path(summary))
    lengths = (pd.read_csv(b.path(lengths_table)) if b.has(lengths_table)
               else pd.DataFrame(columns=["structure", "relative_error"]))
    b.para("A user's specimen enters as vertebra surfaces or a CT label map (docs/specimen.md); its landmarks are "
           "placed automatically. Scored where the truth is known: the embedded Visible Human meshes written as a "
           "user would give them (turned and moved into a CT-like pose, millimetres, LPS) and read back, each "
           "vertebra placed with an atlas built without it (leave one out), against the model's own insertion sites "
           "and facet cartilage. " + accuracy_sentence(s, lengths) + contact_sentence(
               pd.read_csv(b.path(facets_table)) if b.has(facets_table) else pd.DataFrame()))
    b.table_block("Automatic landmarks against the reference model (Visible Human, leave one out)",
                  ["structure", "groups", "median distance [mm]", "largest distance [mm]"],
                  [[r.structure, int(r.n_groups), fmt(r.median_mm, 2), fmt(r.max_mm, 2)] for r in s.itertuples()],
                  source=summary, label="Table G1",
                  note="Distance of the centroid of each insertion group (one ligament's fibre ends on one vertebra) "
                       "from the reference group's; ends on the sacrum are not scored (the atlas has one sacrum).")
    vox_table = b.out("landmark_accuracy", "voxelised")
    if b.has(vox_table):
        vox = pd.read_csv(b.path(vox_table))
        if (vox["input"] == "label volume").any():
            b.para(voxelised_sentence(vox))
            b.table_block("The same bones given as a CT label map", [
                "input", "groups: median [mm]", "groups: largest [mm]", "facet faces to bone: median [mm]",
                "facet faces to bone: largest [mm]", "facet faces to cartilage: median [mm]",
                "joint space resolved"], voxelised_rows(vox), source=vox_table, label="Table G2",
                note="Leave one out, as Table G1. A voxel inside two bones (the Visible Human meshes interpenetrate "
                     "at the facet joints) belongs to the one it lies deeper in. Joint space resolved: the voxel "
                     "edge is at most half the sourced facet joint space; where it is not, a specimen run leaves "
                     "the facet numbers of levels.csv empty.")
    if b.has(effect):
        e = pd.read_csv(b.path(effect))
        rows = []
        for r in e.itertuples():
            num = r.unit != "" and isinstance(r.unit, str)
            rel = r.relative_difference
            rows.append([r.quantity + (f" [{r.unit}]" if num else ""),
                         fmt(float(r.reference_landmarks), 3) if num else str(r.reference_landmarks),
                         fmt(float(r.automatic_landmarks), 3) if num else str(r.automatic_landmarks),
                         fmt(100 * float(rel)) if num and np.isfinite(float(rel)) else "-"])
        b.table_block("What the landmark error does: the calibrated L4-L5 unit on the reference and on the automatic "
                      "landmarks", ["quantity", "reference landmarks", "automatic landmarks", "difference [%]"], rows,
                      source=effect, label="Table G3",
                      note="The same characteristic set on both geometries; each ROM about its geometry's own "
                           "project axes (the automatic frame is found from the anatomy).")
