"""Colour mode filter of the fusion volume (Monica's thesis ch. 4, Alg. 6, moved from surfels to voxels).

The running mean colour blurs colour edges: a voxel at an object's border sees the neighbour's colour in
the frames where the colour image is off by a pixel (colour/depth misregistration, lateral noise), and
auto-gain shifts every colour from frame to frame. The mode filter keeps, per surface voxel, up to M colour
hypotheses with a count each. A new colour sample joins the nearest hypothesis when it is within the
distance threshold T (RGB 0..255, Euclidean) and updates its colour like the mean path does (a running mean
with the hypothesis' own count, alpha >= 0.1); otherwise it opens a new hypothesis, replacing the one seen
least often when all M are taken (Alg. 6 lines 8-14). After an update, hypotheses the updated one explains
better than themselves are merged into it (Alg. 6 lines 21-26, eq. 4.10 with an isotropic Gaussian of
sigma = T / 5: the thesis' new-mode threshold is K sigma_c with K = 5). At read-out the winner takes all
(eq. 4.11): the hypothesis with the highest count becomes the voxel's colour, in the same pool the mean path
fills, so meshes, clouds and segmentation use it unchanged.

Deliberate departures from the thesis: counts instead of the image-centre weights w_uv (the mean path counts
observations too); no position hypotheses (the TSDF fuses geometry; the guided depth, guided_depth.py, only gates
which samples a voxel's hypotheses take); M and T are small and were chosen on generated sequences
(benchmarks/bench_color_mode.py, its choose mode), not taken from the thesis (M_max = 10, K sigma_c = 0.025 of the
unit cube), whose memory and gain-sensitivity do not suit 512^3 voxel grids and auto-gain cameras.

Storage, only with color_mode "mode": pool_hc uint8 (n, 512, M, 3) colours and pool_hn uint8 (n, 512, M)
counts, per stored block (M = 2: 4 bytes per hypothesis, 8 bytes per voxel). A count reaching 255 halves
all counts of its voxel, which keeps their ratios.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from kinfu_cli.core.errors import ConfigError

COLOR_MODES = ("mean", "mode")
# M and T: the least border blur, with the error elsewhere within 1 of the mean's, over M in 2, 3, 4 and T in 15,
# 25, 40, 60, 90 on three generated tuning sequences (bench_color_mode.py's choose mode; M = 3 and 4 scored the
# same as 2 at T = 60, so the smaller one)
MAX_HYPOTHESES = 2  # M: colour hypotheses per voxel
MODE_THRESHOLD = 60.0  # T: RGB distance (0..255) within which a sample joins a hypothesis
SIGMA_PER_THRESHOLD = 0.2  # sigma_c = T / 5 in the merge test (thesis: threshold K sigma_c, K = 5)


@njit(cache=True, error_model="numpy")
def _merge_close(hc, hn, i, k, best, thr2):
    """Alg. 6 lines 21-26: fold every other hypothesis m with exp(-d^2 / (2 sigma^2)) n_best > n_m into best."""
    nh = hn.shape[2]
    inv = np.float32(1.0 / (2.0 * SIGMA_PER_THRESHOLD * SIGMA_PER_THRESHOLD)) / max(thr2, np.float32(1e-6))
    for m in range(nh):
        nm = np.int32(hn[i, k, m])
        if m == best or nm == 0:
            continue
        d2 = np.float32(0.0)
        for ch in range(3):
            e = np.float32(hc[i, k, m, ch]) - np.float32(hc[i, k, best, ch])
            d2 += e * e
        nb = np.int32(hn[i, k, best])
        if np.exp(-d2 * inv) * np.float32(nb) > np.float32(nm):
            tot = nb + nm
            for ch in range(3):
                c = (np.float32(hc[i, k, best, ch]) * nb + np.float32(hc[i, k, m, ch]) * nm) / np.float32(tot)
                hc[i, k, best, ch] = np.uint8(min(np.float32(255.0), c + np.float32(0.5)))
            hn[i, k, best] = np.uint8(min(tot, 255))
            hn[i, k, m] = 0


@njit(cache=True, error_model="numpy")
def mode_update(hc, hn, i, k, r, g, b, thr2):
    """Fold colour sample (r, g, b) uint8 into the hypotheses of voxel k of pool row i (Alg. 6)."""
    nh = hn.shape[2]
    best = -1
    bd = np.float32(np.inf)
    free = -1
    low = -1
    lown = 256
    for m in range(nh):
        n = np.int32(hn[i, k, m])
        if n == 0:
            if free < 0:
                free = m
            continue
        dr = np.float32(hc[i, k, m, 0]) - np.float32(r)
        dg = np.float32(hc[i, k, m, 1]) - np.float32(g)
        db = np.float32(hc[i, k, m, 2]) - np.float32(b)
        d = dr * dr + dg * dg + db * db
        if d < bd:
            bd = d
            best = m
        if n < lown:
            lown = n
            low = m
    if best < 0 or bd > thr2:  # a new mode: a free slot, else the one seen least often
        slot = free if free >= 0 else low
        hc[i, k, slot, 0] = r
        hc[i, k, slot, 1] = g
        hc[i, k, slot, 2] = b
        hn[i, k, slot] = 1
        return
    n = np.int32(hn[i, k, best]) + 1
    if n >= 255:  # keep the counts' ratios, not their size
        for m in range(nh):
            hn[i, k, m] = np.uint8((np.int32(hn[i, k, m]) + 1) >> 1)
        n = np.int32(hn[i, k, best]) + 1
    hn[i, k, best] = np.uint8(n)
    alpha = max(np.float32(1.0) / np.float32(n), np.float32(0.1))
    for ch in range(3):
        c0 = np.float32(hc[i, k, best, ch])
        cn = np.float32(r if ch == 0 else (g if ch == 1 else b))
        hc[i, k, best, ch] = np.uint8(min(np.float32(255.0), c0 + alpha * (cn - c0) + np.float32(0.5)))
    if nh > 1:
        _merge_close(hc, hn, i, k, best, thr2)


@njit(cache=True, parallel=True)
def mode_winners(hc, hn, pool_c, n_used):
    """Winner takes all (eq. 4.11): pool_c of every voxel with a hypothesis gets the most counted one's colour;
    voxels without hypotheses keep their colour."""
    nh = hn.shape[2]
    for i in prange(n_used):
        for k in range(hn.shape[1]):
            best = -1
            bn = 0
            for m in range(nh):
                if hn[i, k, m] > bn:
                    bn = hn[i, k, m]
                    best = m
            if best >= 0:
                for ch in range(3):
                    pool_c[i, k, ch] = hc[i, k, best, ch]


def check_color_mode(value: str) -> str:
    """The colour mode name, lower case; ConfigError naming the parameter otherwise."""
    mode = str(value).strip().lower()
    if mode not in COLOR_MODES:
        raise ConfigError(f"expected one of {', '.join(COLOR_MODES)}, got {value!r}",
                          parameter="color_mode")
    return mode
