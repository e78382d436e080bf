"""Depth lost to dark and glossy materials, an option of the simulated sensor (`DepthSensor(dark_dropout=...,
glossy_deg=...)`), off by default.

A structured-light sensor (Kinect v1, RealSense D4xx) reads depth from its IR pattern: black plastic absorbs the
pattern (a drill's body, a can's rim) and loses most of its pixels in blobs; glossy print mirrors the projector into
the camera where the surface normal bisects the projector and camera directions and loses a band or spot there.
Either leaves a face in pieces separated by a band the camera never measured (5-20 px on real views).

- dark: pixels whose albedo luminance is below `dark_luma` (default DARK_LUMA: the black parts; 0.35 also
  takes the saturated red and blue inks, which absorb IR on many real prints) are lost where a smooth seeded random field (Gaussian
  white noise blurred over `blob_px` pixels) falls below its `dark_dropout` quantile: about that fraction of
  them, in blobs;
- glossy: object pixels (label >= 3) that are not dark are lost where the angle between the normal and the
  half-vector of the projector and camera directions is below `glossy_deg` (a specular spot on flat faces, a band
  along cylinders). A camera looking down at 30-50 deg sees no such spot on vertical sides or tops: it needs a face
  turned to the camera.

Vectorised numpy and scipy's Gaussian filter; the random field draws from its own generator.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.special import ndtri

DARK_LUMA = 0.25  # albedo luminance (0..1) below which a material absorbs the IR pattern
FIRST_OBJECT_LABEL = 3


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 601 luma of RGB 0..1 rows."""
    return rgb @ np.array([0.299, 0.587, 0.114])


def blob_field(shape: tuple[int, int], blob_px: float, rng: np.random.Generator) -> np.ndarray:
    """A smooth standard-normal random field (H, W): white noise blurred over blob_px pixels, rescaled to unit
    variance, so thresholding it at a normal quantile q drops about a fraction q of the pixels, in blobs."""
    f = gaussian_filter(rng.standard_normal(shape), max(float(blob_px), 0.0), mode="wrap")
    return f / max(float(f.std()), 1e-12)


def material_dropout(hit: dict, albedo: np.ndarray, labels: np.ndarray, projector: np.ndarray,
                     dark_dropout: float, glossy_deg: float, blob_px: float, rng: np.random.Generator,
                     dark_luma: float = DARK_LUMA) -> np.ndarray:
    """Mask (H, W) of the pixels that lose depth to dark or glossy materials.

    hit: a sensor cast (t, valid, gid, normals, dir, origin); albedo (G, 3) and labels (G,) per geometry id;
    projector: the IR projector's world position."""
    valid = hit["valid"]
    gid = hit["gid"]
    dark = valid & (luminance(albedo)[gid] < dark_luma)
    lost = np.zeros(valid.shape, dtype=bool)
    if dark_dropout > 0:
        lost |= dark & (blob_field(valid.shape, blob_px, rng) < ndtri(min(float(dark_dropout), 1.0 - 1e-9)))
    if glossy_deg > 0:
        glossy = valid & ~dark & (labels[gid] >= FIRST_OBJECT_LABEL)
        x = hit["origin"] + hit["dir"] * hit["t"][..., None]
        to_cam = hit["origin"] - x
        to_proj = np.asarray(projector, dtype=np.float64) - x
        half = (to_cam / np.maximum(np.linalg.norm(to_cam, axis=-1, keepdims=True), 1e-12)
                + to_proj / np.maximum(np.linalg.norm(to_proj, axis=-1, keepdims=True), 1e-12))
        half /= np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-12)
        cos = np.abs(np.einsum("hwc,hwc->hw", hit["normals"].astype(np.float64), half))
        lost |= glossy & (cos > np.cos(np.radians(float(glossy_deg))))
    return lost
