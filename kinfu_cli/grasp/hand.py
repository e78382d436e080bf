"""The hand as the thesis models it: the graspable volume H (an ellipsoid attached to the palm), the L points
on the half of H nearest the palm (ch. 7.2) and the V = 5 points of palm and fingers (ch. 8.2).

Hand frame (ours; the thesis' iCub frame is robot-specific), right-handed, origin at the palm centre:
  z_h  approach axis: the palm normal, pointing from the palm into the object (the pre-grasp pose is the
       hand pose moved back along -z_h);
  x_h  finger direction (the middle finger, stretched);
  y_h  = z_h x x_h, across the palm (palm width).
H is centred at (0, 0, a_z) in this frame, so its back pole touches the palm; its longest semi-axis a_y runs
across the palm, where a grasped bottle's axis lies. The iCub size (0.03, 0.05, 0.03) m is the default
([code] superquadric-grasp; x, y, z here). Both hands use the same frame: left and right differ by their
workspace (`constraints.default_workspaces`), not by mirrored axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinfu_cli.core.checks import check_number

ICUB_HAND_SIZE = (0.03, 0.05, 0.03)  # H semi-axes (m) along x_h, y_h, z_h
HANDS = ("right", "left")


@dataclass(frozen=True)
class HandModel:
    """H semi-axes `size` (m), the number L of points on its palm-side half, and the palm / finger lengths
    of the V points (m; [ours]: iCub-like, the thesis gives no numbers)."""

    size: tuple[float, float, float] = ICUB_HAND_SIZE
    n_points: int = 48  # L ([code] pointshand = 48)
    palm_width: float = 0.06  # w_p
    thumb_length: float = 0.05  # l_t
    finger_length: float = 0.07  # l_m

    def validate(self) -> None:
        if len(self.size) != 3:
            from kinfu_cli.core.errors import ConfigError

            raise ConfigError(f"expected three semi-axes, got {self.size}", parameter="hand_size")
        for s in self.size:
            check_number(s, "hand_size", 0.005, 0.5, unit="m")
        check_number(self.n_points, "n_points", 8, 2000, integer=True)
        check_number(self.palm_width, "palm_width", 0.005, 0.5, unit="m")  # 0 was a hand of no size
        check_number(self.thumb_length, "thumb_length", 0.005, 0.5, unit="m")
        check_number(self.finger_length, "finger_length", 0.005, 0.5, unit="m")

    def lifted(self, object_size: np.ndarray, object_axes: np.ndarray | None = None,
               cones: tuple = ()) -> "HandModel":
        """Lifting rule (7.2.4): when the object's largest semi-axis that can lie across the palm exceeds H's
        longest one (a_y), stretch a_y to it, which pulls the centre of H onto the object's centre along that
        axis. Which object axis "corresponds" to a_y depends on the orientation cones ([ours]): with a cone
        on the approach z_h, object axes within 45 deg of its direction cannot lie across the palm; with a
        cone on y_h, only object axes within its aperture (+ 15 deg) can."""
        size = np.asarray(object_size, dtype=np.float64)
        ok = np.ones(3, dtype=bool)
        if object_axes is not None:
            for c in cones:
                cos = np.abs(np.asarray(object_axes).T @ c.unit())
                if c.axis == "z":
                    ok &= cos < np.cos(np.radians(45.0))
                elif c.axis == "y":
                    ok &= cos >= np.cos(np.radians(min(c.aperture_deg + 15.0, 90.0)))
        big = float(np.max(size[ok])) if ok.any() else 0.0
        if big <= self.size[1]:
            return self
        return HandModel((self.size[0], big, self.size[2]), self.n_points, self.palm_width, self.thumb_length,
                         self.finger_length)

    def l_points(self) -> np.ndarray:
        """(L, 3) points in the hand frame on the half of H nearest the palm (z <= a_z), evenly spread
        (a Fibonacci lattice on the half sphere, scaled to H); the palm pole is the first."""
        n = int(self.n_points)
        k = np.arange(n)
        cz = -(k + 0.5) / n  # cos of the angle from H's axis, in [-1, 0): the palm-side half
        cz[0] = -1.0
        r = np.sqrt(1.0 - cz ** 2)
        phi = k * np.pi * (3.0 - np.sqrt(5.0))
        unit = np.stack([r * np.cos(phi), r * np.sin(phi), cz], axis=1)
        a = np.asarray(self.size)
        return unit * a + np.array([0.0, 0.0, a[2]])

    def v_points(self) -> np.ndarray:
        """(5, 3) palm and finger points in the hand frame (eq. 8.2): palm centre, palm edges, thumb tip
        (in front of the palm, along z_h), middle fingertip (along x_h)."""
        w = self.palm_width / 2
        return np.array([[0.0, 0.0, 0.0], [0.0, w, 0.0], [0.0, -w, 0.0], [0.0, 0.0, self.thumb_length],
                         [self.finger_length, 0.0, 0.0]])

    def h_center(self) -> np.ndarray:
        """Centre of H in the hand frame."""
        return np.array([0.0, 0.0, self.size[2]])
