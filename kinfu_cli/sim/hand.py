"""Synthetic wrist trajectories of a person acting on a table, with known action locations.

The wrist enters from outside the table (the person's side, -y), reaches each action location with a human-like
minimum-jerk speed profile (Flash & Hogan 1985) along a gently lifted, slightly curved path, pauses there (grasp or
release, 1-2 s with a small smooth jitter), and finally leaves the table. A pick-and-place is two actions: "pick" at A
and "place" at B, with a transport movement between them.

`synth_hand_trajectory(...) -> (Trajectory, changes)`; `changes[i]` holds the true action position, its kind and the
time (middle of the pause) in the trajectory's clock. `write_polhemus(path, traj)` writes the Polhemus `.traj` text
format (4x4 matrices at 100 Hz, no stamps; see ../shared/data/hand-polhemus/README.md).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io import polhemus
from kinfu_cli.io.trajectory import Trajectory
from kinfu_cli.sim.scene import Table

ACTION_KINDS = ("placement", "removal", "pick", "place", "action")


@dataclass(frozen=True)
class Action:
    """One thing the hand does at a place: kind in ACTION_KINDS, position (x, y, z) of the wrist there (metres)."""

    kind: str
    position: tuple[float, float, float]


@dataclass
class HandChange:
    """A true action of a synthetic trajectory: where the wrist paused, what it did, and when (seconds).

    time: middle of the pause; t_start/t_end: the pause; index: sample index of `time`.
    Also readable like a dict (`change["position"]`).
    """

    position: np.ndarray
    kind: str
    time: float
    t_start: float
    t_end: float
    index: int

    def __getitem__(self, key: str):
        return getattr(self, key)

    def to_json(self) -> dict:
        return {"position": [float(p) for p in self.position], "kind": self.kind, "time": float(self.time),
                "t_start": float(self.t_start), "t_end": float(self.t_end)}


def pick_and_place(a: Sequence[float], b: Sequence[float]) -> list[Action]:
    """The two actions of a pick-and-place from a to b."""
    return [Action("pick", tuple(float(x) for x in a)), Action("place", tuple(float(x) for x in b))]


def random_task(kind: str, seed: int = 0, table: Table | None = None, min_separation: float = 0.3,
                hand_height: tuple[float, float] = (0.05, 0.2)) -> list[Action]:
    """Random action locations for one task on the table: kind "placement", "removal" (one action) or
    "pick-and-place" (pick and place at least `min_separation` apart), the wrist `hand_height` above the top."""
    table = table or Table()
    rng = np.random.default_rng([seed, 3])
    half = np.asarray(table.size) / 2 - 0.1

    def spot() -> np.ndarray:
        xy = np.asarray(table.center) + rng.uniform(-half, half)
        return np.array([xy[0], xy[1], table.top_z + rng.uniform(*hand_height)])

    if kind in ("placement", "removal"):
        return [Action(kind, tuple(spot()))]
    if kind == "pick-and-place":
        a = spot()
        for _ in range(1000):
            b = spot()
            if np.linalg.norm(b[:2] - a[:2]) >= min_separation:
                return pick_and_place(a, b)
        raise ConfigError(f"table {table.size} too small for a pick-and-place {min_separation} m apart")
    raise ConfigError(f"task kind {kind!r}: expected placement, removal or pick-and-place")


def min_jerk(tau: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 for tau in [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau ** 2)


def _parse_actions(actions) -> list[Action]:
    out: list[Action] = []
    if isinstance(actions, Action) or (isinstance(actions, dict)):
        actions = [actions]
    for a in actions:
        if isinstance(a, Action):
            out.append(a)
        elif isinstance(a, dict):
            kind = a.get("kind", "action")
            if kind == "pick-and-place":
                out += pick_and_place(*a["positions"])
            else:
                out.append(Action(str(kind), tuple(a["position"])))
        elif isinstance(a, (tuple, list)) and len(a) == 2 and isinstance(a[0], str):
            out.append(Action(a[0], tuple(a[1])))
        else:
            p = np.asarray(a, dtype=float).reshape(-1)
            if p.shape != (3,):
                raise ConfigError(f"hand action {a!r}: expected a position (x, y, z), (kind, position) or an Action")
            out.append(Action("action", tuple(p)))
    for a in out:
        if a.kind not in ACTION_KINDS:
            raise ConfigError(f"hand action kind {a.kind!r}: expected one of {', '.join(ACTION_KINDS)}")
        p = np.asarray(a.position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ConfigError(f"hand action position {a.position!r}: expected three finite numbers")
    if not out:
        raise ConfigError("synthetic hand trajectory: at least one action is needed")
    return out


def synth_hand_trajectory(actions: Iterable, seed: int = 0, rate_hz: float = 100.0, noise_std: float = 0.0, *,
                          pause_s: tuple[float, float] = (1.0, 2.0), jitter_std: float = 0.004,
                          speed: tuple[float, float] = (0.5, 0.9), lift: tuple[float, float] = (0.05, 0.15),
                          curve_std: float = 0.04, start: Sequence[float] | None = None,
                          end: Sequence[float] | None = None, table: Table | None = None,
                          t0: float = 0.0, frame: str = "world") -> tuple[Trajectory, list[HandChange]]:
    """A wrist trajectory visiting each action location and pausing there.

    actions: Action objects, (kind, position) pairs, dicts {"kind", "position"} (kind "pick-and-place" with
    "positions": [a, b]) or bare positions. rate_hz: sample rate. noise_std: white Gaussian noise (m) added to the
    positions (measurement noise; the changes stay the true positions). pause_s: pause duration range (uniform).
    jitter_std: std (m) of the smooth hand jitter during a pause. speed: range of mean speeds (m/s) of a movement
    (peak = 1.875 x mean, minimum jerk). lift: range of the height of the arc over each movement (m). curve_std:
    sideways bow of a movement (m). start/end: entry/exit positions (default: outside the table edge on the person's
    side, -y, above the table). table: the table (default the scene's 1.2 x 0.8 m at z = 0.7). t0: time of sample 0.

    Returns (Trajectory with t, positions and rotations in `frame`, list of HandChange).
    """
    acts = _parse_actions(actions)
    if not rate_hz > 0:
        raise ConfigError(f"hand rate {rate_hz}: expected a positive number of samples per second")
    if noise_std < 0 or jitter_std < 0:
        raise ConfigError("hand noise and jitter: expected non-negative standard deviations")
    if not 0 < pause_s[0] <= pause_s[1]:
        raise ConfigError(f"pause {pause_s}: expected 0 < min <= max seconds")
    table = table or Table()
    rng = np.random.default_rng(seed)
    pts = [np.asarray(a.position, dtype=float) for a in acts]
    edge_y = table.center[1] - table.size[1] / 2
    if start is None:
        start = np.array([pts[0][0] + rng.uniform(-0.25, 0.25), edge_y - rng.uniform(0.1, 0.25),
                          table.top_z + rng.uniform(0.25, 0.4)])
    if end is None:
        end = np.array([pts[-1][0] + rng.uniform(-0.25, 0.25), edge_y - rng.uniform(0.1, 0.25),
                        table.top_z + rng.uniform(0.25, 0.4)])
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)

    # ---- timeline of segments: ("move", a, b, T) and ("pause", p, T) --------------------------------------
    segments: list[tuple] = []
    cur = start
    for p in pts:
        segments.append(("move", cur, p, _move_duration(rng, cur, p, speed), rng.uniform(*lift),
                         rng.normal(0.0, curve_std)))
        segments.append(("pause", p, rng.uniform(*pause_s)))
        cur = p
    segments.append(("move", cur, end, _move_duration(rng, cur, end, speed), rng.uniform(*lift) * 0.5,
                     rng.normal(0.0, curve_std)))
    durations = np.array([s[3] if s[0] == "move" else s[2] for s in segments])
    bounds = np.concatenate([[0.0], np.cumsum(durations)])
    n = int(np.floor(bounds[-1] * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    pos = np.empty((n, 3))
    seg_of = np.clip(np.searchsorted(bounds, t, side="right") - 1, 0, len(segments) - 1)
    changes: list[HandChange] = []
    action_i = 0
    for k, seg in enumerate(segments):
        m = seg_of == k
        tau = (t[m] - bounds[k]) / durations[k]
        if seg[0] == "move":
            _, a, b, _, h, bow = seg
            s = min_jerk(tau)[:, None]
            d = b - a
            side = np.cross([0.0, 0.0, 1.0], d)
            side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.zeros(3)
            bump = np.sin(np.pi * s)
            pos[m] = a + d * s + bump * (h * np.array([0.0, 0.0, 1.0]) + bow * side)
        else:
            _, p, T = seg
            pos[m] = p + _smooth_jitter(rng, tau, T, jitter_std)
            mid = bounds[k] + T / 2
            changes.append(HandChange(np.asarray(p, dtype=float).copy(), acts[action_i].kind, t0 + mid,
                                      t0 + bounds[k], t0 + bounds[k + 1], int(round(mid * rate_hz))))
            action_i += 1
    if noise_std > 0:
        pos = pos + np.random.default_rng([seed, 1]).normal(0.0, noise_std, pos.shape)
    rot = _wrist_rotations(rng, pos, rate_hz)
    traj = Trajectory(t + t0, pos, rot, frame=frame, source="synthetic hand trajectory",
                      meta={"seed": seed, "rate_hz": rate_hz, "noise_std": noise_std})
    return traj, changes


def _move_duration(rng: np.random.Generator, a: np.ndarray, b: np.ndarray, speed: tuple[float, float]) -> float:
    v = rng.uniform(*speed)
    return float(max(0.45, np.linalg.norm(b - a) / v))


def _smooth_jitter(rng: np.random.Generator, tau: np.ndarray, T: float, std: float) -> np.ndarray:
    """Small smooth wandering during a pause: a few random sine components per axis, zero at both ends."""
    if std <= 0 or tau.size == 0:
        return np.zeros((tau.size, 3))
    k = np.arange(1, 4)  # up to 3 half-waves over the pause (slow hand sway)
    amp = rng.normal(0.0, 1.0, (3, k.size)) / k ** 2
    basis = np.sin(np.pi * np.outer(tau, k))  # (n, 4), zero at tau = 0 and 1
    j = basis @ amp.T
    scale = np.sqrt(np.mean(np.sum(amp ** 2, axis=1) / 2) + 1e-12)
    return j * (std / scale)


def _wrist_rotations(rng: np.random.Generator, pos: np.ndarray, rate_hz: float) -> np.ndarray:
    """Palm-down wrist orientation: yaw follows the smoothed reach direction from the person, slight pitch/roll."""
    n = len(pos)
    base_yaw = rng.uniform(-0.3, 0.3) + np.pi / 2  # the forearm points from the person (-y) into the table (+y)
    dx = pos[:, 0] - pos[0, 0]
    yaw = base_yaw - 0.8 * np.tanh(dx / 0.5)
    w = max(1, int(0.3 * rate_hz))
    kern = np.ones(w) / w
    yaw = np.convolve(np.pad(yaw, (w // 2, w - 1 - w // 2), mode="edge"), kern, mode="valid")[:n]
    pitch = np.full(n, np.deg2rad(rng.uniform(10, 30)))
    roll = np.full(n, np.deg2rad(rng.uniform(-10, 10)))
    return Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], axis=1)).as_matrix()


# ---- Polhemus text format ---------------------------------------------------------------------------------

def resample(traj: Trajectory, rate_hz: float) -> Trajectory:
    """The trajectory sampled at a fixed rate (linear positions, slerp rotations) from its first stamp."""
    n = int(np.floor(traj.duration * rate_hz + 1e-9)) + 1
    t = traj.t[0] + np.arange(n) / rate_hz
    pos = np.stack([np.interp(t, traj.t, traj.positions[:, i]) for i in range(3)], axis=1)
    rot = None
    if traj.rotations is not None:
        rot = Slerp(traj.t, Rotation.from_matrix(traj.rotations))(np.clip(t, traj.t[0], traj.t[-1])).as_matrix()
    return Trajectory(t, pos, rot, frame=traj.frame, source=traj.source, t0_ns=traj.t0_ns, meta=dict(traj.meta))


def write_polhemus(path: str | os.PathLike, traj: Trajectory, rate_hz: float = 100.0) -> None:
    """Write `traj` as a Polhemus .traj text file (4x4 matrices at rate_hz, no stamps), atomically.

    Resamples first when the trajectory's spacing is not 1 / rate_hz; the file itself is written by the
    Polhemus reader's module (kinfu_cli.io.polhemus.write_polhemus).
    """
    traj.validate()
    if np.abs(np.diff(traj.t) - 1.0 / rate_hz).max() > 1e-6:
        traj = resample(traj, rate_hz)
    polhemus.write_polhemus(path, traj)
