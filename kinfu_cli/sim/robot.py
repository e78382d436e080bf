"""A robot-like 6-joint arm carrying the camera, for a consistent TF chain in synthetic recordings.

Chain (all `T_parent_child`): world -> base_link (fixed mount, /tf_static) -> link1 (yaw q1 at shoulder height d1)
-> link2 (shoulder pitch q2) -> link3 (upper arm a2 along z, elbow pitch q3) -> link4 (forearm a3 along z, wrist
roll q4) -> link5 (wrist pitch q5) -> link6 (wrist roll q6) -> wrist (flange, d6 along z) -> camera_optical (fixed
hand-eye calibration, /tf_static). Joints 4-6 form a spherical wrist, so inverse kinematics is closed form: the wrist
centre gives q1..q3 (elbow up), the remaining rotation gives q4..q6 (ZYZ Euler angles).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import ConfigError

LINKS = ("base_link", "link1", "link2", "link3", "link4", "link5", "link6", "wrist")
CAMERA_FRAME = "camera_optical"
WORLD_FRAME = "world"


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def transform(R: np.ndarray | None = None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def rotvec(v) -> np.ndarray:
    return Rotation.from_rotvec(v).as_matrix()


def _default_base() -> np.ndarray:
    # beside the table's +y edge (table 1.2 x 0.8 m centred at the origin, top at 0.7 m), facing the table (-y)
    return transform(rot_z(-np.pi / 2), (0.0, 0.62, 0.70))


def _default_hand_eye() -> np.ndarray:
    # the camera 4 cm beside and 6 cm beyond the flange, looking along the flange axis, off by ~1-2 degrees
    return transform(rotvec([0.012, -0.021, np.pi / 2 + 0.015]), (0.0, 0.04, 0.06))


@dataclass
class RobotArm:
    """The arm's geometry: T_world_base (mount), d1 shoulder height, a2/a3 upper arm and forearm, d6 flange offset,
    T_wrist_camera (hand-eye calibration)."""

    T_world_base: np.ndarray = field(default_factory=_default_base)
    d1: float = 0.35
    a2: float = 0.55
    a3: float = 0.55
    d6: float = 0.08
    T_wrist_camera: np.ndarray = field(default_factory=_default_hand_eye)

    def static_transforms(self) -> list[tuple[str, str, np.ndarray]]:
        """(parent, child, T_parent_child) published on /tf_static: the mount and the hand-eye calibration."""
        return [(WORLD_FRAME, "base_link", self.T_world_base.copy()), ("wrist", CAMERA_FRAME, self.T_wrist_camera.copy())]

    def joint_transforms(self, q: np.ndarray) -> list[tuple[str, str, np.ndarray]]:
        """(parent, child, T_parent_child) of the moving chain base_link -> ... -> wrist for joint angles q (6,)."""
        q = np.asarray(q, dtype=float)
        return [
            ("base_link", "link1", transform(rot_z(q[0]), (0.0, 0.0, self.d1))),
            ("link1", "link2", transform(rot_y(q[1]))),
            ("link2", "link3", transform(rot_y(q[2]), (0.0, 0.0, self.a2))),
            ("link3", "link4", transform(rot_z(q[3]), (0.0, 0.0, self.a3))),
            ("link4", "link5", transform(rot_y(q[4]))),
            ("link5", "link6", transform(rot_z(q[5]))),
            ("link6", "wrist", transform(None, (0.0, 0.0, self.d6))),
        ]

    def fk(self, q: np.ndarray) -> np.ndarray:
        """T_world_camera for joint angles q, by chaining every transform."""
        T = self.T_world_base.copy()
        for _, _, Tj in self.joint_transforms(q):
            T = T @ Tj
        return T @ self.T_wrist_camera

    def ik(self, T_world_camera: np.ndarray) -> np.ndarray:
        """Joint angles (6,) putting the camera at T_world_camera (elbow up); ConfigError when out of reach."""
        T_base_wrist = np.linalg.inv(self.T_world_base) @ np.asarray(T_world_camera, float) @ np.linalg.inv(
            self.T_wrist_camera)
        R, p = T_base_wrist[:3, :3], T_base_wrist[:3, 3]
        c = p - self.d6 * R[:, 2]  # wrist centre
        q1 = np.arctan2(c[1], c[0])
        r = np.hypot(c[0], c[1])
        h = c[2] - self.d1
        D = (r * r + h * h - self.a2 ** 2 - self.a3 ** 2) / (2 * self.a2 * self.a3)
        if abs(D) > 1.0:
            dist = float(np.hypot(r, h))
            raise ConfigError(f"camera pose at {np.round(T_world_camera[:3, 3], 3).tolist()} is out of the arm's "
                              f"reach (wrist centre {dist:.2f} m from the shoulder, reach "
                              f"{abs(self.a2 - self.a3):.2f}..{self.a2 + self.a3:.2f} m)")
        q3 = np.arccos(np.clip(D, -1.0, 1.0))
        q2 = np.arctan2(r, h) - np.arctan2(self.a3 * np.sin(q3), self.a2 + self.a3 * np.cos(q3))
        R03 = rot_z(q1) @ rot_y(q2 + q3)
        R36 = R03.T @ R
        s5 = np.hypot(R36[0, 2], R36[1, 2])
        q5 = np.arctan2(s5, R36[2, 2])
        if s5 > 1e-9:
            q4 = np.arctan2(R36[1, 2], R36[0, 2])
            q6 = np.arctan2(R36[2, 1], -R36[2, 0])
        else:  # wrist singularity: only q4 + q6 matters
            q4 = 0.0
            q6 = np.arctan2(R36[1, 0], R36[0, 0])
        return np.array([q1, q2, q3, q4, q5, q6])

    def ik_path(self, poses: list[np.ndarray]) -> np.ndarray:
        """Joint angles (N, 6) for a sequence of camera poses, unwrapped so consecutive angles do not jump by 2 pi."""
        Q = np.array([self.ik(T) for T in poses])
        return np.unwrap(Q, axis=0) if len(Q) > 1 else Q
