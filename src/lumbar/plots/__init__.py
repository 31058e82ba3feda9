"""Figures of the library (matplotlib object API: ``matplotlib.figure.Figure`` objects, no pyplot state and no
backend switching): :mod:`lumbar.plots.discovery` (discrepancy discovery and its benchmark), :mod:`lumbar.plots.render`
(3-D figures of a motion segment: pyvista off-screen, matplotlib fallback), :mod:`lumbar.plots.render_spine` (the
L2-S1 spine with its cables, Fig. 3 analog), :mod:`lumbar.plots.calibration` (the calibration's Figs. 4-5 analogs)
and :mod:`lumbar.plots.posterior` (the calibration's prior and posterior)."""
