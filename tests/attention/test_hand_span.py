"""`kinfu poi` on a path that is no hand: a warning in pois.json, not POIs that look like a person's actions.

Before: `kinfu poi ROS_example.bag --hand-topic groundtruth` (a vehicle's 100 m ground-truth track) printed
5 POIs 20-75 m apart with no warning, as if a person had acted there.
"""

import numpy as np

from kinfu_cli.attention.detect import HAND_SPAN_WARN_M, detect_pois
from kinfu_cli.io.trajectory import Trajectory


def _pause_and_go(scale: float) -> Trajectory:
    """Three pauses joined by straight moves, 0.6 m apart, times `scale`, sampled at 100 Hz."""
    stops = np.array([[0.0, 0.0, 0.0], [0.6, 0.0, 0.0], [0.6, 0.4, 0.1]]) * scale
    pts = [np.repeat(stops[:1], 80, axis=0)]
    for a, b in zip(stops[:-1], stops[1:]):
        pts.append(a + (b - a) * np.linspace(0, 1, 60)[:, None])
        pts.append(np.repeat(b[None], 80, axis=0))
    p = np.concatenate(pts) + np.random.default_rng(0).normal(0, 0.001, (sum(len(q) for q in pts), 3))
    return Trajectory(t=np.arange(len(p)) / 100.0, positions=p, frame="world", source="test")


def test_a_hand_at_a_table_gives_no_span_warning():
    found = detect_pois(_pause_and_go(1.0), "zvc")
    assert found.document["warnings"] == []
    assert len(found.pois) >= 2


def test_a_path_of_tens_of_metres_is_flagged():
    found = detect_pois(_pause_and_go(60.0), "zvc")
    (w,) = found.document["warnings"]
    assert "spans" in w and "is it a hand" in w
    span = float(w.split("spans ")[1].split(" m")[0])
    assert span > HAND_SPAN_WARN_M and abs(span - 60 * np.linalg.norm([0.6, 0.4, 0.1])) < 2.0
