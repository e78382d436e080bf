"""core.grid.check_up: a huge but finite direction is a direction (its norm must not overflow), and every
vector without one is a ConfigError naming the parameter, with no numpy warning on the way."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import check_up


@pytest.mark.parametrize("up, want", [((1e300, 1e300, 0.0), (2 ** -0.5, 2 ** -0.5, 0.0)),
                                      ((0.0, 0.0, -1e308), (0.0, 0.0, -1.0)), ((0, 0, 3), (0, 0, 1))])
def test_huge_directions_are_unit_vectors(up, want):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow in the norm was a RuntimeWarning on stderr
        got = check_up(up, "up")
    np.testing.assert_allclose(got, want, atol=1e-12)


@pytest.mark.parametrize("up", [(0, 0, 0), (np.nan, 0, 1), (np.inf, 0, 0), (1e-320, 0, 0)])
def test_no_direction_is_refused(up):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError) as info:
            check_up(up, "up")
    assert info.value.parameter == "up"
