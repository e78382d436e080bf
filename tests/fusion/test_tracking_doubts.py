"""Tracked poses that look wrong although no frame was lost are reported (fusion/pipeline._tracking_doubts)."""

from __future__ import annotations

import numpy as np

from kinfu_cli.fusion.pipeline import _tracking_doubts


def track_log(dev_m: float, relocalised: int, n: int = 20) -> list[dict]:
    """n frames stepping 1 cm along x and 2 deg about z; the given poses `dev_m` away; the first `relocalised`
    found by re-localisation."""
    out = []
    for i in range(n):
        a = np.radians(2.0 * i)
        T = np.eye(4)
        T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        T[0, 3] = 0.01 * i
        out.append({"index": i, "lost": False, "relocalised": i < relocalised, "T_world_camera": T.tolist(),
                    "given_minus_tracked_m": dev_m})
    return out


def test_good_tracking_gives_no_warning():
    assert _tracking_doubts(track_log(0.007, 0)) == []
    assert _tracking_doubts(track_log(0.007, 4)) == []  # 20 % relocalised is tolerated
    assert _tracking_doubts([]) == []


def test_drift_from_the_given_poses_is_reported_with_the_motion_per_frame():
    w = _tracking_doubts(track_log(0.05, 0))
    assert len(w) == 1
    assert "5.0 cm RMS" in w[0] and "median 1.0 cm / 2.0 deg per frame" in w[0]


def test_frames_found_only_by_relocalisation_are_reported():
    log = track_log(0.0, 10)
    for t in log:
        del t["given_minus_tracked_m"]  # no given poses: the re-localisation share is the only evidence
    w = _tracking_doubts(log)
    assert len(w) == 1 and "10 of 20 tracked frames" in w[0] and "1.0 cm / 2.0 deg" in w[0]
