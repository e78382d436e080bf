"""TernaryVolume on exactly rendered synthetic frames: accuracy, ternary rule, clearing, persistence, errors."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.camera import preset_intrinsics
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.fusion.volume import TernaryVolume, load_grid, load_volume
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import box_scene
from kinfu_cli.sim.sensor import DepthSensor

W, H = 320, 240
VS = 0.006


@pytest.fixture(scope="module")
def scene():
    return box_scene()


@pytest.fixture(scope="module")
def frames(scene):
    K = preset_intrinsics("kinect_v1", W, H)
    sensor = DepthSensor(K, W, H, noise=False)  # exact depth
    poses = orbit_poses(10, radius=0.8, height=0.6, span_deg=360) + orbit_poses(4, radius=0.5, height=0.8,
                                                                                 start_deg=45, span_deg=360)
    return [(*sensor.render(scene, T), K, T) for T in poses]


def new_volume(**kw):
    args = dict(size=(0.96, 0.96, 0.384), voxel_size=VS, origin=(-0.48, -0.48, -0.06), min_depth=0.1,
                truncation=0.02)
    args.update(kw)
    return TernaryVolume(**args)


def fuse(vol, frames):
    for d, c, K, T in frames:
        vol.integrate(d, K, T, c)
    return vol


@pytest.fixture(scope="module")
def fused(frames):
    return fuse(new_volume(), frames)


def test_mesh_within_one_voxel_of_truth(fused, scene):
    mesh = fused.extract_mesh()
    v = np.asarray(mesh.vertices)
    assert len(v) > 5000
    assert mesh.has_vertex_colors()
    dist = np.abs(scene.sdf(v))
    assert dist.mean() <= VS, f"mean distance {dist.mean() * 1000:.2f} mm > 1 voxel"
    assert np.percentile(dist, 95) <= 2 * VS


def test_mesh_faces_face_empty_space(fused):
    """Triangle winding (right-hand normal) agrees with the vertex normals, which point into empty space."""
    mesh = fused.extract_mesh()
    v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    face_n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    vert_n = np.asarray(mesh.vertex_normals)[t].sum(axis=1)
    agree = np.einsum("ij,ij->i", face_n, vert_n) > 0
    assert agree.mean() > 0.98, f"only {agree.mean():.1%} of faces face empty space"
    up = np.abs(face_n[:, 2]) > 0.9 * np.linalg.norm(face_n, axis=1)  # table top and box lids face +z
    assert np.mean(face_n[up, 2] > 0) > 0.98


def test_object_measures_within_1cm(fused, scene):
    """Paper Table 1 measures for each box: height, and major/minor axes of the footprint (the minimum-area
    rectangle around the side vertices between 20 % and 80 % of the height, away from edge artefacts)."""
    import cv2

    v = np.asarray(fused.extract_mesh().vertices)
    for box in scene.objects:
        c = np.asarray(box.center[:2])
        rad = 0.5 * np.hypot(box.size[0], box.size[1]) + 0.01
        sel = v[(np.linalg.norm(v[:, :2] - c, axis=1) < rad) & (v[:, 2] > 0.01)]
        assert len(sel) > 100
        height = sel[:, 2].max()
        band = sel[(sel[:, 2] > 0.2 * height) & (sel[:, 2] < 0.8 * height)]
        _, (a, b), _ = cv2.minAreaRect(band[:, :2].astype(np.float32))
        assert abs(height - box.size[2]) < 0.01, (box, height)
        assert abs(max(a, b) - max(box.size[:2])) < 0.01, (box, a, b)
        assert abs(min(a, b) - min(box.size[:2])) < 0.01, (box, a, b)


def test_ternary_rule_free_space_surface_and_unknown_interior(fused, scene):
    grid = fused.ternary_grid()
    box = scene.objects[0]
    # interior of the big box, deeper than the truncation band: never observed -> unknown
    inner = grid.index_of(np.array([[box.center[0], box.center[1], box.size[2] / 2]]))[0]
    assert grid.labels[tuple(inner)] == 0
    # air above the boxes, seen from every view: empty
    air = grid.index_of(np.array([[0.0, -0.3, 0.3], [0.3, -0.3, 0.1]]))
    assert np.all(grid.labels[tuple(air.T)] == -1)
    # top face of the box: the voxel just below it is occupied
    top = grid.index_of(np.array([[box.center[0], box.center[1], box.size[2] - 0.5 * VS]]))[0]
    assert grid.labels[tuple(top)] == 1
    # below the table beyond the truncation band: unknown
    below = grid.index_of(np.array([[0.3, 0.3, -0.05]]))[0]
    assert grid.labels[tuple(below)] == 0
    counts = grid.counts()
    assert counts["occupied"] > 0 and counts["empty"] > 10 * counts["occupied"]
    # labels follow the rule on the dense v / w
    v, w = fused.tsdf_weights()
    lab = np.where(w == 0, 0, np.where(v <= 0, 1, -1))
    assert np.array_equal(lab, grid.labels)


def test_matches_open3d_uniform_tsdf_labels(frames):
    """Same frames, same grid: >= 99.5 % of the voxels get the same ternary label as open3d's volume."""
    import open3d as o3d

    res, size, trunc = 96, 0.96, 0.03
    origin = np.array([-0.48, -0.48, -0.2])
    ref = o3d.pipelines.integration.UniformTSDFVolume(
        length=size, resolution=res, sdf_trunc=trunc,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor, origin=origin.reshape(3, 1))
    ours = TernaryVolume(size=size, resolution=res, origin=origin, truncation=trunc, min_depth=0.0, color=False)
    for d, c, K, T in frames[:6]:
        intr = o3d.camera.PinholeCameraIntrinsic(W, H, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(c)), o3d.geometry.Image(d), depth_scale=1.0, depth_trunc=4.0,
            convert_rgb_to_intensity=False)
        ref.integrate(rgbd, intr, np.linalg.inv(T))
        ours.integrate(d, K, T)
    tw = np.asarray(ref.extract_volume_tsdf())
    lab_ref = np.where(tw[:, 1] == 0, 0, np.where(tw[:, 0] <= 0, 1, -1)).reshape(res, res, res)
    lab = ours.labels()
    observed = (lab != 0) | (lab_ref != 0)
    assert observed.mean() > 0.2
    assert (lab == lab_ref)[observed].mean() >= 0.995


def test_clear_sphere_then_reintegration_restores(frames, scene):
    vol = fuse(new_volume(), frames[:8])
    v0, w0 = vol.tsdf_weights()
    lab0 = vol.labels()
    center, r = np.array([0.0, 0.0, 0.1]), 0.12
    vol.clear_sphere(center, r)
    v1, w1 = vol.tsdf_weights()
    idx = np.indices(vol.shape).reshape(3, -1).T
    inside = (np.linalg.norm(vol.voxel_centers(idx) - center, axis=1) < r).reshape(vol.shape)
    assert np.all(w1[inside] == 0) and np.all(v1[inside] == 0)
    assert np.array_equal(w1[~inside], w0[~inside]) and np.array_equal(v1[~inside], v0[~inside])
    assert np.count_nonzero(lab0[inside] == 1) > 500
    fuse(vol, frames[8:])
    lab2 = vol.labels()
    # the surface inside the sphere is back: as many occupied voxels as a volume that never forgot
    ref = fuse(new_volume(), frames[8:]).labels()
    occ_back = np.count_nonzero(lab2[inside] == 1)
    assert occ_back >= 0.95 * np.count_nonzero(ref[inside] == 1)
    d = np.abs(scene.sdf(np.asarray(vol.extract_mesh(lo=np.argwhere(inside).min(0),
                                                     hi=np.argwhere(inside).max(0) + 1).vertices)))
    assert len(d) > 500 and d.mean() <= VS


def test_continue_fusing_equals_one_run(frames, tmp_path):
    a, b = frames[:5], frames[5:9]
    one = fuse(new_volume(), a + b)
    part = fuse(new_volume(), a)
    part.save(tmp_path / "volume.npz")
    cont = fuse(load_volume(tmp_path / "volume.npz"), b)
    for x, y in zip(one.tsdf_weights(color=True), cont.tsdf_weights(color=True)):
        assert np.array_equal(x, y)
    # load_grid reads the ternary grid of a volume.npz too
    grid = load_grid(tmp_path / "volume.npz")
    assert np.array_equal(grid.labels, part.labels())
    assert np.allclose(grid.origin, part.origin) and grid.voxel_size == part.voxel_size


def test_raycast_reproduces_rendered_depth(fused, frames):
    d, c, K, T = frames[3]
    depth, normals, verts = fused.raycast(K, W, H, T)
    # rendered points inside the grid (the table extends beyond it)
    from kinfu_cli.fusion.placement import backproject

    pts = backproject(d, K, T, stride=1).reshape(-1, 3)
    lo, hi = fused.bounds()
    inside = np.zeros(d.shape, bool)
    inside[d > 0] = np.all((pts > lo + 2 * VS) & (pts < hi - 2 * VS), axis=1)
    both = (depth > 0) & inside
    assert both.sum() > 0.97 * inside.sum()
    err = np.abs(depth[both] - d[both])
    assert np.median(err) < VS / 2 and err.mean() < VS
    # table normals point up (into the empty space)
    table = both & (np.abs(verts[..., 2]) < 0.003) & np.isfinite(normals[..., 2])
    assert table.sum() > 100 and np.median(normals[..., 2][table]) > 0.95


@pytest.mark.parametrize("pose, msg", [
    (np.full((4, 4), np.nan), "not finite"),
    (np.diag([1.0, 2.0, 1.0, 1.0]), "not rigid"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), "not rigid"),
])
def test_bad_pose_is_refused(frames, pose, msg):
    vol = new_volume()
    d, c, K, _ = frames[0]
    with pytest.raises(VolumeError, match=msg):
        vol.integrate(d, K, pose, c)
    assert vol.n_blocks_allocated == 0


def test_bad_depth_and_intrinsics_are_refused(frames):
    vol = new_volume()
    d, c, K, T = frames[0]
    with pytest.raises(VolumeError, match="no valid pixels"):
        vol.integrate(np.zeros_like(d), K, T)
    with pytest.raises(VolumeError, match="does not match the intrinsics"):
        vol.integrate(d[:100, :100], K, T)
    with pytest.raises(VolumeError, match="3x3 intrinsics"):
        vol.integrate(d, np.eye(3) * np.nan, T)


def test_too_large_volume_refused_before_allocating():
    with pytest.raises(VolumeError, match=r"would need up to [0-9.]+ GB"):
        TernaryVolume(size=20.0, voxel_size=0.002)
    with pytest.raises(ConfigError):
        TernaryVolume(size=3.0, voxel_size=-1)


def _edited_copy(vol, path, meta_changes=None, **arrays_changes):
    """`vol` saved, then written again to `path` with some meta fields and arrays replaced (a foreign file)."""
    import json

    p = path.with_name("saved.npz")
    vol.save(p)
    with np.load(p) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"])) | (meta_changes or {})
    arrays.update(meta=np.array(json.dumps(meta)), **{k: f(arrays[k]) for k, f in arrays_changes.items()})
    np.savez(path, **arrays)
    return path


def test_volume_from_another_version_is_refused(fused, tmp_path):
    with pytest.raises(VolumeError, match="version 99"):
        load_volume(_edited_copy(fused, tmp_path / "old.npz", {"format_version": 99}))
    with pytest.raises(VolumeError, match="no such volume"):
        load_volume(tmp_path / "missing.npz")


def test_volume_with_other_blocks_is_refused(fused, tmp_path):
    """The pools hold blocks of B^3 voxels: a file written with another block edge (meta 'block') would be read
    as garbage, so it is refused naming the file, as pool rows of another length are."""
    with pytest.raises(VolumeError, match="b16.npz: volume stored in blocks of 16"):
        load_volume(_edited_copy(fused, tmp_path / "b16.npz", {"block": 16}))
    with pytest.raises(VolumeError, match="rows.npz: voxel pools are"):
        load_volume(_edited_copy(fused, tmp_path / "rows.npz", pool_v=lambda a: a[:, :64], pool_w=lambda a: a[:, :64]))


def test_raycast_stop_at_unknown_reports_first_non_empty_voxel(fused, frames):
    """NBV ray casting: every ray ends on occupied (1), on unknown (0, vertex at the unknown voxel), or leaves
    the grid through empty space (-1); the end voxel has exactly that label."""
    d, c, K, T = frames[3]
    depth, normals, verts, state = fused.raycast(K, W, H, T, return_state=True, stop_at_unknown=True)
    grid = fused.ternary_grid()
    assert (state == 0).sum() > 100 and (state == 1).sum() > 1000
    unk = np.argwhere(state == 0)
    idx = grid.index_of(verts[unk[:, 0], unk[:, 1]])
    ok = np.all((idx >= 0) & (idx < grid.shape), axis=1)
    assert ok.mean() > 0.99
    assert np.all(grid.labels[tuple(idx[ok].T)] == 0)
    # a surface hit with the unknown stop is the same hit as without it, where both hit
    depth2, _, _, state2 = fused.raycast(K, W, H, T, return_state=True)
    both = (state == 1) & (state2 == 1)
    assert both.sum() > 0.9 * (state == 1).sum()
    assert np.allclose(depth[both], depth2[both])


def projective_samples(pts, d, K, T, trunc):
    """Per world point, the projective TSDF sample of one depth frame (digest sec. 1.2), plain numpy float64:
    (ok: the point updates, u, r: its pixel, t: its truncated distance in [-1, 1])."""
    h, wd = d.shape
    Tcw = np.linalg.inv(T)
    pc = pts @ Tcw[:3, :3].T + Tcw[:3, 3]
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uf = pc[:, 0] * K[0, 0] / z + K[0, 2] + 0.5
        vf = pc[:, 1] * K[1, 1] / z + K[1, 2] + 0.5
    ok = (z > 0) & (uf >= 1e-4) & (uf < wd - 1e-4) & (vf >= 1e-4) & (vf < h - 1e-4)
    u = np.where(ok, uf, 0).astype(np.int64)
    r = np.where(ok, vf, 0).astype(np.int64)
    dd = d[r, u]
    raylen = np.sqrt(1 + ((u - K[0, 2]) / K[0, 0]) ** 2 + ((r - K[1, 2]) / K[1, 1]) ** 2)
    sdf = (dd - z) * raylen
    ok &= (dd > 0) & (sdf > -trunc)
    return ok, u, r, np.minimum(1.0, sdf / trunc)


def _dense_reference(shape, origin, vs, trunc, max_w, frames):
    """The projective update rule (digest §1.2 eqs. 2.1-2.3) on a dense grid in plain numpy, float64."""
    idx = np.indices(shape).reshape(3, -1).T
    pts = origin + (idx + 0.5) * vs
    v = np.zeros(len(pts))
    w = np.zeros(len(pts), dtype=np.int64)
    for d, K, T in frames:
        ok, _, _, t = projective_samples(pts, d, K, T, trunc)
        v[ok] = (v[ok] * w[ok] + t[ok]) / (w[ok] + 1)
        w[ok] = np.minimum(w[ok] + 1, max_w)
    return v.reshape(shape), w.reshape(shape)


def test_block_sparse_update_equals_dense_reference(frames):
    """The fast path (blocks skipped, carved in bulk, or updated by vectorised loops) gives the same v and w
    as the plain per-voxel rule, on frames with holes, image borders and a grid partly behind the camera."""
    rng = np.random.default_rng(3)
    holed = []
    for d, c, K, T in frames[:8]:
        d = d.copy()
        for _ in range(10):  # rectangular holes of no reading, as around depth edges and dark surfaces
            r, u = rng.integers(0, H - 20), rng.integers(0, W - 20)
            d[r:r + rng.integers(2, 20), u:u + rng.integers(2, 20)] = 0
        d[:, : W // 4][rng.random((H, W // 4)) < 0.02] = 0  # scattered invalid pixels on the left
        holed.append((d, K, T))
    # 101 x 93 x 45 voxels: not a multiple of the 8^3 block, so partial blocks at the far faces are covered
    shape, origin, trunc, max_w = (101, 93, 45), np.array([-0.7, -0.6, -0.1]), 0.02, 5
    vol = TernaryVolume(size=np.array(shape) * VS, voxel_size=VS, origin=origin, truncation=trunc,
                        max_weight=max_w, min_depth=0.0, color=False)
    stats = [vol.integrate(d, K, T) for d, K, T in holed]
    assert sum(s["blocks_carved"] for s in stats) > 100 and sum(s["blocks_voxelwise"] for s in stats) > 100
    v_ref, w_ref = _dense_reference(shape, origin, VS, trunc, max_w, holed)
    v, w = vol.tsdf_weights()
    assert vol.shape == shape
    assert (w_ref > 0).mean() > 0.3 and (w_ref == max_w).any()
    # float32 projection could put a voxel on the neighbouring pixel of a float64 one (none do here)
    same_w = w == w_ref
    assert same_w.mean() > 0.9999
    both = same_w & (w > 0)
    dv = np.abs(v[both] - v_ref[both])
    assert np.quantile(dv, 0.999) < 2e-4 and dv.mean() < 1e-5


def test_block_sparse_update_equals_dense_reference_in_open_space():
    """Large free space (a wall 1.6-2.0 m away, seen from two poses): whole super-blocks are carved in bulk."""
    K = preset_intrinsics("kinect_v1", W, H)
    v, u = np.mgrid[0:H, 0:W]
    wall = (1.6 + 0.4 * u / W + 0.1 * v / H).astype(np.float32)  # a slanted wall
    wall[100:130, 150:200] = 0  # a blob without readings
    T1 = np.eye(4)
    T2 = np.eye(4)
    T2[:3, :3] = np.array([[np.cos(0.1), 0, np.sin(0.1)], [0, 1, 0], [-np.sin(0.1), 0, np.cos(0.1)]])
    T2[:3, 3] = [0.05, 0.02, -0.03]
    frames = [(wall, K, T1), (wall, K, T2)]
    shape, origin, trunc, max_w = (150, 110, 190), np.array([-0.75, -0.55, 0.3]), 0.03, 128
    vol = TernaryVolume(size=np.array(shape) * 0.01, voxel_size=0.01, origin=origin, truncation=trunc,
                        max_weight=max_w, min_depth=0.0, color=False)
    stats = [vol.integrate(d, K, T) for d, K, T in frames]
    assert sum(s["blocks_carved"] for s in stats) > 2000
    v_ref, w_ref = _dense_reference(shape, origin, 0.01, trunc, max_w, frames)
    vv, ww = vol.tsdf_weights()
    assert (w_ref > 0).mean() > 0.3
    assert (ww == w_ref).mean() > 0.9999
    both = (ww == w_ref) & (ww > 0)
    assert np.abs(vv[both] - v_ref[both]).max() < 2e-4


def test_a_new_grid_that_cannot_hold_a_surface_is_refused():
    # a 3 m voxel in a 2 m box made a one-voxel grid that fused nothing; a band under half a voxel lost the surfaces
    # (0.03 m at 0.1 m voxels kept 2 occupied voxels of the sample's table scene)
    with pytest.raises(ConfigError) as err:
        TernaryVolume(size=2.0, voxel_size=3.0)
    assert err.value.parameter == "voxel_size" and "1x1x1 voxels" in str(err.value)
    with pytest.raises(ConfigError) as err:
        TernaryVolume(size=2.0, resolution=2)
    assert err.value.parameter == "size/resolution"
    with pytest.raises(ConfigError) as err:
        TernaryVolume(size=2.0, voxel_size=0.1, truncation=0.03)
    assert err.value.parameter == "truncation" and "0.05 m" in str(err.value)
    TernaryVolume(size=(0.4, 0.4, 0.16), voxel_size=0.04, truncation=0.03)  # 4 voxels, 0.75 voxel: the room tests'
    # none given: 3 cm, widened to 0.75 voxel on coarse grids (a 10 cm voxel kept 510 occupied voxels of the scene
    # above instead of 2)
    assert TernaryVolume(size=2.0, voxel_size=0.1, truncation=None).truncation == pytest.approx(0.075)
    assert TernaryVolume(size=2.0, voxel_size=0.02, truncation=None).truncation == 0.03
