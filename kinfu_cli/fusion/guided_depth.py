"""Guided depth filter of the colour mode filter (Monica's thesis ch. 4, Alg. 7, after He et al.'s guided filter).

Colour and depth of an RGB-D camera are never registered exactly: a calibration error of a pixel puts a band of
the neighbour's colour on every object border, and the mode filter keeps that colour there (the colour most frames
saw). The thesis re-estimates each observation's depth with a guided filter whose guide is colour and depth, so
that depth edges follow colour edges and a colour sample lands on the surface it belongs to. Per pixel, over a
circular window of radius R_m: a linear model d = a^T gamma + b of the depth from the 4-channel guide gamma =
(r, g, b, d), fitted by ridge regression with Sigma_E = diag(sigma_c^2 x3, sigma_d^2) (small sigma_c: colour
explains depth wherever it can; large sigma_d: the depth channel itself only weakly), then the window means of
(a, b) applied to the pixel's own guide. Where the colour image shows the neighbour but the depth the object, the
enhanced depth moves towards the neighbour's depth.

Departures from the thesis, on purpose:
- The guide is the observed colour and the raw depth (He et al.'s self-guided form), not the matched hypothesis'
  colour and the model's synthetic depth: a voxel grid has no per-pixel surfel to match before integrating, and a
  ray cast per frame would cost more than the integration; the observed colour carries the colour edge that is
  misregistered, which is what the filter has to follow.
- The enhanced depth moves no geometry (the TSDF fuses the raw depth, as the mean path does); it only decides
  which voxels receive the frame's colour samples (kernels._update_block, mode branch): a voxel takes the pixel's
  colour when it is within the colour band of the raw depth (as without the filter) and within GATE_VOXELS of the
  enhanced depth. Letting the enhanced depth alone decide lost the mode filter's lead at strong colour pruning.
- A gated sample is not dropped: it goes to the running mean colour (the mean path's), which only a voxel without
  hypotheses shows (mode_winners writes the winner over it everywhere else). So a voxel that took colour samples
  always ends with a colour (dropping them left ~9 % of the border voxels black, exported as such), and where gated
  and ungated samples both arrived, the ungated ones alone decide, as before. Chosen on the tuning seeds over
  taking a voxel's first sample ungated (benchmarks/bench_guided_depth.py: the better PR points at 3 of 4 T_lccp).
- Only pixels with a depth reading and a colour sample enter the window means (normalised by their count).
- sigma_c = 0.02 instead of 0.005 and a gate of 3 voxels (not the 1.2-voxel colour band: on a slanted face next to
  a colour edge the window's fit is biased by up to a voxel or two, and a tight gate dropped that face's own
  samples) were chosen on the tuning seeds 0, 1, 8-19 of benchmarks/bench_guided_depth.py; sigma_d = 5 cm and
  R_m = 3 px are the thesis' (Table 4.2). The gate was 2 voxels while gated samples were dropped; with them kept
  for the running mean, gates of 2, 2.5 and 3 voxels scored the same PR points within noise, and 3 voxels the
  lowest border colour error (bench_color_mode.py's tuning sequences 101-103; 2 voxels: worse than no gate).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

SIGMA_C = 0.02  # colour std of Sigma_E, unit RGB (thesis: 0.005; chosen on the tuning seeds)
SIGMA_D = 0.05  # depth std of Sigma_E, metres (thesis Table 4.2)
RADIUS = 3  # R_m: radius of the circular window, pixels (thesis Table 4.2)
GATE_VOXELS = 3.0  # a voxel takes a colour sample only within this many voxels of the guided depth (tuning seeds)
NCH = 15  # moments per pixel: count, 4 means, 10 second moments of (r, g, b, d)


@njit(cache=True)
def _half_widths(radius):
    """Half width of the circular window's row at each dy in [-radius, radius] (dx^2 + dy^2 <= R^2)."""
    hw = np.empty(2 * radius + 1, dtype=np.int64)
    for j in range(2 * radius + 1):
        dy = j - radius
        x = 0
        while (x + 1) * (x + 1) + dy * dy <= radius * radius:
            x += 1
        hw[j] = x
    return hw


@njit(cache=True, inline="always")
def _disk_sum(pre, v, u, hw, radius, out):
    """Sums of every channel of pre's rows over the circular window around (v, u), clipped to the image."""
    h = pre.shape[0]
    w = pre.shape[1] - 1
    out[:] = 0.0
    for j in range(2 * radius + 1):
        y = v + j - radius
        if y < 0 or y >= h:
            continue
        a = max(u - hw[j], 0)
        b = min(u + hw[j] + 1, w)
        for c in range(out.shape[0]):
            out[c] += pre[y, b, c] - pre[y, a, c]


@njit(cache=True, inline="always")
def _solve4(m, r, x):
    """x = m^-1 r for a symmetric positive definite 4x4 m (Cholesky, in place on m; its diagonal ends as the
    reciprocals of L's: one division per column instead of one per entry)."""
    for j in range(4):
        s = m[j, j]
        for k in range(j):
            s -= m[j, k] * m[j, k]
        inv = 1.0 / np.sqrt(max(s, 1e-30))
        m[j, j] = inv
        for i in range(j + 1, 4):
            t = m[i, j]
            for k in range(j):
                t -= m[i, k] * m[j, k]
            m[i, j] = t * inv
    for i in range(4):  # forward: L y = r
        t = r[i]
        for k in range(i):
            t -= m[i, k] * x[k]
        x[i] = t * m[i, i]
    for i in range(3, -1, -1):  # backward: L^T x = y
        t = x[i]
        for k in range(i + 1, 4):
            t -= m[k, i] * x[k]
        x[i] = t * m[i, i]


@njit(cache=True, parallel=True)
def _moment_prefix(depth, color, color_ok, pre, valid):
    """Row prefix sums of the per-pixel moments (count, (r, g, b, d) in unit RGB and metres, their 10 products),
    each pixel's moments 0 where it has no reading or no colour sample: pre[v, u + 1] = sum over pixels 0..u of
    row v (float64, (H, W + 1, NCH)); valid[v, u] 1 where the pixel has both. One pass: no per-pixel moment
    image is stored (it was as large as `pre`, and writing then re-reading it cost more than the sums)."""
    h, w = depth.shape
    inv = 1.0 / 255.0
    for v in prange(h):
        acc = np.zeros(NCH, dtype=np.float64)
        gv = np.empty(4, dtype=np.float64)
        pre[v, 0, :] = 0.0
        for u in range(w):
            p = v * w + u
            ok = depth[v, u] > 0.0 and (color_ok.shape[0] == 0 or color_ok[p] != 0)
            valid[v, u] = ok
            if ok:
                gv[0] = color[p, 0] * inv
                gv[1] = color[p, 1] * inv
                gv[2] = color[p, 2] * inv
                gv[3] = depth[v, u]
                acc[0] += 1.0
                c = 5
                for i in range(4):
                    acc[1 + i] += gv[i]
                    for k in range(i, 4):
                        acc[c] += gv[i] * gv[k]
                        c += 1
            for c in range(NCH):
                pre[v, u + 1, c] = acc[c]


@njit(cache=True, parallel=True)
def _coefficient_prefix(pre, valid, hw, radius, sc2, sd2, pre_ab):
    """Row prefix sums (as _moment_prefix's) of (1, a, b) of the windowed ridge fit per valid pixel (Alg. 7 lines
    1-8), 0 at the others: pre_ab (H, W + 1, 6), what _apply's window means of (a, b) need."""
    h, w = valid.shape
    for v in prange(h):
        s = np.empty(NCH, dtype=np.float64)
        m = np.empty((4, 4), dtype=np.float64)
        r = np.empty(4, dtype=np.float64)
        x = np.empty(4, dtype=np.float64)
        mu = np.empty(4, dtype=np.float64)
        acc = np.zeros(6, dtype=np.float64)
        pre_ab[v, 0, :] = 0.0
        for u in range(w):
            if valid[v, u]:
                _disk_sum(pre, v, u, hw, radius, s)
                inv_n = 1.0 / s[0]
                for i in range(4):
                    mu[i] = s[1 + i] * inv_n
                c = 5
                for i in range(4):
                    for k in range(i, 4):
                        cov = s[c] * inv_n - mu[i] * mu[k]
                        m[i, k] = cov
                        m[k, i] = cov
                        c += 1
                for i in range(4):
                    r[i] = m[i, 3]  # cov(gamma, d): the input is the guide's depth channel
                for i in range(3):
                    m[i, i] += sc2
                m[3, 3] += sd2
                _solve4(m, r, x)
                b = mu[3]
                for i in range(4):
                    b -= x[i] * mu[i]
                    acc[1 + i] += x[i]
                acc[0] += 1.0
                acc[5] += b
            for c in range(6):
                pre_ab[v, u + 1, c] = acc[c]


@njit(cache=True, parallel=True)
def _apply(pre_ab, depth, color, valid, hw, radius, out):
    """d_e = F_m(a)^T gamma + F_m(b) at valid pixels (Alg. 7 lines 9-11), 0 elsewhere, into out (H, W) float32."""
    h, w = valid.shape
    inv = 1.0 / 255.0
    for v in prange(h):
        s = np.empty(6, dtype=np.float64)
        for u in range(w):
            if not valid[v, u]:
                out[v, u] = 0.0
                continue
            p = v * w + u
            _disk_sum(pre_ab, v, u, hw, radius, s)
            d = s[5]
            d += s[1] * (color[p, 0] * inv)
            d += s[2] * (color[p, 1] * inv)
            d += s[3] * (color[p, 2] * inv)
            d += s[4] * np.float64(depth[v, u])
            out[v, u] = d / s[0]


def guided_depth(depth: np.ndarray, color: np.ndarray, color_ok: np.ndarray | None = None,
                 radius: int | None = None, sigma_c: float | None = None, sigma_d: float | None = None,
                 buffers: dict | None = None) -> np.ndarray:
    """Enhanced depth (float32 (H, W), 0 where there is no reading) of depth (H, W) metres, guided by color
    (uint8 (H * W, 3) or (H, W, 3)); color_ok: uint8 (H * W,) 1 where the colour has a sample (empty: everywhere).
    buffers: a dict the caller keeps between frames of one size, for the work arrays (~50 MB at 640x480, which
    fresh cost more to page in than to fill) and the result, which the next call then overwrites."""
    d = np.ascontiguousarray(depth, dtype=np.float32)
    col = np.ascontiguousarray(color, dtype=np.uint8).reshape(-1, 3)
    ok = np.zeros(0, np.uint8) if color_ok is None else np.ascontiguousarray(color_ok, dtype=np.uint8).reshape(-1)
    radius = RADIUS if radius is None else radius
    sigma_c = SIGMA_C if sigma_c is None else sigma_c
    sigma_d = SIGMA_D if sigma_d is None else sigma_d
    h, w = d.shape
    buf = {} if buffers is None else buffers
    if buf.get("shape") != (h, w):
        buf.clear()
        buf.update(shape=(h, w), pre=np.empty((h, w + 1, NCH)), valid=np.empty((h, w), dtype=np.bool_),
                   pre_ab=np.empty((h, w + 1, 6)), out=np.empty((h, w), dtype=np.float32))
    hw = _half_widths(int(radius))
    _moment_prefix(d, col, ok, buf["pre"], buf["valid"])
    _coefficient_prefix(buf["pre"], buf["valid"], hw, int(radius), float(sigma_c) ** 2, float(sigma_d) ** 2,
                        buf["pre_ab"])
    _apply(buf["pre_ab"], d, col, buf["valid"], hw, int(radius), buf["out"])
    return buf["out"]
