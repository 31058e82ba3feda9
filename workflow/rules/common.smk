from glob import glob
from pathlib import Path

from snakemake.utils import validate


validate(config, schema="../schemas/config.schema.yaml")


def final_outputs():
    """Every result the default target builds; rules of later stages add theirs here."""
    return [
        "results/tables/fsu_geometry.csv",
        "results/figures/fig1_l4l5_model.png",
        "results/tables/fsu_rom_intact.csv",
        # stepwise reduction (issue 3): calibration (Tables 1-3, Figs. 4-5), forward (Table 4, Fig. 6)
        "results/tables/table1_disc_calibrated.csv",
        "results/tables/table2_facet_surfaces.csv",
        "results/tables/table3_ligaments_calibrated.csv",
        "results/figures/fig4_disc_torque_angle.png",
        "results/figures/fig5_ligament_characteristics.png",
        "results/tables/table4_rom_synopsis.csv",
        "results/tables/table4_outlier_counts.csv",
        "results/tables/table4_vs_paper.csv",
        "results/figures/table4_grid.png",
        "results/figures/fig6_rom_stepwise_reduction.png",
        # L2-S1 with wire cables, L4-L5 IDP (issue 4): Table 5, Figs. 3 and 7
        "results/figures/fig3_l2s1_cables.png",
        "results/tables/table5_idp_synopsis.csv",
        "results/tables/table5_outlier_counts.csv",
        "results/tables/table5_vs_paper.csv",
        "results/tables/l2s1_internal_loads.csv",
        "results/figures/table5_grid.png",
        "results/figures/fig7_idp.png",
    ]


def geometry_inputs(wildcards):
    """Files the geometry is read from: the Visible Human directory, or the project landmarks
    that go with the myo-sim meshes (the meshes themselves come with the pinned myo-sim package)."""
    if config["geometry"]["kind"] == "visible_human":
        return [config["geometry"]["path"]]
    return sorted(glob("data/landmarks/*.csv"))


# ---- stepwise reduction (issue 3)
def stepwise_reduction_experiment(wildcards):
    """The ROM table to calibrate on and compare with: the user's measured table when
    stepwise_reduction.measured_table is set, else the workflow's surrogate."""
    measured = config["stepwise_reduction"]["measured_table"]
    return measured if measured else "results/experiments/stepwise_reduction_surrogate.csv"


def stepwise_reduction_derived(wildcards):
    """Disc-only rows derived from the published Eq. 3 fit (replace the surrogate's w/o ALL rows)."""
    path = config["stepwise_reduction"]["disc_only_derived"]
    return [path] if path else []


def stepwise_reduction_characteristics(wildcards):
    """The calibrated set comes from the calibration; the literature sets from the data directory."""
    if wildcards.set == "calibrated":
        return "results/calibration/characteristics/disc.csv"
    return config["characteristics"]["data_dir"]


# ---- L2-S1 IDP experiment (issue 4)
def l2s1_idp_reference(wildcards):
    """The IDP table Table 5 compares with: l2s1.measured_table when set, else the surrogate."""
    return config["l2s1"]["measured_table"] or "results/experiments/idp_wilke1996_surrogate.csv"


def l2s1_characteristics(wildcards):
    """Tables of one characteristic set for the L2-S1 model. "calibrated": l2s1.calibrated_characteristics
    (a file inside it when rule calibrate produces that directory, so the DAG chains), or the published
    characteristics.data_dir when that is null / neither produced nor present."""
    data_dir = config["characteristics"]["data_dir"]
    cal = config["l2s1"]["calibrated_characteristics"]
    if wildcards.set != "calibrated" or not cal:
        return data_dir
    cal_dir = Path(cal)
    produced = any(r.name == "calibrate" for r in workflow.rules) and cal_dir == Path(
        "results", "calibration", "characteristics"
    )
    if produced:
        return str(cal_dir.joinpath("disc.csv"))
    return cal if cal_dir.is_dir() else data_dir

