"""TernaryVolume: a KinectFusion TSDF volume that knows unknown / empty / occupied for every voxel.

Per voxel a truncated signed distance v in [-1, 1], a weight w in [0, max_weight] and (optionally) a
colour. Ternary rule (digest §1.2, eq. 2.11): w = 0 unknown; w > 0 and v <= 0 occupied; w > 0 and v > 0
empty. Free space in front of observed surfaces becomes known-empty (v = 1); interiors beyond the
truncation band stay unknown.

Storage is sparse by 8^3 blocks (see kernels.py): never-observed space costs one byte per block,
carved free space too; only blocks near surfaces hold per-voxel v (int16), w (uint8) and colour.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.ndimage import binary_dilation

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, check_up, read_ternary
from kinfu_cli.core.memory import check_grid_memory
from kinfu_cli.core.poses import check_rigid
from kinfu_cli.core.volume_file import (FORMAT, FORMAT_VERSION, MAX_COORDINATE_M, MAX_RANGE_M, MIN_VOXEL_M,
                                        check_intrinsics, read_volume_file, read_volume_meta, write_volume_file)
from kinfu_cli.fusion import guided_depth as gdf
from kinfu_cli.fusion import kernels as kn
from kinfu_cli.fusion.color_mode import MAX_HYPOTHESES, MODE_THRESHOLD, check_color_mode, mode_winners
from kinfu_cli.fusion.mesh import extract_mesh

BYTES_PER_VOXEL = 3  # v int16 + w uint8
BYTES_PER_VOXEL_COLOR = 3
BYTES_PER_HYPOTHESIS = 4  # colour mode filter: uint8 RGB + uint8 count


def _triple(x, name: str, kind=float) -> tuple:
    if np.isscalar(x):
        t = (kind(x),) * 3
    else:
        t = tuple(kind(v) for v in x)
        if len(t) != 3:
            raise ConfigError(f"{name}: expected one value or three (x, y, z), got {len(t)}")
    return t


def worst_case_bytes(shape, color, hypotheses: int = MAX_HYPOTHESES) -> int:
    """Bytes a grid of `shape` voxels needs when every block holds a surface (block tables and full pools).
    color: False, True (mean colour) or "mode" (mean colour plus the mode filter's hypotheses)."""
    nblocks = int(np.prod([(int(d) + kn.B - 1) // kn.B for d in shape]))
    per_voxel = BYTES_PER_VOXEL + (BYTES_PER_VOXEL_COLOR if color else 0)
    if isinstance(color, str) and color == "mode":
        per_voxel += hypotheses * BYTES_PER_HYPOTHESIS
    return nblocks * (kn.B3 * per_voxel + 5)


# the fewest voxels a new grid may have along an axis: fewer hold no surface worth a mesh (a 3 m voxel in a 2 m box
# made a one-voxel grid that fused nothing, without a word)
MIN_GRID_VOXELS = 4
# the narrowest truncation band, in voxels: below half a voxel most surfaces fall between voxel centres and vanish
# (0.3 voxel kept 2 occupied voxels of a table scene, 0.25 a fifth of them; 0.75, the 4 cm room tests', holds)
MIN_TRUNCATION_VOXELS = 0.5
# the truncation when none is given: KinectFusion's 3 cm, widened to 0.75 voxel for voxels over 4 cm (a coarse grid
# would lose its surfaces with 3 cm)
DEFAULT_TRUNCATION_M = 0.03
DEFAULT_TRUNCATION_VOXELS = 0.75


def default_truncation(voxel_size: float) -> float:
    """The truncation distance (m) of a grid of `voxel_size` when none is given."""
    return max(DEFAULT_TRUNCATION_M, DEFAULT_TRUNCATION_VOXELS * float(voxel_size))


def _check_grid_use(size, dims, voxel_size: float, truncation: float, voxel_size_given: bool) -> None:
    """ConfigError when a new grid cannot hold a surface: too few voxels along an axis, or a truncation band
    narrower than MIN_TRUNCATION_VOXELS."""
    if min(dims) < MIN_GRID_VOXELS:
        raise ConfigError(f"a {'x'.join(f'{s:g}' for s in size)} m grid holds {'x'.join(map(str, dims))} voxels of "
                          f"{voxel_size:g} m: expected at least {MIN_GRID_VOXELS} along each axis (a smaller voxel or "
                          f"a larger size)", parameter="voxel_size" if voxel_size_given else "size/resolution")
    if truncation < MIN_TRUNCATION_VOXELS * voxel_size:
        raise ConfigError(f"{truncation:g} m is under half the {voxel_size:g} m voxel: surfaces would fall between "
                          f"voxel centres and vanish (expected at least {MIN_TRUNCATION_VOXELS * voxel_size:g} m; "
                          f"KinectFusion uses a few voxels)", parameter="truncation")


class TernaryVolume:
    """A KinFu-style TSDF grid with free-space carving.

    size: edge length(s) in metres (one value for a cube); resolution: voxels per axis (one value or three);
    voxel_size: overrides resolution (resolution = ceil(size / voxel_size)); origin: world position of the
    grid's minimum corner (default: grid centred on the world origin); truncation: M_v in metres;
    max_weight: M_w; min_depth/max_depth: depth readings outside are ignored; color: keep RGB per voxel;
    color_mode: "mean" (running mean) or "mode" (colour hypotheses, winner takes all: fusion/color_mode.py).
    """

    def __init__(self, size=(3.0, 3.0, 3.0), resolution=512, voxel_size: float | None = None,
                 origin=None, truncation: float | None = DEFAULT_TRUNCATION_M, max_weight: int = 128,
                 min_depth: float = 0.3, max_depth: float = 4.0, color: bool = True, color_mode: str = "mean",
                 _allocate: bool = True) -> None:
        size = _triple(size, "size")
        voxel_size_given = voxel_size is not None
        if not all(0 < s <= MAX_COORDINATE_M for s in size):  # NaN fails too; 1e308 overflowed the voxel check
            raise ConfigError(f"expected positive lengths in metres up to {MAX_COORDINATE_M:g}, got {size}",
                              parameter="size")
        if voxel_size is not None:
            voxel_size = float(voxel_size)
            if not (np.isfinite(voxel_size) and voxel_size > 0):
                raise ConfigError(f"expected a positive length in metres, got {voxel_size}", parameter="voxel_size")
            dims = tuple(max(1, int(np.ceil(s / voxel_size - 1e-9))) for s in size)
        else:
            dims = _triple(resolution, "resolution", int)
            if not all(d > 0 for d in dims):
                raise ConfigError(f"resolution: expected positive voxel counts, got {dims}")
            if len(set(np.round(np.array(size) / np.array(dims), 12))) != 1:
                raise ConfigError(f"size {size} and resolution {dims} give non-cubic voxels; give a voxel size "
                                  f"instead", parameter="voxel_size")
            voxel_size = size[0] / dims[0]
        if not MIN_VOXEL_M <= voxel_size <= MAX_RANGE_M:  # 1e-300 overflowed the voxel counts and index casts
            raise ConfigError(f"expected a voxel edge of {MIN_VOXEL_M * 1000:g} mm to {MAX_RANGE_M:g} m, got "
                              f"{voxel_size:g} m",
                              parameter="voxel_size" if voxel_size_given else "size/resolution")
        truncation = default_truncation(voxel_size) if truncation is None else truncation
        # finite and of a sensor's size: a 1e300 truncation or depth range overflows the kernels' casts
        check_number(truncation, "truncation", 0, MAX_RANGE_M, low_open=True, unit="m")
        check_number(max_weight, "max_weight", 1, 255, integer=True)
        check_number(min_depth, "min_depth", 0, MAX_RANGE_M, unit="m")
        check_number(max_depth, "max_depth", 0, MAX_RANGE_M, unit="m")
        if not min_depth < max_depth:
            raise ConfigError(f"expected 0 <= min < max, got {min_depth}, {max_depth}", parameter="min_depth/max_depth")
        if _allocate:  # a new grid; a volume read back is taken as it was fused
            _check_grid_use(size, dims, voxel_size, float(truncation), voxel_size_given)
        self.voxel_size = float(voxel_size)
        self.shape = tuple(int(d) for d in dims)
        if origin is None:
            origin = -0.5 * np.array(self.shape) * self.voxel_size
        self.origin = np.asarray(_triple(origin, "origin"), dtype=np.float64)
        if not np.all(np.isfinite(self.origin)) or np.any(np.abs(self.origin) > MAX_COORDINATE_M):
            raise ConfigError(f"expected finite x,y,z within {MAX_COORDINATE_M:g} m, got "
                              f"{tuple(float(v) for v in self.origin)}", parameter="origin")
        self.truncation = float(truncation)
        self.max_weight = int(max_weight)
        self.min_depth = float(min_depth)
        self.max_depth = float(max_depth)
        self.color = bool(color)
        self.color_mode = check_color_mode(color_mode) if self.color else "mean"
        self._winners_stale = False  # mode: hypotheses changed since pool_c last got the winners
        self.mode_hypotheses = MAX_HYPOTHESES  # M and T of the mode filter (color_mode.py); set before integrating
        self.mode_threshold = MODE_THRESHOLD
        self.mode_guided = True  # mode: colour samples gated by the guided depth (fusion/guided_depth.py)
        self.nb = np.array([(d + kn.B - 1) // kn.B for d in self.shape], dtype=np.int64)
        self._check_memory()
        self._raylen_cache: dict = {}
        self.frames_integrated = 0
        self.frame = ""  # name of the world frame the poses were given in ("" = not known)
        self.up: np.ndarray | None = None  # unit direction against gravity in that frame (None = not known)
        self.up_source = ""  # how up was decided (fusion.up.choose_up), "" when not known
        self.intrinsics: dict | None = None  # the depth camera fused: fx, fy, cx, cy, width, height
        self.hypotheses_loaded = True  # False: read by load_volume(hypotheses=False), not to be fused into or saved
        if _allocate:
            self.block_idx = np.full(tuple(self.nb), -1, dtype=np.int32)
            self.block_w = np.zeros(tuple(self.nb), dtype=np.uint8)
            self.n_used = 0
            self._alloc_pools(1024)

    # ------------------------------------------------------------------ storage
    @property
    def bytes_worst_case(self) -> int:
        return worst_case_bytes(self.shape, "mode" if self.color_mode == "mode" else self.color,
                                self.mode_hypotheses)

    def _check_memory(self) -> None:
        nx, ny, nz = self.shape
        check_grid_memory(self.bytes_worst_case, f"volume of {nx}x{ny}x{nz} voxels at {self.voxel_size * 1000:.2f} mm",
                          "use a coarser voxel size or a smaller size", parameter="voxel_size/size")

    def _alloc_pools(self, cap: int) -> None:
        self.pool_v = np.zeros((cap, kn.B3), dtype=np.int16)
        self.pool_w = np.zeros((cap, kn.B3), dtype=np.uint8)
        self.pool_c = np.zeros((cap if self.color else 0, kn.B3, 3), dtype=np.uint8)
        nh = cap if self.color_mode == "mode" else 0
        self.pool_hc = np.zeros((nh, kn.B3, self.mode_hypotheses, 3), dtype=np.uint8)
        self.pool_hn = np.zeros((nh, kn.B3, self.mode_hypotheses), dtype=np.uint8)

    def _ensure_capacity(self, need: int) -> None:
        self._check_hypotheses()
        cap = self.pool_v.shape[0]
        if need <= cap:
            return
        new = max(need, int(cap * 1.6) + 256)
        new = min(new, int(np.prod(self.nb)))
        new = max(new, need)
        pv = np.zeros((new, kn.B3), dtype=np.int16)
        pw = np.zeros((new, kn.B3), dtype=np.uint8)
        pv[: self.n_used] = self.pool_v[: self.n_used]
        pw[: self.n_used] = self.pool_w[: self.n_used]
        if self.color:
            pc = np.zeros((new, kn.B3, 3), dtype=np.uint8)
            pc[: self.n_used] = self.pool_c[: self.n_used]
            self.pool_c = pc
        if self.color_mode == "mode":
            hc = np.zeros((new,) + self.pool_hc.shape[1:], dtype=np.uint8)
            hn = np.zeros((new,) + self.pool_hn.shape[1:], dtype=np.uint8)
            hc[: self.n_used] = self.pool_hc[: self.n_used]
            hn[: self.n_used] = self.pool_hn[: self.n_used]
            self.pool_hc, self.pool_hn = hc, hn
        self.pool_v, self.pool_w = pv, pw

    @property
    def n_blocks_allocated(self) -> int:
        return int(self.n_used)

    def memory_bytes(self) -> int:
        """Bytes held by the grid's arrays (block tables and pools)."""
        return int(self.block_idx.nbytes + self.block_w.nbytes + self.pool_v.nbytes + self.pool_w.nbytes
                   + self.pool_c.nbytes + self.pool_hc.nbytes + self.pool_hn.nbytes)

    # ------------------------------------------------------------------ integration
    def _raylen(self, K: np.ndarray, width: int, height: int) -> np.ndarray:
        key = (tuple(np.round(K.ravel(), 9)), width, height)
        r = self._raylen_cache.get(key)
        if r is None:
            u = (np.arange(width, dtype=np.float64) - K[0, 2]) / K[0, 0]
            v = (np.arange(height, dtype=np.float64) - K[1, 2]) / K[1, 1]
            r = np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2).astype(np.float32)
            self._raylen_cache = {key: r}
        return r

    def prepare_depth(self, depth: np.ndarray) -> np.ndarray:
        """float32 depth with readings outside [min_depth, max_depth] (and NaN) set to 0."""
        d = np.ascontiguousarray(depth, dtype=np.float32)
        if d.ndim != 2:
            raise VolumeError(f"depth: expected a 2-D image in metres, got shape {d.shape}")
        return kn.clean_depth(d, self.min_depth, self.max_depth)

    def integrate(self, depth: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray,
                  color: np.ndarray | None = None, color_mask: np.ndarray | None = None) -> dict:
        """Fuse one depth image (metres, float32 (H, W); 0/NaN = no reading) taken from T_world_camera.

        color: uint8 RGB (H, W, 3) registered to the depth image, or None; color_mask: bool (H, W), False where
        `color` has no sample (None: it has one everywhere; an exactly black pixel never has one). Returns counts of
        blocks carved in bulk and updated voxel by voxel, and of the valid readings and those whose point lies in
        the grid (readings_in_grid: none means the frame added no surface, a wrong pose or grid).
        """
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise VolumeError(f"K: expected finite 3x3 intrinsics with fx, fy > 0, got {K.tolist()}")
        T = check_rigid(T_world_camera)
        d = self.prepare_depth(depth)
        dmax_all = float(d.max()) if d.size else 0.0
        h, w = d.shape
        if not (0 <= K[0, 2] <= w and 0 <= K[1, 2] <= h):
            raise VolumeError(f"depth image {w}x{h} does not match the intrinsics (principal point "
                              f"{K[0, 2]:.1f}, {K[1, 2]:.1f} outside the image)")
        if not dmax_all > 0:
            raise VolumeError(f"depth image has no valid pixels in [{self.min_depth}, {self.max_depth}] m")
        if color is not None and self.color:
            color = np.asarray(color)
            if color.ndim != 3 or color.shape[2] < 3:
                raise VolumeError(f"color: expected an RGB image (H, W, 3), got shape {color.shape}")
            if color.shape[:2] != (h, w):
                import cv2  # only here: readers of volumes (segment, nbv) need not load OpenCV

                color = cv2.resize(np.ascontiguousarray(color[:, :, :3]), (w, h), interpolation=cv2.INTER_NEAREST)
            col = np.ascontiguousarray(color[:, :, :3], dtype=np.uint8)
        else:
            col = np.zeros((0, 0, 3), dtype=np.uint8)
        ok = np.zeros(0, dtype=np.uint8)
        if color_mask is not None and col.size:
            m = np.asarray(color_mask, dtype=bool)
            if m.shape != col.shape[:2]:
                raise VolumeError(f"color_mask: expected shape {col.shape[:2]}, got {m.shape}")
            ok = np.ascontiguousarray(m.reshape(-1), dtype=np.uint8)
        if col.size:
            # an exactly black pixel is no colour sample: registered colour images (a RealSense's aligned colour)
            # mark their holes so, and black is the volume's "never coloured" (a black sample would only darken
            # the running mean of a coloured voxel)
            flat = col.reshape(-1, 3)
            seen = (flat[:, 0] | flat[:, 1] | flat[:, 2]) != 0  # ndarray.any(axis=1) is 8x slower on 3 bytes a row
            if not seen.all():
                ok = np.ascontiguousarray(seen if ok.size == 0 else seen & ok.astype(bool), dtype=np.uint8)
        T_cw = np.linalg.inv(T)
        fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
        pm = self._pyramid_buffer(h, w)
        kn.depth_pyramid(d, pm)
        inv_sat = kn._invalid_integral(d)
        b_lo, b_hi = self._frustum_blocks(T, K, w, h, dmax_all + self.truncation)
        cls = kn.classify_blocks(self.nb, self.origin, self.voxel_size, T_cw, fx, fy, cx, cy, w, h,
                                 self.truncation, pm, inv_sat, dmax_all, b_lo, b_hi)
        bidx = self.block_idx.reshape(-1)
        bw = self.block_w.reshape(-1)
        work, new_b, n_carve, n_voxel = kn.work_list(cls, bidx)
        work = self._work_order(work)
        if new_b.size:
            self._ensure_capacity(self.n_used + new_b.size)
            self.n_used = kn.allocate_new(new_b, bidx, bw, self.pool_v, self.pool_w, self.pool_c, self.n_used)
        guided = np.zeros(0, dtype=np.float32)
        if self.color_mode == "mode" and self.mode_guided and col.shape[0] > 0:
            if getattr(self, "_guided_buffers", None) is None:
                self._guided_buffers = {}  # the guided filter's work arrays, kept between frames (its docstring)
            guided = gdf.guided_depth(d, col, ok, buffers=self._guided_buffers).reshape(-1)
        kn.integrate_blocks(cls, self.nb, np.array(self.shape, dtype=np.int64), bidx, bw, self.pool_v,
                            self.pool_w, self.pool_c, *self._hypotheses(), self.origin, self.voxel_size,
                            T_cw, fx, fy, cx, cy, w, h, kn.depth_and_raylen(d, self._raylen(K, w, h)),
                            col.reshape(-1, 3), ok, self.truncation, self.max_weight, work, float(self.mode_threshold),
                            guided, float(gdf.GATE_VOXELS))
        self._winners_stale = self._winners_stale or (self.color_mode == "mode" and col.shape[0] > 0)
        self.frames_integrated += 1
        lo, hi = self.bounds()
        readings, in_grid = kn.readings_in_box(d, T, fx, fy, cx, cy, lo, hi)
        return {"blocks_carved": int(n_carve), "blocks_voxelwise": int(n_voxel),
                "blocks_allocated": int(self.n_used), "readings": int(readings), "readings_in_grid": int(in_grid)}

    def _hypotheses(self) -> tuple:
        """The mode filter's pools for the kernels; (None, None) for the mean, whose kernel then lacks the mode
        code altogether."""
        self._check_hypotheses()
        return (self.pool_hc, self.pool_hn) if self.color_mode == "mode" else (None, None)

    def _frustum_blocks(self, T: np.ndarray, K: np.ndarray, w: int, h: int, far: float):
        """Block index box [lo, hi) holding the viewing frustum up to depth `far` (one block of margin)."""
        corners = np.array([[-1, -1], [w + 1, -1], [-1, h + 1], [w + 1, h + 1]], dtype=np.float64)
        rays = np.stack([(corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1],
                         np.ones(4)], axis=1) * far
        pts = np.vstack([np.zeros(3), rays]) @ T[:3, :3].T + T[:3, 3]
        lo = np.floor((pts.min(axis=0) - self.origin) / (self.voxel_size * kn.B)).astype(np.int64) - 1
        hi = np.floor((pts.max(axis=0) - self.origin) / (self.voxel_size * kn.B)).astype(np.int64) + 2
        return np.clip(lo, 0, self.nb), np.clip(hi, 0, self.nb)

    def _pyramid_buffer(self, h: int, w: int) -> np.ndarray:
        buf = getattr(self, "_pm", None)
        if buf is None or buf.shape[1:3] != (h, w):
            buf = np.empty((kn.PYR_LEVELS, h, w, 2), dtype=np.float32)
            self._pm = buf
        return buf

    @staticmethod
    def _work_order(work: np.ndarray, chunk: int = 256) -> np.ndarray:
        """Blocks with work, in runs of `chunk` neighbouring blocks (pool rows and depth pixels stay in cache)
        whose order is shuffled with a fixed seed, so that numba's static split gives both threads similar
        loads (busy blocks are spatially clustered)."""
        n = work.shape[0]
        if n <= chunk:
            return work
        starts = np.arange(0, n, chunk)
        np.random.default_rng(12345).shuffle(starts)
        idx = (starts[:, None] + np.arange(chunk)[None, :]).ravel()
        return work[idx[idx < n]]

    def clear_sphere(self, center, radius: float) -> None:
        """Forget every voxel whose centre is inside the sphere (v = 0, w = 0: unknown), as ForgetAround."""
        c = np.asarray(center, dtype=np.float64).reshape(3)
        radius = float(radius)
        if not (np.all(np.isfinite(c)) and np.isfinite(radius) and radius > 0):
            raise ConfigError(f"clear sphere: expected finite centre and radius > 0, got {c.tolist()}, {radius}")
        sph = kn.sphere_blocks(self.nb, self.origin, self.voxel_size, c, radius)
        bidx = self.block_idx.reshape(-1)
        bw = self.block_w.reshape(-1)
        # partly covered uniform blocks that are known need per-voxel storage first
        part = np.flatnonzero((sph == 1) & (bidx < 0) & (bw > 0))
        if part.size:
            cls = np.zeros_like(sph)
            cls[part] = kn.VOXEL
            self._ensure_capacity(self.n_used + part.size)
            self.n_used = kn.allocate_blocks(cls, bidx, bw, self.pool_v, self.pool_w, self.pool_c, self.n_used)
        kn.clear_sphere_blocks(sph, self.nb, bidx, bw, self.pool_v, self.pool_w, self.origin, self.voxel_size,
                               c, radius)

    # ------------------------------------------------------------------ read-out
    def labels(self) -> np.ndarray:
        """Ternary labels int8 [x, y, z]: 1 occupied, 0 unknown, -1 empty."""
        return kn.labels_dense(self.nb, np.array(self.shape, dtype=np.int64), self.block_idx, self.block_w,
                               self.pool_v, self.pool_w)

    def labels_at(self, points: np.ndarray) -> np.ndarray:
        """int8 (N,) labels at world points (N, 3), as `labels()` gives them, read from the blocks (no dense
        grid: 134 MB at 512^3); points outside the grid were never observed: UNKNOWN."""
        idx = np.floor((np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.origin) / self.voxel_size)
        idx = idx.astype(np.int64)
        inside = np.all((idx >= 0) & (idx < np.array(self.shape)), axis=1)
        out = np.full(len(idx), UNKNOWN, dtype=np.int8)
        g = idx[inside]
        blk, loc = g // kn.B, g % kn.B
        i = self.block_idx[blk[:, 0], blk[:, 1], blk[:, 2]]
        carved = self.block_w[blk[:, 0], blk[:, 1], blk[:, 2]] > 0  # a block seen only as free space
        k = loc[:, 0] * kn.B * kn.B + loc[:, 1] * kn.B + loc[:, 2]
        j = np.maximum(i, 0)
        w, v = self.pool_w[j, k], self.pool_v[j, k]
        stored = np.where(w == 0, UNKNOWN, np.where(v <= 0, OCCUPIED, EMPTY))
        out[inside] = np.where(i < 0, np.where(carved, EMPTY, UNKNOWN), stored)
        return out

    def ternary_grid(self) -> TernaryGrid:
        return TernaryGrid(self.labels(), self.origin.copy(), self.voxel_size, self.frame, self.up, self.intrinsics)

    def _box(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        lo = np.zeros(3, np.int64) if lo is None else np.asarray(lo, dtype=np.int64).reshape(3)
        hi = np.array(self.shape, np.int64) if hi is None else np.asarray(hi, dtype=np.int64).reshape(3)
        lo = np.clip(lo, 0, self.shape)
        hi = np.clip(hi, lo, self.shape)
        return lo, hi

    def tsdf_weights(self, lo=None, hi=None, color: bool = False):
        """Dense (v float32, w uint8[, colour uint8 (..., 3)]) over the voxel box [lo, hi) (default: all).

        Whole 512^3 grids cost 640 MB here; ask for sub-boxes where possible.
        """
        lo, hi = self._box(lo, hi)
        if color:
            self.sync_colors()
        tv, tw, tc = kn.dense_box(lo, hi, self.block_idx, self.block_w, self.pool_v, self.pool_w, self.pool_c,
                                  bool(color))
        return (tv, tw, tc) if color else (tv, tw)

    def sync_colors(self) -> None:
        """Mode filter: write each voxel's winning hypothesis into the colour pool (a no-op for the mean)."""
        if self._winners_stale:
            mode_winners(self.pool_hc, self.pool_hn, self.pool_c, self.n_used)
            self._winners_stale = False

    def voxel_colors(self, idx: np.ndarray) -> np.ndarray:
        """uint8 (N, 3) colours of the voxels at grid indices idx (N, 3), as `tsdf_weights(color=True)` gives them
        (black: never coloured, or no voxel stored there), read from the blocks: a caller that needs colour at a
        few surface points need not copy a dense colour box (3 bytes a voxel) to read them."""
        self.sync_colors()
        g = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
        if len(self.pool_c) == 0 or len(g) == 0:
            return np.zeros((len(g), 3), dtype=np.uint8)
        blk, loc = g // kn.B, g % kn.B
        i = self.block_idx[blk[:, 0], blk[:, 1], blk[:, 2]]
        out = self.pool_c[np.maximum(i, 0), loc[:, 0] * kn.B * kn.B + loc[:, 1] * kn.B + loc[:, 2]]
        out[i < 0] = 0
        return out

    def tsdf(self, lo=None, hi=None) -> np.ndarray:
        """Dense v (float32 in [-1, 1]; 0 where unknown) over [lo, hi)."""
        return self.tsdf_weights(lo, hi)[0]

    def weights(self, lo=None, hi=None) -> np.ndarray:
        """Dense w (uint8, 0 = unknown) over [lo, hi)."""
        return self.tsdf_weights(lo, hi)[1]

    def voxel_centers(self, idx: np.ndarray) -> np.ndarray:
        return self.origin + (np.asarray(idx, dtype=np.float64) + 0.5) * self.voxel_size

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World min and max corner of the grid."""
        return self.origin.copy(), self.origin + np.array(self.shape) * self.voxel_size

    def surface_blocks(self) -> np.ndarray:
        """bool (blocks) : blocks holding an occupied voxel, grown by one block (a surface between an occupied
        voxel and its empty neighbour can reach into the next block)."""
        occ = kn.occupied_blocks(self.block_idx, self.pool_v, self.pool_w)
        if not occ.any():
            return occ
        return binary_dilation(occ, structure=np.ones((3, 3, 3), bool)) & (self.block_idx >= 0)

    def surface_block_box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Voxel box [lo, hi) around the blocks where a surface can be (see surface_blocks), or None."""
        ib = np.argwhere(self.surface_blocks())
        if ib.size == 0:
            return None
        lo = ib.min(axis=0) * kn.B
        hi = np.minimum((ib.max(axis=0) + 1) * kn.B, self.shape)
        return lo, hi

    def raycast(self, K: np.ndarray, width: int, height: int, T_world_camera: np.ndarray,
                min_depth: float | None = None, max_depth: float | None = None, return_state: bool = False,
                stop_at_unknown: bool = False):
        """Ray cast the TSDF from a pose: (depth (H, W) float32 z in metres, 0 = no hit; normals (H, W, 3) world,
        NaN = none; vertices (H, W, 3) world, NaN = none). With return_state also an int8 (H, W) map:
        1 the ray hit an occupied surface, 0 it met unknown space, -1 it left the grid through empty space.
        stop_at_unknown (next-best view): rays also stop at the first unknown voxel, whose position is the
        vertex of those pixels (state 0), so each ray reports the first non-empty voxel and its state.
        """
        K = np.asarray(K, dtype=np.float64)
        T = check_rigid(T_world_camera)
        lo = self.min_depth if min_depth is None else float(min_depth)
        hi = self.max_depth if max_depth is None else float(max_depth)
        depth, normals, verts, state = kn.raycast_kernel(
            np.array(self.shape, dtype=np.int64), self.block_idx, self.block_w, self.pool_v, self.pool_w,
            self.origin, self.voxel_size, self.truncation, T, np.linalg.inv(K), int(width), int(height), lo, hi,
            bool(stop_at_unknown))
        if return_state:
            return depth, normals, verts, state
        return depth, normals, verts

    def extract_mesh(self, lo=None, hi=None):
        """Coloured open3d TriangleMesh of the v = 0 surface (marching cubes, skimage) between known voxels,
        optionally only inside the voxel box [lo, hi)."""
        return extract_mesh(self, lo, hi)

    def counts(self) -> dict[str, int]:
        return self.ternary_grid().counts()

    # ------------------------------------------------------------------ persistence
    def meta(self) -> dict:
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "shape": list(self.shape),
                "voxel_size": self.voxel_size, "origin": self.origin.tolist(), "truncation": self.truncation,
                "max_weight": self.max_weight, "min_depth": self.min_depth, "max_depth": self.max_depth,
                "color": self.color, "color_mode": self.color_mode, "block": kn.B,
                "frames_integrated": self.frames_integrated,
                **({"color_hypotheses": self.mode_hypotheses, "color_threshold": self.mode_threshold}
                   if self.color_mode == "mode" else {}),
                "frame": self.frame, "up": None if self.up is None else self.up.tolist(),
                "up_source": self.up_source, "intrinsics": self.intrinsics}

    def save(self, path: str | os.PathLike) -> Path:
        """Write one .npz (metadata, block tables, used pool rows) atomically; `load_volume` reads it back."""
        self._check_hypotheses()
        n = self.n_used
        self.sync_colors()
        arrays = {"block_idx": self.block_idx, "block_w": self.block_w, "pool_v": self.pool_v[:n],
                  "pool_w": self.pool_w[:n], "pool_c": self.pool_c[:n] if self.color else self.pool_c[:0]}
        if self.color_mode == "mode":  # the hypotheses too, so that fusion can go on (init)
            arrays.update(pool_hc=self.pool_hc[:n], pool_hn=self.pool_hn[:n])
        return write_volume_file(path, self.meta(), arrays)

    def _check_hypotheses(self) -> None:
        if not self.hypotheses_loaded:
            raise VolumeError("this colour-mode volume was read without its colour hypotheses "
                              "(load_volume(hypotheses=False)): it cannot be fused into or saved")

    def copy(self) -> "TernaryVolume":
        other = TernaryVolume.__new__(TernaryVolume)
        other.__dict__.update({k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()})
        other._raylen_cache = {}
        other._guided_buffers = None  # work arrays: each volume its own
        return other

    def __repr__(self) -> str:
        nx, ny, nz = self.shape
        return (f"TernaryVolume({nx}x{ny}x{nz}, voxel {self.voxel_size * 1000:.2f} mm, origin "
                f"{np.round(self.origin, 3).tolist()}, {self.n_used} blocks stored)")


def load_volume(path: str | os.PathLike, hypotheses: bool = True) -> TernaryVolume:
    """Read a volume written by TernaryVolume.save; VolumeError for missing, foreign or other-version files.

    The pools are the arrays np.load returns (no copy: `_ensure_capacity` grows them when fusion goes on).
    hypotheses=False leaves a colour-mode volume's hypotheses unread (pool_c holds their winners, written by
    save): for readers of the colours only, such as segmentation; such a volume refuses integrate and save."""
    path = Path(path)
    meta, arrays = read_volume_file(path, optional=hypotheses)
    if meta.get("block", kn.B) != kn.B:  # the pools' rows are blocks of B^3 voxels: another B reads as garbage
        raise VolumeError(f"{path}: volume stored in blocks of {meta['block']!r} voxels a side; this kinfu reads "
                          f"blocks of {kn.B}")
    try:
        vol = TernaryVolume(size=[s * meta["voxel_size"] for s in meta["shape"]], voxel_size=meta["voxel_size"],
                            origin=meta["origin"], truncation=meta["truncation"], max_weight=meta["max_weight"],
                            min_depth=meta["min_depth"], max_depth=meta["max_depth"], color=meta["color"],
                            color_mode=meta.get("color_mode", "mean"), _allocate=False)
    except (ConfigError, VolumeError) as exc:  # the file's grid, not options: name the file (a memory check, ...)
        raise VolumeError(f"{path}: {exc.detail}") from None
    if vol.color_mode == "mode":
        vol.mode_hypotheses = int(meta.get("color_hypotheses", MAX_HYPOTHESES))
        vol.mode_threshold = float(meta.get("color_threshold", MODE_THRESHOLD))
    if tuple(vol.shape) != tuple(meta["shape"]) or arrays["block_idx"].shape != tuple(vol.nb):
        raise VolumeError(f"{path}: inconsistent volume file (shape {meta['shape']}, blocks "
                          f"{arrays['block_idx'].shape})")
    vol.block_idx = np.ascontiguousarray(arrays["block_idx"], dtype=np.int32)
    vol.block_w = np.ascontiguousarray(arrays["block_w"], dtype=np.uint8)
    n = int(arrays["pool_v"].shape[0])
    vol.n_used = n
    vol._alloc_pools(0)
    vol.pool_v = np.ascontiguousarray(arrays["pool_v"], dtype=np.int16)
    vol.pool_w = np.ascontiguousarray(arrays["pool_w"], dtype=np.uint8)
    if vol.color:
        if arrays["pool_c"].shape[0] != n:
            raise VolumeError(f"{path}: inconsistent colour pool ({arrays['pool_c'].shape[0]} rows, expected {n})")
        vol.pool_c = np.ascontiguousarray(arrays["pool_c"], dtype=np.uint8)
    if vol.color_mode == "mode" and hypotheses:
        hc, hn = arrays.get("pool_hc"), arrays.get("pool_hn")
        if (hc is None or hn is None or hc.shape != (n,) + vol.pool_hc.shape[1:]
                or hn.shape != (n,) + vol.pool_hn.shape[1:]):
            raise VolumeError(f"{path}: colour mode volume without matching hypothesis pools (pool_hc, pool_hn "
                              f"of {n} rows, {vol.mode_hypotheses} hypotheses per voxel)")
        vol.pool_hc = np.ascontiguousarray(hc, dtype=np.uint8)
        vol.pool_hn = np.ascontiguousarray(hn, dtype=np.uint8)
    vol.hypotheses_loaded = hypotheses or vol.color_mode != "mode"
    vol.frames_integrated = int(meta.get("frames_integrated", 0))
    vol.frame = str(meta.get("frame", "") or "")
    try:  # volumes written before the up direction and the intrinsics were recorded have neither
        vol.up = None if meta.get("up") is None else check_up(meta["up"])
    except ConfigError:
        raise VolumeError(f"{path}: meta 'up' is not a finite direction: {meta.get('up')!r}") from None
    vol.up_source = str(meta.get("up_source", "") or "") if vol.up is not None else ""
    vol.intrinsics = check_intrinsics(meta.get("intrinsics"), path)
    return vol


def volume_intrinsics(path: str | os.PathLike) -> dict | None:
    """The depth intrinsics (fx, fy, cx, cy, width, height) a fusion volume.npz or ternary.npz was fused with;
    None for files written before they were recorded."""
    meta = read_volume_meta(path)
    if meta is None:
        grid = read_ternary(path)
        if grid is None:  # a readable .npz of something else (nbv read it as a ternary: AttributeError)
            raise VolumeError(f"{path}: not a kinfu volume.npz or ternary.npz (neither a 'meta' nor a 'ternary' "
                              f"array)")
        return grid.intrinsics
    return check_intrinsics(meta.get("intrinsics"), path)


def load_grid(path: str | os.PathLike) -> TernaryGrid:
    """The ternary grid of a `ternary.npz` or of a fusion `volume.npz`."""
    grid = read_ternary(path)
    return grid if grid is not None else load_volume(path).ternary_grid()
