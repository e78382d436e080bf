"""Synthetic hand trajectories: pauses at the action locations, minimum-jerk moves, noise, Polhemus output."""

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.hand import Action, min_jerk, pick_and_place, synth_hand_trajectory, write_polhemus
from kinfu_cli.sim.scene import Table


def _speed(traj):
    return np.linalg.norm(np.diff(traj.positions, axis=0), axis=1) / np.diff(traj.t)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("actions", [
    [Action("placement", (0.2, 0.1, 0.78))],
    [("removal", (-0.35, 0.2, 0.8))],
    pick_and_place((0.3, -0.1, 0.78), (-0.25, 0.15, 0.82)),
])
def test_pauses_at_each_action_location(actions, seed):
    traj, changes = synth_hand_trajectory(actions, seed=seed)
    traj.validate()
    assert len(changes) == len(actions) if not isinstance(actions[0], tuple) or len(actions) > 1 else 1
    assert np.allclose(np.diff(traj.t), 0.01)
    speed = _speed(traj)
    table = Table()
    assert not table.contains_xy(traj.positions[0, :2]) and not table.contains_xy(traj.positions[-1, :2])
    for c in changes:
        pause = (traj.t >= c.t_start) & (traj.t <= c.t_end)
        assert 1.0 <= c.t_end - c.t_start <= 2.0
        d = np.linalg.norm(traj.positions[pause] - c.position, axis=1)
        assert d.max() < 0.02 and d.mean() < 0.01          # stays at the location, small jitter
        assert speed[pause[:-1]].max() < 0.08               # nearly still
        assert np.linalg.norm(traj.positions[c.index] - c.position) < 0.02
        assert c.t_start < c.time < c.t_end
    assert 0.8 < speed.max() < 3.0                          # human reaching speeds
    # far from the actions the hand is moving, not resting
    far = np.min([np.linalg.norm(traj.positions - c.position, axis=1) for c in changes], axis=0) > 0.15
    assert np.median(speed[far[:-1]]) > 0.2


def test_minimum_jerk_profile_and_times_are_ordered():
    tau = np.linspace(0, 1, 101)
    s = min_jerk(tau)
    assert s[0] == 0 and s[-1] == 1 and np.all(np.diff(s) >= 0)
    assert abs(np.gradient(s, tau).max() - 1.875) < 1e-3     # peak speed 1.875 x mean
    traj, changes = synth_hand_trajectory(pick_and_place((0.1, 0, 0.8), (-0.3, 0.1, 0.8)), seed=4, t0=5.0)
    assert traj.t[0] == 5.0
    assert [c.kind for c in changes] == ["pick", "place"] and changes[0].t_end < changes[1].t_start
    assert changes[0]["kind"] == "pick" and changes[0].to_json()["position"] == [0.1, 0.0, 0.8]


def test_deterministic_and_noise_level():
    acts = [("placement", (0.0, 0.0, 0.8))]
    a, _ = synth_hand_trajectory(acts, seed=9)
    b, _ = synth_hand_trajectory(acts, seed=9)
    n, _ = synth_hand_trajectory(acts, seed=9, noise_std=0.01)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.rotations, b.rotations)
    err = n.positions - a.positions
    assert abs(err.std() - 0.01) < 0.001 and abs(err.mean()) < 0.001
    r = a.rotations
    assert np.allclose(r @ r.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    slow, _ = synth_hand_trajectory(acts, seed=9, rate_hz=30)
    assert np.allclose(np.diff(slow.t), 1 / 30) and abs(slow.duration - a.duration) < 0.05


def test_polhemus_file_round_trip(tmp_path):
    from kinfu_cli.io.polhemus import read_polhemus

    traj, _ = synth_hand_trajectory(pick_and_place((0.1, 0, 0.8), (-0.3, 0.1, 0.8)), seed=1, rate_hz=30)
    write_polhemus(tmp_path / "hand.traj", traj)
    back = read_polhemus(tmp_path / "hand.traj")
    assert abs(back.duration - traj.duration) < 0.011            # resampled to 100 Hz
    probe = np.interp(back.t[::7], traj.t - traj.t[0], traj.positions[:, 0])
    assert np.abs(back.positions[::7, 0] - probe).max() < 1e-5


def test_bad_actions_are_config_errors():
    with pytest.raises(ConfigError, match="at least one action"):
        synth_hand_trajectory([])
    with pytest.raises(ConfigError, match="kind 'throw'"):
        synth_hand_trajectory([("throw", (0, 0, 0.8))])
    with pytest.raises(ConfigError, match="position"):
        synth_hand_trajectory([(0.0, 1.0)])
    with pytest.raises(ConfigError, match="rate"):
        synth_hand_trajectory([(0.0, 0.0, 0.8)], rate_hz=0)


def test_random_tasks_on_a_large_table():
    from kinfu_cli.sim.hand import random_task

    table = Table(size=(2.0, 1.4), top_z=1.2)   # the Polhemus data set's table
    for seed in range(5):
        acts = random_task("pick-and-place", seed, table=table)
        assert [a.kind for a in acts] == ["pick", "place"]
        a, b = (np.asarray(x.position) for x in acts)
        assert np.linalg.norm(a[:2] - b[:2]) >= 0.3 and table.contains_xy(np.stack([a[:2], b[:2]])).all()
        assert 1.25 <= a[2] <= 1.4
        traj, changes = synth_hand_trajectory(acts, seed=seed, table=table, noise_std=0.002)
        assert [c.kind for c in changes] == ["pick", "place"]
        assert not table.contains_xy(traj.positions[0, :2])
    assert random_task("removal", 1) != random_task("removal", 2)
    with pytest.raises(ConfigError, match="task kind"):
        random_task("juggle")
