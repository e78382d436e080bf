"""Grid settings far outside any sensor's scale are ConfigErrors naming the parameter before any work: a voxel of
1e-300 m (from --voxel-size or a 1e-300 m --size) overflowed the voxel counts (OverflowError traceback) or the
block casts (numpy warnings), an origin of 1e300 m likewise, and a --fill-gaps of 1e20 overflowed numba."""

from __future__ import annotations

import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.fusion.pipeline import fuse_recording
from kinfu_cli.fusion.volume import TernaryVolume
from tests.recordings import make_recording


@pytest.mark.parametrize("kwargs, parameter", [
    ({"voxel_size": 1e-300}, "voxel_size"),
    ({"voxel_size": 1e300}, "voxel_size"),
    ({"size": 1e-300, "resolution": 32}, "size/resolution"),
    ({"size": 1.0, "resolution": 32, "origin": (1e300, 0, 0)}, "origin"),
])
def test_absurd_grids_are_refused_naming_the_parameter(kwargs, parameter):
    with pytest.raises(ConfigError) as err:
        TernaryVolume(**kwargs)
    assert err.value.parameter == parameter


def test_a_gap_longer_than_any_image_is_refused_before_reading(tmp_path):
    rec = make_recording(tmp_path / "rec.mcap")
    with pytest.raises(ConfigError) as err:
        fuse_recording(rec, size=1.0, resolution=32, fill_gaps=10 ** 20)
    assert err.value.parameter == "fill_gaps"
