"""A RealSense SDK recording (RealSense Viewer / librealsense .bag): topics under /device_0/, depth in the
sensor's Depth Units, colour from the colour camera beside the depth camera, placed through the streams' own
extrinsics (/device_0/sensor_<i>/<Stream>_<n>/tf/<reference>), not through /tf.

The bags are written here in the layout librealsense's "Realsense Record and Playback" document gives (no real
SDK bag was available): header frame_ids empty, static information (camera infos, options, extrinsics) at time
0, each stream's extrinsics mapping the reference stream's points into that stream's frame."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinfu_cli.io.writers import RecordingWriter
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

S = 1_000_000_000
WD, HD = 160, 120  # depth camera
WC, HC = 200, 150  # colour camera: its own size and focal length
K_COLOR = np.array([[185.0, 0, 99.0], [0, 185.0, 76.0], [0, 0, 1]])
T_DEPTH_COLOR = np.eye(4)  # the colour optical frame in the depth optical frame: 15 mm to the side, turned 1 deg
T_DEPTH_COLOR[:3, :3] = Rotation.from_euler("y", 1.0, degrees=True).as_matrix()
T_DEPTH_COLOR[:3, 3] = [0.015, 0.0, 0.0]
T_DEPTH_REF = np.eye(4)  # the reference stream (extrinsics group 0) is not the depth stream here: 5 mm beside it
T_DEPTH_REF[:3, 3] = [-0.005, 0.001, 0.0]
DEPTH = "/device_0/sensor_0/Depth_0"
COLOR = "/device_0/sensor_1/Color_0"


def write_sdk_bag(path, units: float | None = 0.001, color_tf: bool = True, frames: int = 3, span_deg: float = 60.0):
    """A RealSense SDK-layout bag of the tabletop scene; returns [(rendered depth m, colour the depth camera
    sees)] per frame. units: the Depth Units option (None: not recorded)."""
    scene = primitive_tabletop_scene(seed=4)
    K_depth = kinect_v1_intrinsics(WD, HD)
    depth_cam, color_cam = DepthSensor(K_depth, WD, HD, noise=False), DepthSensor(K_COLOR, WC, HC, noise=False)
    poses = orbit_poses(frames, radius=0.85, height=1.3, target=(0.0, 0.0, 0.75), start_deg=30.0,
                        span_deg=span_deg)
    scale = 0.001 if units is None else units
    truth = []
    with RecordingWriter(path) as w:
        w.write_camera_info(f"{DEPTH}/info/camera_info", 0, "", K_depth, WD, HD)
        w.write_camera_info(f"{COLOR}/info/camera_info", 0, "", K_COLOR, WC, HC)
        if units is not None:
            w.write_float32("/device_0/sensor_0/option/Depth Units/value", 0, units)
        w.write_float32("/device_0/sensor_1/option/Exposure/value", 0, 156.0)
        w.write_transform(f"{DEPTH}/tf/0", 0, np.linalg.inv(T_DEPTH_REF))  # reference -> depth
        if color_tf:  # reference -> colour
            w.write_transform(f"{COLOR}/tf/0", 0, np.linalg.inv(T_DEPTH_COLOR) @ np.linalg.inv(T_DEPTH_REF))
        for i, T in enumerate(poses):
            t = S + i * S // 30
            depth, own = depth_cam.render(scene, T)
            _, rgb = color_cam.render(scene, T @ T_DEPTH_COLOR)
            raw = np.round(depth / scale)
            raw[raw > 65534] = 0
            truth.append((np.where(raw > 0, depth, 0.0), own))
            w.write_image(f"{DEPTH}/image/data", t, "", raw.astype(np.uint16), "mono16")
            w.write_image(f"{COLOR}/image/data", t + 2_000_000, "", rgb, "rgb8")
    return truth
