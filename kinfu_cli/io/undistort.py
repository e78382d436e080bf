"""Images of a camera with lens distortion (CameraInfo `distortion_model` and D), remapped to the pinhole camera K
that fusion, ICP and ray casting assume. An Azure Kinect's or Kinect v2's depth camera publishes its raw images
with strong distortion (a wide lens): read as pinhole, a tilted table bends by centimetres at the image borders.

Depth is remapped by nearest pixel (interpolating across an edge would invent surfaces between foreground and
background); a z-depth image keeps its values, only the pixels move. Models: plumb_bob and rational_polynomial
(OpenCV's 5 and 8 coefficients) and equidistant (OpenCV's fisheye, 4). D all zero is no distortion.
"""

from __future__ import annotations

import cv2
import numpy as np

from kinfu_cli.core.errors import RecordingError

PINHOLE_MODELS = ("plumb_bob", "rational_polynomial")
FISHEYE_MODELS = ("equidistant", "fisheye")


def check_distortion(model: str, D, topic: str) -> tuple[str, np.ndarray]:
    """(model, D) as fusion uses them: D empty when there is no distortion; RecordingError naming the topic for
    a model OpenCV does not have or a D of the wrong length."""
    d = np.asarray(list(D) if D is not None else [], dtype=np.float64).reshape(-1)
    if d.size == 0 or not np.any(d):
        return "", np.zeros(0)
    if not np.all(np.isfinite(d)):
        raise RecordingError(f"{topic}: CameraInfo D holds non-finite values ({d.tolist()})")
    model = str(model or "plumb_bob").strip().lower()
    if model in PINHOLE_MODELS:
        if d.size not in (4, 5, 8, 12, 14):
            raise RecordingError(f"{topic}: {model} distortion with {d.size} coefficients (expected 5 or 8)")
        return model, d
    if model in FISHEYE_MODELS:
        if d.size < 4 or np.any(d[4:]):  # zeros padded to 5 (some drivers) drop; a fifth value is another model's
            raise RecordingError(f"{topic}: {model} distortion with {d.size} coefficients {d.tolist()} (expected 4)")
        return "equidistant", d[:4]
    raise RecordingError(f"{topic}: distortion model {model!r} is not supported (expected plumb_bob, "
                         f"rational_polynomial or equidistant; its images cannot be read as pinhole)")


class Undistorter:
    """Remaps images of one camera (K, model, D) to pinhole K, the maps made once per image size."""

    def __init__(self, K: np.ndarray, model: str, D: np.ndarray):
        self.K, self.model, self.D = np.asarray(K, dtype=np.float64), model, np.asarray(D, dtype=np.float64)
        self._maps: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    @classmethod
    def pinhole(cls, K: np.ndarray) -> "Undistorter":
        """A camera without distortion: images pass unchanged."""
        return cls(K, "", np.zeros(0))

    def __bool__(self) -> bool:
        return self.D.size > 0

    def _map(self, w: int, h: int, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if (w, h) not in self._maps:
            if self.model == "equidistant":
                m = cv2.fisheye.initUndistortRectifyMap(K, self.D, np.eye(3), K, (w, h), cv2.CV_32FC1)
            else:
                m = cv2.initUndistortRectifyMap(K, self.D, np.eye(3), K, (w, h), cv2.CV_32FC1)
            self._maps[(w, h)] = m
        return self._maps[(w, h)]

    def image(self, img: np.ndarray, size_of_K: tuple[int, int] | None = None) -> np.ndarray:
        """`img` as the pinhole camera K sees it (nearest pixel). size_of_K: the (width, height) K belongs to,
        when `img` is the same camera at another resolution (a registered colour image)."""
        if not self:
            return img
        h, w = img.shape[:2]
        K = self.K
        if size_of_K is not None and size_of_K != (w, h):
            K = K.copy()
            K[0] *= w / size_of_K[0]
            K[1] *= h / size_of_K[1]
        m1, m2 = self._map(w, h, K)
        return cv2.remap(img, m1, m2, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def project(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) pixel positions of camera-frame points (z > 0) through the distorted lens."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 1, 3)
        zero = np.zeros(3)
        if self.model == "equidistant":
            uv, _ = cv2.fisheye.projectPoints(pts, zero, zero, self.K, self.D)
        else:
            uv, _ = cv2.projectPoints(pts, zero, zero, self.K, self.D)
        return uv.reshape(-1, 2)


def reproject_pinhole(img: np.ndarray, K_from: np.ndarray, K_to: np.ndarray, size_of_K: tuple[int, int]) -> np.ndarray:
    """`img`, an image of pinhole camera K_from, as pinhole camera K_to of the same optical frame sees it (nearest
    pixel): a rectified image (on its camera info's P) placed on an undistorted one (on K). size_of_K: the (width,
    height) both K belong to, scaled to `img`'s size. Unchanged when the two are the same camera."""
    if np.allclose(K_from, K_to, rtol=1e-9, atol=1e-9):
        return img
    h, w = img.shape[:2]
    scale = np.array([[w / size_of_K[0]], [h / size_of_K[1]], [1.0]])
    src, dst = np.asarray(K_from, np.float64) * scale, np.asarray(K_to, np.float64) * scale
    m1, m2 = cv2.initUndistortRectifyMap(src, np.zeros(5), np.eye(3), dst, (w, h), cv2.CV_32FC1)
    return cv2.remap(img, m1, m2, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
