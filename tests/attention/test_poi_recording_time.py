"""POIs of a recording say when they happened on the recording's clock (the one --start/--end take).

Before: `kinfu poi` on `kinfu synth --hand-rate 10` printed "#0 ... at t = 1.83 s" for the pick the ground truth
puts at 3.94 s into the recording: "time" counts from the first hand sample (2.1 s in), and nothing said so.
"""

import numpy as np

from kinfu_cli.attention.detect import detect_pois
from kinfu_cli.io.trajectory import Trajectory

START = 1767225600_000000000


def _hand(t0_ns: int, span) -> Trajectory:
    """A hand pausing at two places 0.6 m apart, 100 Hz, its first sample at t0_ns."""
    p = np.concatenate([np.zeros((100, 3)), np.linspace([0, 0, 0], [0.6, 0, 0], 60), np.tile([0.6, 0, 0], (100, 1))])
    p += np.random.default_rng(1).normal(0, 0.001, p.shape)
    return Trajectory(t=np.arange(len(p)) / 100.0, positions=p, frame="world", source="test", t0_ns=t0_ns,
                      meta={"recording_span_ns": span})


def test_poi_recording_time_is_its_stamp_from_the_recording_start():
    found = detect_pois(_hand(START + 2_100_000_000, (START, START + 10_000_000_000)), "zvc")
    assert len(found.pois) == 2
    for p in found.pois:
        assert abs(p.extra["recording_time_s"] - (p.time + 2.1)) < 1e-6


def test_stamps_on_another_clock_get_no_recording_time():
    found = detect_pois(_hand(900_000_000_000, (START, START + 10_000_000_000)), "zvc")  # sim time
    assert found.pois and all("recording_time_s" not in p.extra for p in found.pois)
