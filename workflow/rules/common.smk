from glob import glob

from snakemake.utils import validate


validate(config, schema="../schemas/config.schema.yaml")


def final_outputs():
    """Every result the default target builds; rules of later stages add theirs here."""
    return [
        "results/tables/fsu_geometry.csv",
        "results/figures/fig1_l4l5_model.png",
        "results/tables/fsu_rom_intact.csv",
    ]


def geometry_inputs(wildcards):
    """Files the geometry is read from: the Visible Human directory, or the project landmarks
    that go with the myo-sim meshes (the meshes themselves come with the pinned myo-sim package)."""
    if config["geometry"]["kind"] == "visible_human":
        return [config["geometry"]["path"]]
    return sorted(glob("data/landmarks/*.csv"))
