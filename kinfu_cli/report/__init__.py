"""Plots (PNG) of volumes, trajectories and views."""
