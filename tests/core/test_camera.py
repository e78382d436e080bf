"""core.camera: one set of named sensor presets, intrinsics scaling, the NBV camera model's checks."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.camera import SENSOR_PRESETS, CameraModel, preset_intrinsics, scaled_intrinsics
from kinfu_cli.core.errors import ConfigError


def test_presets_at_native_and_scaled_sizes():
    K = preset_intrinsics("kinect_v1")
    assert np.allclose(K, [[525, 0, 319.5], [0, 525, 239.5], [0, 0, 1]])
    Kir = preset_intrinsics("kinect_v1_ir", 320, 240)
    assert np.allclose(Kir, [[292.5, 0, 159.5], [0, 292.5, 119.5], [0, 0, 1]])
    # scaling a preset by a factor is the same as asking for the smaller image
    assert np.allclose(scaled_intrinsics(preset_intrinsics("kinect_v1_ir"), 0.25), preset_intrinsics("kinect_v1_ir", 160, 120))
    assert set(SENSOR_PRESETS) == {"kinect_v1", "kinect_v1_ir"}


def test_unknown_preset_and_tiny_image_are_config_errors():
    with pytest.raises(ConfigError, match="kinect_v1, kinect_v1_ir"):
        preset_intrinsics("kinect_v2")
    with pytest.raises(ConfigError, match="at least 2x2"):
        preset_intrinsics("kinect_v1", 1, 480)


def test_camera_model_errors_name_the_parameter():
    with pytest.raises(ConfigError) as err:
        CameraModel(0.0, 525.0, 319.5, 239.5, 640, 480)
    assert err.value.parameter == "fx" and str(err.value).startswith("fx: expected a positive focal length")
    with pytest.raises(ConfigError) as err:
        CameraModel(525.0, 525.0, 319.5, 239.5, 640, 480, vfov_extra_deg=50)
    assert err.value.parameter == "vfov_extra_deg"
