"""Localisation and recognition of a known mesh from 3-D surface points: the Memory Unscented Particle Filter
(Vezzani 2019, ch. 4-5), its baselines, generated test meshes and the thesis' Table 4.2 protocol."""
