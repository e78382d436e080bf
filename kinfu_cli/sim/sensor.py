"""A Kinect-like RGB-D sensor rendered with open3d's RaycastingScene.

Depth is the z coordinate in the camera optical frame (x right, y down, z forward), float32 metres, 0 = invalid.
With `noise=True` the depth follows the Kinect v1 model of Nguyen, Izadi and Lovell (3DIMPVT 2012):

- axial noise, Gaussian with sigma_z(z, theta) = 0.0012 + 0.0019 (z - 0.4)^2 + 0.0001 / sqrt(z) * theta^2 /
  (pi/2 - theta)^2 metres (theta = angle between the ray and the surface normal);
- lateral noise: the ray through each pixel is jittered by `lateral_px` pixels (sigma), so edges are ragged;
- projector shadows: the IR projector sits `baseline` metres beside the camera (+x); a surface point the projector
  cannot see (occluded on the projector ray) has no depth — the dropouts on one side of every object;
- edge dropouts: pixels next to a depth discontinuity are lost with probability `edge_dropout`;
- grazing surfaces (theta > `max_incidence_deg`) are lost, plus iid random missing pixels (`missing_rate`);
- disparity quantisation: the Kinect v1 measures disparity in 1/8 pixel steps of its 585 px IR camera, so depth
  comes in steps of z^2 / (8 * 585 * baseline) (about 4 mm at 1.2 m, Khoshelham & Elberink 2012); the Gaussian part is
  reduced so that noise + quantisation together keep the sigma_z above;
- out of [min_range, max_range] is 0; depth is quantised to millimetres (what 16UC1 stores).

Colour is the albedo of what each pixel sees (per object colour; wood stripes on the table, a checker on the floor)
with Lambert shading from a fixed light above the table, an ambient term and a little Gaussian pixel noise; the
colour camera is registered to the depth camera (same intrinsics and pose, as the Kinect's registered mode).
With `noise=False` depth is exact (float32 ray casting, no quantisation) and colour has no pixel noise.

Photometric nonidealities, off by default (existing sequences do not change; thesis ch. 4 blames the Kinect v2's
auto-gain and misregistration for colour blur): `gain_jitter` (sigma of the log of a per-frame global gain, as
auto-exposure changes it from frame to frame), `white_balance_jitter` (sigma of the log of a per-frame, per-channel
gain) and `misregistration` (du, dv pixels, rotation degrees about the image centre: colour pixel (u, v) sees what
the depth camera sees at that offset: a calibration error, the same in every frame); `misregistration_jitter` adds
a per-frame shift (sigma in pixels per axis), as unsynchronised colour and depth streams of a moving camera give.
They draw from their own generators, so turning them on leaves the depth noise as it was.

Material dropouts, off by default: `dark_dropout` (fraction of the pixels of dark albedo (luma < `dark_luma`)
lost, in blobs of about `dropout_blob_px` pixels) and `glossy_deg` (specular spot / band of glossy objects), see `sim.materials`: the
missing-depth bands real RealSense views show on black plastic and glossy print (issue 12).

Ray casting is open3d C++, the noise model vectorised numpy, shading a numba kernel.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import open3d as o3d
from numba import njit, prange

from kinfu_cli.core.camera import SENSOR_PRESETS, preset_intrinsics
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.poses import check_poses
from kinfu_cli.sim.materials import DARK_LUMA, material_dropout
from kinfu_cli.sim.scene import LABEL_NONE, RaycastTarget, Scene

# numba probes the TBB threading layer at the first parallel call and warns when the installed TBB is too old;
# it then falls back to OpenMP/workqueue, which is what we want: keep the CLI's stderr clean.
warnings.filterwarnings("ignore", message="The TBB threading layer requires TBB version")

LIGHT_DIR = np.array([0.3, -0.4, 1.0]) / np.linalg.norm([0.3, -0.4, 1.0])  # towards the light, world frame
BACKGROUND_RGB = np.array([0.08, 0.08, 0.09])
PHOTO_STREAM = 0x9A1  # seeds the photometric effects' own generator (with the sensor seed and frame seed)
SHIFT_STREAM = 0x9A2  # seeds the per-frame misregistration shifts (their own, so the gains stay as they were)
MATERIAL_STREAM = 0x9A3  # seeds the dark-material blobs (sim.materials)


def kinect_v1_intrinsics(width: int = 640, height: int = 480) -> np.ndarray:
    """The simulated sensor's intrinsics: the raw Kinect v1 IR camera (preset "kinect_v1_ir", fx = fy = 585 at
    640x480) scaled to width x height, principal point at the centre."""
    return preset_intrinsics("kinect_v1_ir", width, height)


def pixel_directions(K: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Camera-frame directions (..., 3) of the rays through image points (u, v) (float pixels, 0 = the first
    pixel's centre), scaled to camera z = 1 so that a hit's distance along the ray is its depth."""
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)


def world_rays(d_cam: np.ndarray, T_world_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """open3d rays (..., 6) float32 (camera centre, world direction) for camera-frame directions, and the world
    directions in float64."""
    d_world = d_cam @ T_world_camera[:3, :3].T
    rays = np.empty(d_world.shape[:-1] + (6,), dtype=np.float32)
    rays[..., :3] = T_world_camera[:3, 3]
    rays[..., 3:] = d_world
    return rays, d_world


def ideal_depth(scene: o3d.t.geometry.RaycastingScene, K: np.ndarray, width: int, height: int,
                T_world_camera: np.ndarray) -> np.ndarray:
    """Noise-free optical-axis depth (H, W) float32 of a RaycastingScene through the pixel centres, inf where
    the ray hits nothing and no range limits: the exact image a z-buffer test compares with."""
    v, u = np.mgrid[0:height, 0:width]
    rays, _ = world_rays(pixel_directions(np.asarray(K, dtype=np.float64), u.astype(np.float64),
                                          v.astype(np.float64)), np.asarray(T_world_camera, dtype=np.float64))
    return scene.cast_rays(o3d.core.Tensor.from_numpy(rays))["t_hit"].numpy()


def nguyen_axial_sigma(z: np.ndarray, theta: np.ndarray | float = 0.0) -> np.ndarray:
    """Kinect v1 axial depth noise sigma (metres) at depth z (m) and incidence angle theta (rad), Nguyen et al. 2012."""
    z = np.asarray(z, dtype=np.float64)
    theta = np.minimum(np.asarray(theta, dtype=np.float64), np.deg2rad(85.0))
    return 0.0012 + 0.0019 * (z - 0.4) ** 2 + 0.0001 / np.sqrt(np.maximum(z, 1e-6)) * theta ** 2 / (np.pi / 2 - theta) ** 2


@dataclass
class SensorFrame:
    """Everything one render produces. depth/true_depth float32 (H,W) m, 0 = invalid; color uint8 (H,W,3) RGB;
    labels int32 (H,W): 0 nothing, 1 floor, 2 table, 3+i object i of the scene (see scene.label_of)."""

    depth: np.ndarray
    color: np.ndarray
    labels: np.ndarray
    true_depth: np.ndarray


class DepthSensor:
    """A pinhole RGB-D camera with a Kinect v1 noise model (see the module docstring).

    K: 3x3 intrinsics; width, height: pixels; min_range, max_range: metres; noise: apply the noise model;
    seed: seed of the noise (renders draw from one generator in sequence unless `frame_seed` is given).
    """

    def __init__(self, K: np.ndarray, width: int, height: int, min_range: float = 0.3, max_range: float = 4.0,
                 noise: bool = True, seed: int = 0, *, baseline: float = 0.075, lateral_px: float = 0.5,
                 edge_dropout: float = 0.5, missing_rate: float = 0.005, max_incidence_deg: float = 80.0,
                 edge_jump: float = 0.03, color_noise: float = 2.0 / 255.0,
                 disparity_quantisation: bool = True, ir_focal: float = SENSOR_PRESETS["kinect_v1_ir"]["fx"],
                 subpixel: int = 8, gain_jitter: float = 0.0, white_balance_jitter: float = 0.0,
                 misregistration: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 misregistration_jitter: float = 0.0, dark_dropout: float = 0.0, glossy_deg: float = 0.0,
                 dropout_blob_px: float = 4.0, dark_luma: float = DARK_LUMA) -> None:
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ConfigError(f"camera intrinsics: expected a 3x3 matrix with positive focal lengths, got {K.tolist()}")
        if int(width) < 1 or int(height) < 1:
            raise ConfigError(f"image size {width}x{height}: expected positive width and height")
        if not 0 <= min_range < max_range:
            raise ConfigError(f"sensor range [{min_range}, {max_range}]: expected 0 <= min_range < max_range")
        self.K = K
        self.width, self.height = int(width), int(height)
        self.min_range, self.max_range = float(min_range), float(max_range)
        self.noise = bool(noise)
        self.seed = int(seed)
        self.baseline = float(baseline)
        self.lateral_px = float(lateral_px)
        self.edge_dropout = float(edge_dropout)
        self.missing_rate = float(missing_rate)
        self.max_incidence = np.deg2rad(float(max_incidence_deg))
        self.edge_jump = float(edge_jump)
        self.color_noise = float(color_noise)
        self.disparity_quantisation = bool(disparity_quantisation)
        self.bf = float(baseline) * float(ir_focal) * int(subpixel)  # depth = bf / (disparity in subpixel steps)
        self.gain_jitter = float(gain_jitter)
        self.white_balance_jitter = float(white_balance_jitter)
        mis = tuple(float(x) for x in misregistration)
        self.misregistration_jitter = float(misregistration_jitter)
        if (len(mis) != 3 or not all(np.isfinite(mis)) or not (0 <= self.gain_jitter < 1)
                or not (0 <= self.white_balance_jitter < 1) or not (0 <= self.misregistration_jitter <= 100)):
            raise ConfigError(f"photometric effects: expected gain and white balance jitters in [0, 1), a "
                              f"misregistration (du, dv, degrees) of finite numbers and its jitter in [0, 100] px, "
                              f"got {self.gain_jitter}, {self.white_balance_jitter}, {misregistration}, "
                              f"{misregistration_jitter}")
        self.misregistration = mis
        self.dark_dropout, self.glossy_deg = float(dark_dropout), float(glossy_deg)
        self.dropout_blob_px, self.dark_luma = float(dropout_blob_px), float(dark_luma)
        if not (0 <= self.dark_dropout <= 1 and 0 <= self.glossy_deg < 90 and 0 <= self.dropout_blob_px <= 100
                and 0 <= self.dark_luma <= 1):
            raise ConfigError(f"material dropouts: expected dark_dropout in [0, 1], glossy_deg in [0, 90), "
                              f"dropout_blob_px in [0, 100] and dark_luma in [0, 1], got {dark_dropout}, {glossy_deg}, "
                              f"{dropout_blob_px}, {dark_luma}")
        self._rng = np.random.default_rng(self.seed)
        self._photo_rng = np.random.default_rng([self.seed, PHOTO_STREAM])
        self._shift_rng = np.random.default_rng([self.seed, SHIFT_STREAM])
        self._material_rng = np.random.default_rng([self.seed, MATERIAL_STREAM])
        v, u = np.mgrid[0:self.height, 0:self.width]
        self._u = u.astype(np.float64)
        self._v = v.astype(np.float64)
        self._color_uv = self._misregistered_pixels() if any(mis) else None
        self._cache: tuple[int, RaycastTarget] | None = None
        self._dcam = pixel_directions(self.K, self._u, self._v)

    # ---- public -------------------------------------------------------------------------------------
    def render(self, scene_or_mesh, T_world_camera: np.ndarray, frame_seed: int | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """Depth float32 (H,W) metres (0 = invalid) and colour uint8 (H,W,3) RGB seen from T_world_camera (4x4)."""
        f = self.render_frame(scene_or_mesh, T_world_camera, frame_seed)
        return f.depth, f.color

    def render_frame(self, scene_or_mesh, T_world_camera: np.ndarray, frame_seed: int | None = None) -> SensorFrame:
        """Like render() but also returns the label image and the noise-free depth.

        scene_or_mesh: a Scene, a RaycastTarget, or an open3d TriangleMesh (legacy or tensor; vertex colours are used
        when present). frame_seed: when given, the noise of this frame depends only on (seed, frame_seed).
        """
        T = check_poses(T_world_camera, "camera pose")[0]
        target = self._target(scene_or_mesh)
        rng = np.random.default_rng([self.seed, int(frame_seed)]) if frame_seed is not None else self._rng
        H, W = self.height, self.width

        # noise-free cast through the pixel centres (colour, labels, true depth)
        hit = self._cast(target, T)
        true_depth = np.where(hit["valid"], hit["t"], 0.0)
        labels = np.where(hit["valid"], target.labels[np.minimum(hit["gid"], len(target.labels) - 1)], LABEL_NONE)
        color_uv = self._frame_color_pixels(frame_seed)
        color = self._shade(target, hit if color_uv is None else self._cast(target, T, *color_uv), rng,
                            self._photometric_gain(frame_seed))
        in_range = (true_depth >= self.min_range) & (true_depth <= self.max_range)

        if not self.noise:
            depth = np.where(in_range, true_depth, 0.0).astype(np.float32)
            return SensorFrame(depth, color, labels.astype(np.int32), np.where(in_range, true_depth, 0.0).astype(np.float32))

        # lateral noise: cast again through jittered pixel positions
        if self.lateral_px > 0:
            du = rng.normal(0.0, self.lateral_px, (H, W))
            dv = rng.normal(0.0, self.lateral_px, (H, W))
            nh = self._cast(target, T, self._u + du, self._v + dv)
        else:
            nh = hit
        z = np.where(nh["valid"], nh["t"], 0.0)
        ok = nh["valid"] & (z > 0)

        # incidence angle between the viewing ray and the surface normal
        theta = self._theta(nh)
        ok &= theta <= self.max_incidence

        # projector shadow: the projector at +baseline along camera x must see the point
        if self.baseline > 0 and np.any(ok):
            proj = T[:3, :3] @ np.array([self.baseline, 0.0, 0.0]) + T[:3, 3]
            pts = self._points(nh, ok)
            d = pts - proj
            rays = np.concatenate([np.broadcast_to(proj, d.shape), d], axis=1).astype(np.float32)
            occluded = target.scene.test_occlusions(o3d.core.Tensor(rays), tnear=0.0, tfar=0.995).numpy()
            idx = np.flatnonzero(ok.ravel())
            ok.ravel()[idx[occluded]] = False
        if self.dark_dropout > 0 or self.glossy_deg > 0:
            ok &= ~self._material_dropout(target, nh, T, frame_seed)

        # axial noise (+ disparity quantisation, which accounts for part of the model's variance)
        sigma = nguyen_axial_sigma(z, theta)
        if self.disparity_quantisation and self.bf > 0:
            step = z ** 2 / self.bf
            sigma = np.sqrt(np.maximum(sigma ** 2 - step ** 2 / 12.0, 0.0))
        z = z + rng.normal(0.0, 1.0, z.shape) * sigma
        if self.disparity_quantisation and self.bf > 0:
            disp = np.maximum(np.round(self.bf / np.maximum(z, 1e-3)), 1.0)
            z = np.where(ok, self.bf / disp, 0.0)

        # edge dropouts next to depth discontinuities (of the noise-free image)
        if self.edge_dropout > 0:
            edge = _discontinuities(true_depth, self.edge_jump)
            ok &= ~(edge & (rng.random(edge.shape) < self.edge_dropout))
        if self.missing_rate > 0:
            ok &= rng.random(z.shape) >= self.missing_rate
        ok &= (z >= self.min_range) & (z <= self.max_range)
        depth = np.where(ok, np.round(z * 1000.0) / 1000.0, 0.0).astype(np.float32)
        return SensorFrame(depth, color, labels.astype(np.int32),
                           np.where(in_range, true_depth, 0.0).astype(np.float32))

    # ---- internals ----------------------------------------------------------------------------------
    def _target(self, scene_or_mesh) -> RaycastTarget:
        if isinstance(scene_or_mesh, RaycastTarget):
            return scene_or_mesh
        if self._cache is not None and self._cache[0] is scene_or_mesh:
            return self._cache[1]
        if isinstance(scene_or_mesh, Scene):
            target = scene_or_mesh.raycasting_scene()
        elif isinstance(scene_or_mesh, (o3d.geometry.TriangleMesh, o3d.t.geometry.TriangleMesh)):
            target = mesh_target(scene_or_mesh)
        else:
            raise ConfigError(f"cannot render a {type(scene_or_mesh).__name__}: expected a Scene or a TriangleMesh")
        self._cache = (scene_or_mesh, target)  # keeps a reference, so the id cannot be reused
        return target

    def _cast(self, target: RaycastTarget, T: np.ndarray, u: np.ndarray | None = None,
              v: np.ndarray | None = None) -> dict:
        """Cast one ray per pixel (through pixel centres, or through (u, v) when given).

        Returns t (H,W) float64 optical-axis depth (0 = no hit), valid, gid, normals (H,W,3) float32,
        dir (H,W,3) float64 world ray directions with camera-z component 1, prim, uv.
        """
        d_cam = self._dcam if u is None else pixel_directions(self.K, u, v)
        rays, d_world = world_rays(d_cam, T)
        ans = target.scene.cast_rays(o3d.core.Tensor.from_numpy(rays))
        t = ans["t_hit"].numpy()
        gid = ans["geometry_ids"].numpy()
        valid = np.isfinite(t) & (gid != o3d.t.geometry.RaycastingScene.INVALID_ID)
        return {"t": np.where(valid, t, 0.0).astype(np.float64), "gid": np.where(valid, gid, 0).astype(np.int64),
                "valid": valid, "normals": ans["primitive_normals"].numpy(), "dir": d_world,
                "prim": ans["primitive_ids"].numpy(), "uv": ans["primitive_uvs"].numpy(), "origin": T[:3, 3]}

    def _material_dropout(self, target: RaycastTarget, hit: dict, T: np.ndarray, frame_seed: int | None
                          ) -> np.ndarray:
        """Pixels lost to dark or glossy materials (sim.materials), from their own generator."""
        rng = (np.random.default_rng([self.seed, MATERIAL_STREAM, int(frame_seed)]) if frame_seed is not None
               else self._material_rng)
        proj = T[:3, :3] @ np.array([self.baseline, 0.0, 0.0]) + T[:3, 3]
        return material_dropout(hit, target.albedo, target.labels, proj, self.dark_dropout, self.glossy_deg,
                                self.dropout_blob_px, rng, self.dark_luma)

    @staticmethod
    def _theta(hit: dict) -> np.ndarray:
        """Angle (rad) between each pixel's ray and the surface normal it hit (0 where nothing was hit)."""
        d = hit["dir"]
        cos = np.abs(np.einsum("hwc,hwc->hw", hit["normals"].astype(np.float64), d)) / np.linalg.norm(d, axis=-1)
        return np.where(hit["valid"], np.arccos(np.clip(cos, 0.0, 1.0)), 0.0)

    @staticmethod
    def _points(hit: dict, mask: np.ndarray) -> np.ndarray:
        """World points (n, 3) hit by the pixels in mask."""
        return hit["origin"] + hit["dir"][mask] * hit["t"][mask][:, None]

    def _misregistered_pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """Depth-image positions (u, v) the colour pixels look through: rotated about the image centre by the
        misregistration's angle, then shifted by its (du, dv)."""
        du, dv, deg = self.misregistration
        a = np.deg2rad(deg)
        cu, cv = (self.width - 1) / 2.0, (self.height - 1) / 2.0
        x, y = self._u - cu, self._v - cv
        return (cu + du + np.cos(a) * x - np.sin(a) * y, cv + dv + np.sin(a) * x + np.cos(a) * y)

    def _frame_color_pixels(self, frame_seed: int | None) -> tuple[np.ndarray, np.ndarray] | None:
        """Depth-image positions the colour pixels of this frame look through: the fixed misregistration plus
        this frame's shift (misregistration_jitter); None when the colour is registered."""
        if self.misregistration_jitter <= 0:
            return self._color_uv
        rng = (np.random.default_rng([self.seed, SHIFT_STREAM, int(frame_seed)]) if frame_seed is not None
               else self._shift_rng)
        du, dv = rng.normal(0.0, self.misregistration_jitter, 2)
        u, v = self._color_uv if self._color_uv is not None else (self._u, self._v)
        return u + du, v + dv

    def _photometric_gain(self, frame_seed: int | None) -> np.ndarray | None:
        """Per-channel gain (3,) of this frame's auto-exposure and white balance; None when both are off."""
        if self.gain_jitter <= 0 and self.white_balance_jitter <= 0:
            return None
        rng = (np.random.default_rng([self.seed, PHOTO_STREAM, int(frame_seed)]) if frame_seed is not None
               else self._photo_rng)
        log_gain = rng.normal(0.0, self.gain_jitter) + rng.normal(0.0, self.white_balance_jitter, 3)
        return np.exp(log_gain).astype(np.float32)

    def _shade(self, target: RaycastTarget, hit: dict, rng: np.random.Generator,
               gain: np.ndarray | None = None) -> np.ndarray:
        rgb = _shade_kernel(hit["valid"], hit["gid"], hit["t"], hit["dir"], hit["normals"],
                            np.ascontiguousarray(hit["origin"], dtype=np.float64), target.albedo.astype(np.float32),
                            target.textured.astype(np.int32), LIGHT_DIR.astype(np.float32),
                            BACKGROUND_RGB.astype(np.float32))
        if target.vertex_colours:  # plain mesh with vertex colours: barycentric interpolation (x Lambert term)
            vc = hit["valid"] & (target.textured[hit["gid"]] == 3)
            if np.any(vc):
                vcol, tris = target.vertex_colours[0]
                prim = hit["prim"][vc].astype(np.int64)
                uv = hit["uv"][vc].astype(np.float64)
                w = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
                albedo = np.einsum("nk,nkc->nc", w, vcol[tris[prim]])
                rgb[vc] *= (albedo / target.albedo[0]).astype(np.float32)
        if gain is not None:
            rgb *= gain
        if self.noise and self.color_noise > 0:
            rgb += rng.standard_normal(rgb.shape, dtype=np.float32) * np.float32(self.color_noise)
        return np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)


@njit(cache=True, parallel=True)
def _shade_kernel(valid, gid, t, dirs, normals, origin, albedo_tab, tex_tab, light, background):  # pragma: no cover
    """Albedo (with the table's wood stripes / the floor's checker / a wallpaper) x (ambient + Lambert), float32 RGB
    (H, W, 3)."""
    H, W = valid.shape
    out = np.empty((H, W, 3), dtype=np.float32)
    for r in prange(H):
        for c in range(W):
            if not valid[r, c]:
                for k in range(3):
                    out[r, c, k] = background[k]
                continue
            g = gid[r, c]
            scale = 1.0
            tex = tex_tab[g]
            if tex == 1 or tex == 2 or tex == 4:
                px = origin[0] + dirs[r, c, 0] * t[r, c]
                py = origin[1] + dirs[r, c, 1] * t[r, c]
                if tex == 1:
                    scale = 0.88 + 0.12 * np.sin(px * 45.0 + 3.0 * np.sin(py * 7.0))
                elif tex == 2:
                    scale = 0.8 + 0.2 * ((np.floor(px / 0.5) + np.floor(py / 0.5)) % 2)
                else:  # wallpaper: smooth blotches ~15 cm across, varying along all three axes
                    pz = origin[2] + dirs[r, c, 2] * t[r, c]
                    scale = 0.75 + 0.25 * (np.sin(px * 6.1 + 2.3 * np.sin(py * 4.7 + pz * 3.1))
                                           * np.sin(py * 5.3 + pz * 7.9 + 1.7 * np.sin(px * 3.7)))
            nd = normals[r, c, 0] * dirs[r, c, 0] + normals[r, c, 1] * dirs[r, c, 1] + normals[r, c, 2] * dirs[r, c, 2]
            nl = normals[r, c, 0] * light[0] + normals[r, c, 1] * light[1] + normals[r, c, 2] * light[2]
            if nd > 0:  # the normal must face the camera
                nl = -nl
            lam = min(max(nl, 0.0), 1.0)
            shade = scale * (0.35 + 0.65 * lam)
            for k in range(3):
                out[r, c, k] = albedo_tab[g, k] * shade
    return out


def mesh_target(mesh) -> RaycastTarget:
    """A RaycastTarget for any open3d mesh: label 3 everywhere, vertex colours if it has them, else light grey."""
    legacy = mesh.to_legacy() if isinstance(mesh, o3d.t.geometry.TriangleMesh) else mesh
    if len(legacy.triangles) == 0:
        raise ConfigError("cannot render an empty mesh (no triangles)")
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(legacy))
    vcols = []
    tex = 0
    if legacy.has_vertex_colors():
        vcols = [(np.asarray(legacy.vertex_colors, dtype=np.float64), np.asarray(legacy.triangles, dtype=np.int64))]
        tex = 3
    return RaycastTarget(rc, np.array([3], np.int32), np.array([[0.7, 0.7, 0.7]]), np.array([tex], np.int32), vcols)


def _discontinuities(depth: np.ndarray, jump: float) -> np.ndarray:
    """Pixels with a 4-neighbour whose depth differs by more than jump * depth (or one side has no depth)."""
    d = depth
    edge = np.zeros(d.shape, dtype=bool)
    for a, b, sa, sb in ((d[:, 1:], d[:, :-1], (slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                         (d[1:, :], d[:-1, :], (slice(1, None), slice(None)), (slice(None, -1), slice(None)))):
        zmax = np.maximum(a, b)
        e = (np.abs(a - b) > jump * zmax) & (zmax > 0)
        edge[sa] |= e
        edge[sb] |= e
    return edge
