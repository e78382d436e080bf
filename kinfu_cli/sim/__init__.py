"""Synthetic tabletop scenes, a Kinect-like depth sensor and hand trajectories."""
