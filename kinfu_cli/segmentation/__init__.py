"""Segments of the reconstruction, their saliency, and superquadric fits."""
