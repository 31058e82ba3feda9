"""Muscles of the lumbar model (paper 2): Millard curves, the myo-sim fascicle set, paths, redundancy solver."""
