"""Grasp poses from superquadrics (Vezzani 2019 thesis, ch. 7.2, 7.4, 8.2)."""
