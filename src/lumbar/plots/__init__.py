"""Figures of the library (matplotlib object API: ``matplotlib.figure.Figure`` objects, no pyplot state and no
backend switching): :mod:`lumbar.plots.discovery` (discrepancy discovery and its benchmark)."""
