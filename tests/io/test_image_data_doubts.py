"""Image messages whose data does not fit what they say: JPEG colour with an EXIF orientation, data longer than
step x height, depth images of no pixels."""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.rgbd_frame import DROP_NO_PIXELS
from kinfu_cli.io.messages import decode_color, decode_depth
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter
from tests.conftest import one_line_error

T0 = 1_700_000_000 * 10**9
W, H = 8, 6
K = np.array([[10.0, 0, 3.5], [0, 10.0, 2.5], [0, 0, 1]])


def _jpeg_with_orientation(bgr: np.ndarray, orientation: int | None) -> bytes:
    """JPEG bytes of `bgr` with an EXIF APP1 segment holding one Orientation tag (none: plain)."""
    jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 100])[1].tobytes()
    if orientation is None:
        return jpeg
    tiff = b"II*\x00\x08\x00\x00\x00" + b"\x01\x00" + b"\x12\x01\x03\x00\x01\x00\x00\x00"
    tiff += orientation.to_bytes(2, "little") + b"\x00\x00" + b"\x00\x00\x00\x00"
    exif = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + (len(exif) + 2).to_bytes(2, "big") + exif + jpeg[2:]


@pytest.mark.parametrize("orientation", [3, 6])  # rotate 180, rotate 90
def test_jpeg_colour_is_decoded_as_stored_whatever_its_exif_orientation(orientation):
    # image_transport decodes the pixels as stored (the camera's); applying EXIF turned them off the depth image
    bgr = np.zeros((H, W, 3), np.uint8)
    bgr[:2, :3] = (0, 0, 255)  # red in the top-left corner
    plain = decode_color(SimpleNamespace(format="bgr8; jpeg compressed bgr8",
                                         data=_jpeg_with_orientation(bgr, None)))
    turned = decode_color(SimpleNamespace(format="bgr8; jpeg compressed bgr8",
                                          data=_jpeg_with_orientation(bgr, orientation)))
    assert turned.shape == (H, W, 3)
    np.testing.assert_array_equal(turned, plain)
    assert turned[0, 0, 0] > 200 and turned[-1, -1, 0] < 50


def _image(data: bytes, h: int, w: int, encoding: str, step: int):
    return SimpleNamespace(height=h, width=w, encoding=encoding, step=step, is_bigendian=0, data=data)


def test_image_data_longer_than_step_times_height_is_refused():
    depth = np.arange(W * H, dtype="<u2").reshape(H, W)
    doubled = _image(depth.tobytes() * 2, H, W, "16UC1", W * 2)  # two images' bytes, or another size's
    with pytest.raises(RecordingError, match=r"/camera/depth/image_raw: image data has 192 bytes, more than the 96"):
        decode_depth(doubled, "/camera/depth/image_raw")
    rgb = np.zeros((H, W, 3), np.uint8)
    with pytest.raises(RecordingError, match=r"/camera/color/image_raw: image data has 145 bytes, more than the 144"):
        decode_color(_image(rgb.tobytes() + b"\x00", H, W, "rgb8", W * 3), "/camera/color/image_raw")
    # rows padded to a longer step, data exactly step x height: read as before
    padded = np.zeros((H, W * 2 + 4), np.uint8)
    padded[:, : W * 2] = depth.view(np.uint8)
    np.testing.assert_array_equal(decode_depth(_image(padded.tobytes(), H, W, "16UC1", W * 2 + 4)),
                                  depth * np.float32(0.001))


def _recording(path, sizes: list[tuple[int, int]], extra_bytes: int = 0):
    """Depth images of the given (height, width), each with its camera info (for W x H) and colour."""
    with RecordingWriter(path) as w:
        for i, (h, wd) in enumerate(sizes):
            stamp = T0 + i * 100_000_000
            w.write_camera_info("/camera/depth/camera_info", stamp, "cam", K, W, H)
            data = np.full((h, wd), 1000 + i, "<u2").tobytes() + b"\x00" * extra_bytes
            msg = w._type("sensor_msgs/msg/Image")(
                header=w._header("/camera/depth/image_raw", stamp, "cam"), height=h, width=wd, encoding="16UC1",
                is_bigendian=0, step=wd * 2, data=np.frombuffer(data, np.uint8))
            w._write("/camera/depth/image_raw", "sensor_msgs/msg/Image", stamp, msg)
            w.write_image("/camera/color/image_raw", stamp, "cam", np.zeros((H, W, 3), np.uint8), "rgb8")
    return path


def test_export_refuses_depth_data_longer_than_the_image(tmp_path):
    path = _recording(tmp_path / "long.mcap", [(H, W)] * 3, extra_bytes=W * H * 2)
    res = CliRunner().invoke(cli, ["export", str(path), "-o", str(tmp_path / "out"), "--pose-source", "none"])
    one_line_error(res, "long.mcap", "/camera/depth/image_raw", "image data has 192 bytes, more than the 96")


def test_empty_depth_images_are_named_as_such(tmp_path):
    # a 0x0 image scaled K to zeros and was counted as "no valid pixel", as if the sensor saw nothing
    mixed = _recording(tmp_path / "mixed.mcap", [(H, W), (0, 0), (H, W), (0, 0)])
    stats = FrameStats()
    with open_recording(mixed) as rec:
        frames = list(iter_frames(rec, pose_source="none", stats=stats))
    assert len(frames) == 2 and stats.dropped == {DROP_NO_PIXELS: 2}
    said = [w for w in stats.warnings("mixed.mcap") if "empty" in w]
    assert said == ["mixed.mcap: 2 of 4 depth images are empty (0 pixels wide or high: a driver fault?); they were "
                    "left out"]
    empty = _recording(tmp_path / "empty.mcap", [(0, 0)] * 3)
    res = CliRunner().invoke(cli, ["export", str(empty), "-o", str(tmp_path / "out"), "--pose-source", "none"])
    one_line_error(res, "empty.mcap", "no usable depth frame", "depth image is empty (0 pixels wide or high)': 3")
