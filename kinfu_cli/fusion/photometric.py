"""The photometric term of projective ICP: the frame's intensities against the last fused frame's.

Depth alone cannot pin a camera that sees a wall, the floor and one edge: sliding along the wall-floor line
costs the point-to-plane error nothing, and on noisy depth ICP drifts along it (benchmarks/bench_room_drift.py).
Colour texture on those surfaces does pin it. As in hybrid RGB-D odometry (Steinbruecker et al. 2011; Whelan et
al.'s Kintinuous / ElasticFusion, which pair a frame-to-model ICP with this term), each data vertex of the frame,
moved by the current pose estimate into the previous frame's camera, should see there the intensity it has here;
the residual is the previous frame's intensity (bilinear) at that pixel minus this frame's, linearised with the
previous image's gradient. Its normal equations have the same layout as the point-to-plane ones
(fusion.normal_sums: J = [p x g, g], g the residual's gradient in world coordinates), so ICP adds them with a
weight. Against the previous frame, not the model: the model's colour is a running mean at voxel size, the last
frame's image is sharp; the geometric term keeps the pose on the model, so the two together drift no more than
the geometric one where depth holds.

It runs on every pyramid level. Without it on the coarsest (80 px, 30 iterations, 2 ms of a kitchen frame) the
coarse steps slid along the wall as with depth alone, but too slowly for the speed check to call re-localisation,
and the finer levels could not pull the pose back: the plain and low-contrast room walks ran off by 0.2-1.7 m
(textured ones were unchanged). A weak colour term is worse than none for the same reason (an uncapped weight of
0.003 drifted 8-10 cm where depth alone re-localised its way to 2-3 cm).

Correspondences are skipped where the previous frame has no reading at that pixel or one further than
OCCLUSION_PER_M x depth from the point (occluded or off an edge), and where the residual exceeds MAX_RESIDUAL
(a highlight, a moved object).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from kinfu_cli.fusion.normal_sums import add_correspondence, moved_vertex

# a correspondence whose intensities differ by more than this (0..1 grey) is not the same surface point lit alike
MAX_RESIDUAL = 0.2
# the previous frame's reading at the projected pixel must lie within this share of the point's depth from it
OCCLUSION_PER_M = 0.04
# levels wider than this (px) take every 2nd pixel of every 2nd row: intensities are plentiful there (the term is
# capped at a share of the depth term's information anyway), and the finest level's full term cost 1/3 more
# tracking time on the 7-Scenes kitchen
FULL_WIDTH = 160


@dataclass
class IntensityLevel:
    """One pyramid level of a frame's intensities: grey (H, W) float32 in 0..1 (NaN: no colour sample) and,
    for a reference frame, its gradients per pixel (gx, gy; None for the frame being tracked)."""
    gray: np.ndarray
    gx: np.ndarray | None = None
    gy: np.ndarray | None = None


@dataclass
class PhotometricReference:
    """The last fused frame: its intensity levels (with gradients), its depth per level (the same sizes) and its
    pose (world <- camera)."""
    levels: list[IntensityLevel]
    depths: list[np.ndarray]
    T_world_camera: np.ndarray


def intensity_pyramid(color: np.ndarray, mask: np.ndarray | None, shapes: list[tuple[int, int]],
                      gradients: bool = False) -> list[IntensityLevel]:
    """Grey levels of an RGB uint8 image at each (height, width) of `shapes` (the depth pyramid's, finest first;
    the first the depth image's: the colour is resized to it when of another size). mask: False where the colour
    has no sample (a registered image's holes). Black pixels are samples here (the volume reads exact black as no
    colour, but tracking on the real tabletop box, 15 % of its pixels black, went from 1.00 to 1.53 cm when they
    were taken as holes: they are dark surfaces there). A level's pixel is the mean of the samples it covers (NaN
    when none). gradients (a reference frame): holes are filled with the mean of the samples within 2 px first (a
    hole would otherwise take every bilinear sample and gradient near it with it), then the Sobel gradients (per
    pixel)."""
    import cv2  # heavy: only when tracking

    grey = cv2.cvtColor(np.ascontiguousarray(color), cv2.COLOR_RGB2GRAY)
    valid = np.ones(grey.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    num = np.where(valid, grey.astype(np.float32) * np.float32(1 / 255), np.float32(0))
    den = valid.astype(np.float32)
    out = []
    for h, w in shapes:
        if num.shape != (h, w):  # a level, or colour of another size than the depth: area means, or bilinear
            interp = cv2.INTER_AREA if w <= num.shape[1] else cv2.INTER_LINEAR  # when colour is the smaller
            num = cv2.resize(num, (w, h), interpolation=interp)
            den = cv2.resize(den, (w, h), interpolation=interp)
        has = den > 0
        g = np.where(has, num / np.maximum(den, np.float32(1e-6)), np.float32(np.nan)).astype(np.float32)
        lev = IntensityLevel(g)
        if gradients:
            near = cv2.blur(den, (5, 5))  # holes filled with the mean of the samples within 2 px
            filled = np.where(has, g, cv2.blur(num, (5, 5)) / np.maximum(near, np.float32(1e-6)))
            filled = np.where(has | (near > 0), filled, np.float32(np.nan)).astype(np.float32)
            lev.gray = filled
            lev.gx = cv2.Sobel(filled, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            lev.gy = cv2.Sobel(filled, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        out.append(lev)
    return out


@njit(cache=True, inline="always")
def _bilinear(img, x, y):
    """img at the sub-pixel position (x, y) (column, row), inside the image's last pixel centres."""
    x0 = int(x)
    y0 = int(y)
    ax = x - x0
    ay = y - y0
    return ((1.0 - ay) * ((1.0 - ax) * img[y0, x0] + ax * img[y0, x0 + 1])
            + ay * ((1.0 - ax) * img[y0 + 1, x0] + ax * img[y0 + 1, x0 + 1]))


@njit(cache=True, inline="always")
def photometric_rows(acc, vert, gray, v0, v1, R, t, ref_gray, ref_gx, ref_gy, ref_depth, R_rw, t_rw, fx, fy, cx,
                     cy, stride):
    """Adds the photometric normal-equation sums of every stride-th pixel of every stride-th row of data rows
    v0..v1-1 to acc (fusion.normal_sums; fusion.icp runs it beside the point-to-plane sums, row chunks in parallel):
    vert the frame's vertices (camera), gray their intensities, R, t the pose estimate (world <- camera), ref_* the
    reference level, R_rw, t_rw its camera <- world, fx .. cy the level's intrinsics (both frames' camera)."""
    w = vert.shape[1]
    rh, rw = ref_gray.shape
    J = np.empty(6)
    for v in range(v0, v1):
        if v % stride:
            continue
        for u in range(0, w, stride):
            i0 = gray[v, u]
            if not (i0 == i0):
                continue
            ok, px, py, pz, qx, qy, qz = moved_vertex(vert, v, u, R, t, R_rw, t_rw)
            if not ok or qz <= 0.0:
                continue
            xf = fx * qx / qz + cx
            yf = fy * qy / qz + cy
            if not (xf >= 0.0 and yf >= 0.0 and xf < rw - 1.0 and yf < rh - 1.0):
                continue
            zr = ref_depth[int(yf + 0.5), int(xf + 0.5)]
            if zr <= 0.0 or abs(zr - qz) > OCCLUSION_PER_M * qz:
                continue
            ir = _bilinear(ref_gray, xf, yf)
            gx = _bilinear(ref_gx, xf, yf)
            gy = _bilinear(ref_gy, xf, yf)
            r = ir - i0
            if not (abs(r) <= MAX_RESIDUAL and gx == gx and gy == gy):
                continue
            # d residual / d q (the point in the reference camera), then into the world: g = R_rw^T dq
            dqx = gx * fx / qz
            dqy = gy * fy / qz
            dqz = -(gx * fx * qx + gy * fy * qy) / (qz * qz)
            g0 = R_rw[0, 0] * dqx + R_rw[1, 0] * dqy + R_rw[2, 0] * dqz
            g1 = R_rw[0, 1] * dqx + R_rw[1, 1] * dqy + R_rw[2, 1] * dqz
            g2 = R_rw[0, 2] * dqx + R_rw[1, 2] * dqy + R_rw[2, 2] * dqz
            add_correspondence(acc, J, px, py, pz, g0, g1, g2, r)
