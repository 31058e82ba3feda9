"""Figures of the library (matplotlib object API: ``matplotlib.figure.Figure`` objects, no pyplot state and no
backend switching): :mod:`lumbar.plots.discovery` (discrepancy discovery and its benchmark), :mod:`lumbar.plots.render`
(3-D figures of a motion segment: pyvista off-screen, matplotlib fallback), :mod:`lumbar.plots.render_spine` (the
L2-S1 spine with its cables, Fig. 3 analog), :mod:`lumbar.plots.posterior` (the calibration's posterior) and one module
per stage, named like it: :mod:`lumbar.plots.calibration` (Figs. 4-5), :mod:`lumbar.plots.stepwise_reduction` (Table 4 grid, Fig. 6), :mod:`lumbar.plots.load_sharing`,
:mod:`lumbar.plots.validation` (the scoreboard, the other levels), :mod:`lumbar.plots.l2s1` (Table 5 grid, Fig. 7) and
:mod:`lumbar.plots.muscle_model` (paper 2's figures)."""
