"""Shared vocabulary of every stage: errors, progress bars, atomic files, the ternary grid and its
files, camera models and sensor presets, poses, points of interest.

This layer imports no stage (io, fusion, attention, segmentation, nbv, sim, evaluation, report,
commands); every stage may import it. tests/test_layers.py enforces the layering.
"""
