# The calibrated units as OpenSim 4.6 models: every level of the configured geometry with the calibrated (MAP)
# characteristic set as <specimen>_<level>.osim in the stage's export folder (vertebra meshes beside them, a reduced
# joint per level), the calibration's 90 % posterior intervals in parameter_intervals.csv, and each model's ROM in
# OpenSim (a static solve of OpenSim's own residual forces, in a process of its own) beside the project's in the
# check table (docs/opensim_export.md).


rule export_opensim:
    input:
        geometry_inputs,
        calibrated=characteristic_tables(calibrated_dir(), ["calibrated"]),
        posterior=out("calibration", "posterior"),
    output:
        **stage_outputs("export_opensim", "export_opensim"),
    log:
        log_file("export_opensim"),
    benchmark:
        benchmark_file("export_opensim")
    conda:
        "../envs/lumbar.yaml"
    params:
        geometry=config["geometry"],
        fsu=config["fsu"],
        export=config["export_opensim"],
    script:
        "../scripts/export_opensim.py"
