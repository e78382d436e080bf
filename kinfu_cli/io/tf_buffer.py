"""A TF buffer: static and dynamic transforms, chain lookup between any two frames, interpolation.

Transforms are checked on the way in, as tf2 does: two different non-empty frame names, a finite translation
(within MAX_TRANSLATION_M of the parent's origin), a finite quaternion of unit length within tf2's tolerance
(| |q|^2 - 1 | < QUAT_NORM2_TOLERANCE; accepted ones are normalised). A transform failing a check is not
stored; `add_message` counts it by reason (`rejected`) and by link (`rejected_links`), so a chain broken by
rejected transforms can be reported naming the link. Chains are walked with a loop check: links that form a
cycle raise TransformError naming the frames of the loop instead of walking forever.

A frame may be re-parented over time (tf2 allows it; `parent_changes` notes it). Its transforms, in stamp order
(not the order messages were logged), fall into runs under one parent; a lookup at a stamp goes through the parent
of the run it falls in, and between the last transform of a run and the first of the next it takes the run's last
transform, as tf2 takes the earlier of two samples under different parents (a camera moved from the arm to a
tripod; an object taken from the table by the gripper and put back, any number of times). The tree (`tree`,
`chain`) shows the latest parent; a chain that exists only at some times (before the frame moved onto a parent
linked to nothing) still counts as connected, and the lookups outside those times fail. A frame whose transforms
switch parents at a large share of them (TWO_PARENTS_MIN_SWITCHES, TWO_PARENTS_MIN_SHARE) is published under two
parents at once (two publishers: a broken tree, whose lookups tf2 would flip between the chains); its link is
taken from the parent with the most transforms and `parent_warnings` says so, naming the parents
(`from_recording` puts it in the recording's problems).

Like tf2, a lookup interpolates across any stretch without transforms; one that falls in a gap much longer than
the link's usual spacing (GAP_FACTOR x its median period and more than GAP_MIN_NS) is counted by stamp, and
`gap_warnings` names the link, the gap and how many stamps fell in such gaps.

Each link is stored as `T_parent_child` (maps child coordinates into the parent frame), the convention of
tf2's TransformStamped (header.frame_id = parent, child_frame_id = child). Between two samples of a dynamic
link the translation is interpolated linearly and the rotation by slerp. `lookup_many` evaluates a whole
array of stamps at once (vectorised numpy), `lookup` one stamp.
"""

from __future__ import annotations

import bisect
import math
from array import array
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.errors import TransformError
from kinfu_cli.core.poses import matrix_to_quaternion, quaternion_to_matrix
from kinfu_cli.io.messages import header_frame, normalize_msgtype, time_to_ns

TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
QUAT_NORM2_TOLERANCE = 0.01  # tf2's QUATERNION_NORMALIZATION_TOLERANCE on | |q|^2 - 1 |
MAX_TRANSLATION_M = 1e6  # a link longer than this is corrupt data, not a robot (and would overflow products)
GAP_FACTOR = 10  # a stretch without transforms this many times the link's median period is a gap ...
GAP_MIN_NS = 500_000_000  # ... when it is also longer than this
FOREVER_NS = 2**62  # time_range's bound on a side that only static links hold (a frame moved onto a static parent)


@dataclass
class _Link:
    """One parent -> child link: samples in flat typed arrays (8 + 56 bytes each), sorted on first use."""

    parent: str
    static: bool
    stamps: array = field(default_factory=lambda: array("q"))
    values: array = field(default_factory=lambda: array("d"))  # tx ty tz qx qy qz qw per sample
    _arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    _last_T: np.ndarray | None = None  # matrix of the latest sample, cached
    # gaps (set with the arrays): sorted start and end stamps of stretches much longer than the median period
    gap_starts: list[int] = field(default_factory=list)
    gap_ends: list[int] = field(default_factory=list)
    period_ns: float = 0.0  # median spacing of the samples
    gap_hits: set[int] = field(default_factory=set)  # stamps looked up inside a gap

    def add(self, stamp_ns: int, trans, quat) -> None:
        self.stamps.append(int(stamp_ns))
        self.values.extend(trans)
        self.values.extend(quat)
        self._arrays = None
        self._last_T = None

    def clear(self) -> None:
        self.stamps, self.values, self._arrays, self._last_T = array("q"), array("d"), None, None

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sorted stamps (N,), translations (N,3), quaternions xyzw (N,4); duplicate stamps keep the last."""
        if self._arrays is None:
            st = np.frombuffer(self.stamps, dtype=np.int64).copy()
            vals = np.frombuffer(self.values, dtype=np.float64).reshape(-1, 7)
            order = np.argsort(st, kind="stable")
            st = st[order]
            keep = np.ones(st.shape[0], bool)
            keep[:-1] = st[1:] != st[:-1]  # last of each run of equal stamps
            v = vals[order[keep]]
            self._arrays = (st[keep], np.ascontiguousarray(v[:, :3]), np.ascontiguousarray(v[:, 3:]))
            self._find_gaps(self._arrays[0])
        return self._arrays

    def _find_gaps(self, st: np.ndarray) -> None:
        """Stretches of a dynamic link without samples, much longer than its median period (module docstring)."""
        steps = np.diff(st)
        self.gap_starts, self.gap_ends, self.period_ns = [], [], 0.0
        if self.static or steps.size == 0:
            return
        self.period_ns = float(np.median(steps))
        at = np.flatnonzero(steps > max(GAP_FACTOR * self.period_ns, GAP_MIN_NS))
        self.gap_starts, self.gap_ends = st[at].tolist(), st[at + 1].tolist()

    def note_gaps(self, stamps: np.ndarray) -> None:
        """Remember the stamps (within the link's range) that fall strictly inside one of its gaps: bisect for one
        stamp (the per-frame path), searchsorted for many."""
        if stamps.shape[0] == 1:
            s = int(stamps[0])
            j = bisect.bisect_right(self.gap_starts, s) - 1
            if j >= 0 and self.gap_starts[j] < s < self.gap_ends[j]:
                self.gap_hits.add(s)
            return
        starts, ends = np.asarray(self.gap_starts, dtype=np.int64), np.asarray(self.gap_ends, dtype=np.int64)
        j = np.searchsorted(starts, stamps, side="right") - 1
        jj = np.maximum(j, 0)
        inside = (j >= 0) & (stamps > starts[jj]) & (stamps < ends[jj])
        if inside.any():
            self.gap_hits.update(stamps[inside].tolist())

def slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of quaternions (N,4) at fractions a (N,); shortest arc."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64).copy()
    a = np.asarray(a, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-9
    safe = np.where(small, 1.0, sin_t)
    w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / safe)
    w1 = np.where(small, a, np.sin(a * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def transform_problem(parent: str, child: str, translation: np.ndarray, quat_xyzw: np.ndarray) -> str | None:
    """Why tf2 (and kinfu) would refuse the transform parent -> child, or None when it is fine."""
    if not parent or not child or parent == child:
        return "expected two different, non-empty frame names"
    if not np.all(np.isfinite(translation)):
        return "non-finite translation"
    if float(np.abs(translation).max()) > MAX_TRANSLATION_M:
        return f"translation beyond {MAX_TRANSLATION_M:g} m"
    if not np.all(np.isfinite(quat_xyzw)):
        return "non-finite quaternion"
    norm2 = float(np.dot(quat_xyzw, quat_xyzw))
    if norm2 < 1e-18:
        return "zero quaternion"
    if abs(norm2 - 1.0) >= QUAT_NORM2_TOLERANCE:
        return f"quaternion not of unit length (| |q|^2 - 1 | >= {QUAT_NORM2_TOLERANCE:g})"
    return None


def _fmt_s(ns: int) -> str:
    return f"{ns * 1e-9:.3f}"


# parent changes (in stamp order) that make a frame "under two parents at once" (two publishers alternating at
# nearly every transform) rather than re-parented now and then (a camera moved to a tripod, an object picked and put
# back again and again, two publishers overlapping for a moment at a hand-over): at least this many switches ...
TWO_PARENTS_MIN_SWITCHES = 4
# ... that are also at least this share of the frame's transforms (alternating publishers: ~1; a pick-and-place
# with TF at 100 Hz: 4 switches in thousands of transforms) ...
TWO_PARENTS_MIN_SHARE = 0.1
# ... and where one parent's runs are mostly (half or more) this short: one publisher's messages between the
# other's (an object picked every second with TF at 10 Hz switches at 20 % of its transforms, in runs of ~5 under
# both parents)
TWO_PARENTS_RUN = 2


@dataclass
class _Runs:
    """A re-parented frame's transforms in stamp order, as runs under one parent: run k spans the stamps
    [starts[k], ends[k]] under links[k]."""

    starts: np.ndarray
    ends: np.ndarray
    links: list[_Link]


def is_static_tf_topic(topic: str) -> bool:
    """A static TF topic (/tf_static, /robot/tf_static): its transforms hold for ever, and its few messages each
    carry links sent once and given by no other message (so a corrupt one is never skipped)."""
    return topic.rstrip("/").endswith("tf_static")


class TfBuffer:
    """Static + dynamic TF links; `lookup(target, source, stamp_ns) -> T_target_source`."""

    def __init__(self) -> None:
        self._links: dict[str, _Link] = {}  # child -> its link in the tree (the latest parent's; see _refresh)
        self._parents: dict[str, dict[str, _Link]] = {}  # child -> parent -> link, in the order first seen
        self._multi: set[str] = set()  # children with transforms under more than one parent
        self._stale = False  # a child of _multi got a transform since _refresh
        self._runs: dict[str, _Runs] = {}  # re-parented children (_refresh)
        self._at_once: dict[str, int] = {}  # children under two parents at once -> parent switches (_refresh)
        self.rejected: dict[str, int] = {}  # transforms from messages that were skipped, by reason
        self.rejected_links: dict[tuple[str, str], dict[str, int]] = {}  # (parent, child) -> reason -> count

    # ----------------------------------------------------------------------------------- filling
    def add(self, parent: str, child: str, stamp_ns: int, T: np.ndarray, static: bool = False) -> None:
        """Add T_parent_child at stamp_ns (ignored for static links)."""
        T = np.asarray(T, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise TransformError(f"TF link {parent} -> {child}: transform is not a finite 4x4 matrix")
        self.add_quat(parent, child, stamp_ns, T[:3, 3], matrix_to_quaternion(T[:3, :3]), static)

    def add_quat(self, parent: str, child: str, stamp_ns: int, translation, quat_xyzw, static: bool = False) -> None:
        """Add a link given as translation (3,) and quaternion (x, y, z, w); TransformError (naming the link and
        what is wrong) for a transform that fails the checks of the module docstring."""
        parent, child = _strip(parent), _strip(child)
        trans = np.asarray(translation, dtype=np.float64).reshape(3)
        quat = np.asarray(quat_xyzw, dtype=np.float64).reshape(4)
        reason = transform_problem(parent, child, trans, quat)
        if reason is not None:
            raise TransformError(f"TF link {parent!r} -> {child!r}: {reason}")
        norm = float(np.linalg.norm(quat))
        parents = self._parents.setdefault(child, {})
        link = parents.get(parent)
        if link is not None and static and not link.static:  # a moving link sent once on /tf_static: one more
            static = False  # sample, as tf2 keeps it in the frame's time cache (its /tf samples were thrown away)
        if link is None or link.static != static:
            link = parents[parent] = _Link(parent, static)
        if static:
            link.clear()
        link.add(stamp_ns, trans.tolist(), (quat / norm).tolist())
        if len(parents) > 1:  # which link the tree and each stamp take is settled on the next query
            self._multi.add(child)
            self._stale = True
        else:
            self._links[child] = link

    def _refresh(self) -> None:
        """Settle the frames with transforms under several parents (module docstring): their transforms in stamp
        order, cut into runs under one parent; many switches make a frame one under two parents at once (the
        link with the most transforms, the first seen on a tie), else it is re-parented (the tree takes the last
        run's link, lookups the run of their stamp)."""
        if not self._stale:
            return
        self._stale = False
        self._runs, self._at_once = {}, {}
        for child in self._multi:
            links = list(self._parents[child].values())
            st = np.concatenate([link.arrays()[0] for link in links])
            lab = np.concatenate([np.full(link.arrays()[0].shape[0], i) for i, link in enumerate(links)])
            order = np.argsort(st, kind="stable")
            st, lab = st[order], lab[order]
            change = np.flatnonzero(lab[1:] != lab[:-1]) + 1
            first = np.r_[0, change]
            short = np.diff(np.r_[first, st.size]) <= TWO_PARENTS_RUN
            if (change.size >= TWO_PARENTS_MIN_SWITCHES and change.size >= TWO_PARENTS_MIN_SHARE * st.size
                    and any(np.mean(short[lab[first] == i]) >= 0.5 for i in np.unique(lab))):
                self._at_once[child] = int(change.size)
                self._links[child] = max(links, key=lambda candidate: len(candidate.stamps))
                continue
            last = np.r_[change - 1, st.size - 1]
            self._runs[child] = _Runs(st[first], st[last], [links[i] for i in lab[first]])
            self._links[child] = self._runs[child].links[-1]

    @property
    def parent_changes(self) -> list[tuple[str, str, str]]:
        """(child, old parent, new parent) for each re-parenting, in stamp order; lookups take the parent of
        their stamp (not for frames under two parents at once: parent_warnings)."""
        self._refresh()
        return [(child, a.parent, b.parent) for child, runs in sorted(self._runs.items())
                for a, b in zip(runs.links, runs.links[1:])]

    def parent_warnings(self) -> list[str]:
        """One warning per frame published under two (or more) parents at once: the parents, how many transforms
        each, which one lookups take, and how far apart the parents place the frame."""
        self._refresh()
        out = []
        for child, switches in self._at_once.items():
            parents, used = self._parents[child], self._links[child]
            counts = ", ".join(f"{p!r} ({len(link.stamps)} transforms)" for p, link in parents.items())
            others = [p for p in parents if p != used.parent]
            tie = sum(len(link.stamps) == len(used.stamps) for link in parents.values()) > 1
            text = (f"TF frame {child!r} is published under {len(parents)} parents at once, {counts}, switching "
                    f"between them {switches} times (two publishers of one frame: a broken TF tree); poses through "
                    f"{child!r} take its link from {used.parent!r} (the parent with the most transforms"
                    f"{', the first seen of those' if tie else ''}) and ignore its transforms from "
                    f"{', '.join(repr(p) for p in others)}")
            apart = self._parents_apart(child, others)
            if apart is not None:
                text += f"; the parents place {child!r} up to {apart:.3g} m apart"
            out.append(text)
        return out

    def gap_warnings(self) -> list[str]:
        """One warning per link that lookups interpolated across a gap much longer than its usual spacing (the
        module docstring): the link, the gap(s), and at how many stamps."""
        out = []
        for child, link in ((c, link) for c, parents in self._parents.items() for link in parents.values()):
            if not link.gap_hits:
                continue
            hits = np.fromiter(link.gap_hits, dtype=np.int64)  # each inside a gap (note_gaps)
            starts, ends = np.asarray(link.gap_starts, dtype=np.int64), np.asarray(link.gap_ends, dtype=np.int64)
            j = np.searchsorted(starts, hits, side="right") - 1  # the gap each hit fell in
            gaps = np.unique(j)
            longest = int(gaps[np.argmax(ends[gaps] - starts[gaps])])
            length, start, end = link.gap_ends[longest] - link.gap_starts[longest], starts[longest], ends[longest]
            one = gaps.size == 1
            what = (f"no transform for {length * 1e-9:.3f} s (stamps {_fmt_s(start)} .. {_fmt_s(end)} s)" if one else
                    f"{gaps.size} gaps without transforms, the longest {length * 1e-9:.3f} s (stamps "
                    f"{_fmt_s(start)} .. {_fmt_s(end)} s),")
            out.append(f"TF link {link.parent} -> {child} has {what} though its transforms are usually "
                       f"{link.period_ns * 1e-9:.3g} s apart: {j.size} lookups fell in "
                       f"{'that gap' if one else 'those gaps'} and were interpolated across "
                       f"{'it' if one else 'them'}, so they may be far off")
        return out

    def _parents_apart(self, child: str, others: list[str]) -> float | None:
        """How far apart (m, at most) the taken parent and the ignored ones place `child`, at the ignored
        transforms' stamps that both chains cover (at most 500 of them); None where they cannot be compared."""
        apart = None
        try:
            root = self.chain(child)[-1]
            for other in others:
                link = self._parents[child][other]
                chain = self.chain(other)
                if child in chain or chain[-1] != root:
                    continue
                st, tr, qu = link.arrays()
                keep = np.ones(st.shape[0], bool)
                for rng in (self.time_range(root, child), self.time_range(root, other)):
                    if rng is not None:
                        keep &= (st >= rng[0]) & (st <= rng[1])
                idx = np.flatnonzero(keep)
                if not idx.size:
                    continue
                idx = idx[np.linspace(0, idx.size - 1, min(idx.size, 500)).round().astype(int)]
                stamps = None if link.static else st[idx]
                idx = idx[-1:] if link.static else idx
                taken = self._chain_T(root, child, stamps, 0)[:, :3, 3]
                ignored = self._chain_T(root, other, stamps, 0)
                ignored = ignored[:, :3, :3] @ tr[idx, :, None] + ignored[:, :3, 3:]
                d = float(np.max(np.linalg.norm(taken - ignored[..., 0], axis=1)))
                apart = d if apart is None else max(apart, d)
        except TransformError:
            return apart
        return apart

    def add_message(self, msg: object, static: bool = False) -> int:
        """Add every TransformStamped of a tf2_msgs/TFMessage or tf/tfMessage; returns how many. A transform that
        fails the checks is skipped and counted (`rejected`, `rejected_links`)."""
        n = 0
        for tr in msg.transforms:
            t, r = tr.transform.translation, tr.transform.rotation
            parent, child = _strip(header_frame(tr)), _strip(str(tr.child_frame_id or ""))
            try:
                self.add_quat(parent, child, time_to_ns(tr.header.stamp), (t.x, t.y, t.z), (r.x, r.y, r.z, r.w),
                              static=static)
            except TransformError as exc:  # one bad transform in a recording does not spoil the others
                reason = exc.detail.split(": ", 1)[-1]
                self.rejected[reason] = self.rejected.get(reason, 0) + 1
                per_link = self.rejected_links.setdefault((parent, child), {})
                per_link[reason] = per_link.get(reason, 0) + 1
                continue
            n += 1
        return n

    @classmethod
    def from_recording(cls, rec, topics: Iterable[str] | None = None) -> "TfBuffer":
        """Read every TF topic (/tf, /tf_static and other topics of TF message types) of a Recording.

        A topic whose name ends in 'tf_static' is static.
        """
        buf = cls()
        if topics is None:
            topics = [name for name, info in rec.topics.items()
                      if any(normalize_msgtype(t) in TF_TYPES for t in info.msgtypes)]
        topics = list(topics)
        if not topics:
            return buf
        for topic, msgtype, _, msg in rec.typed_messages(topics):
            if msgtype not in TF_TYPES:
                continue
            buf.add_message(msg, static=is_static_tf_topic(topic))
        problems = getattr(rec, "problems", None)
        for warning in buf.parent_warnings():  # said once, however often the recording's TF is read
            line = f"{rec.path}: {warning}"
            if problems is not None and line not in problems:
                problems.append(line)
        return buf

    # ----------------------------------------------------------------------------------- queries
    def frames(self) -> list[str]:
        self._refresh()
        names = set(self._links)
        names.update(parent for parents in self._parents.values() for parent in parents)  # earlier parents too
        return sorted(names)

    def tree(self) -> dict[str, str]:
        """child -> parent for every link (a re-parented frame: its latest parent)."""
        self._refresh()
        return {child: link.parent for child, link in sorted(self._links.items())}

    def is_static(self, child: str) -> bool:
        """Whether `child`'s link never moves (a re-parented frame: whether all its parents' links are static)."""
        self._refresh()
        child = _strip(child)
        if child in self._runs:
            return all(link.static for link in self._runs[child].links)
        return self._links[child].static

    def link_stamps(self, child: str) -> np.ndarray:
        """Sorted stamps (ns) of the link parent(child) -> child (of a re-parented frame: under every parent)."""
        self._refresh()
        child = _strip(child)
        link = self._links.get(child)
        if link is None:
            raise TransformError(f"frame {child!r} has no parent link in the TF tree")
        if child in self._runs:
            return np.unique(np.concatenate([run.arrays()[0] for run in self._runs[child].links]))
        return link.arrays()[0]

    def time_range(self, target: str, source: str) -> tuple[int, int] | None:
        """[first, last] stamps (ns) over which lookup(target, source) works, the hull of `intervals` (a stamp
        inside may still fall where no chain connects: `covers` tells); None when all links are static."""
        spans = self.intervals(_strip(target), _strip(source))
        if not spans:
            self._connecting_tree(_strip(target), _strip(source))  # TransformError naming the frames
            return 0, -1  # chains, but never with transforms of all their moving links at once
        lo, hi = min(a for a, _ in spans), max(b for _, b in spans)
        return None if (lo, hi) == (-FOREVER_NS, FOREVER_NS) else (lo, hi)

    def dynamic_span(self) -> tuple[int, int] | None:
        """[first, last] stamps (ns) of all moving links' transforms (any frames), None without any: when the TF
        recording ran, which tells a stamp outside it from one where a chain was broken (`covers` false inside)."""
        ends = [(int(st[0]), int(st[-1])) for links in self._parents.values() for link in links.values()
                if not link.static and (st := link.arrays()[0]).size]
        return (min(a for a, _ in ends), max(b for _, b in ends)) if ends else None

    def intervals(self, target: str, source: str) -> list[tuple[int, int]]:
        """The stamp intervals [lo, hi] (ns) where a chain connects the two frames and its moving links have
        transforms, one per stretch between the runs of re-parented frames (+-FOREVER_NS where static links
        hold the chain for ever); [] where no chain ever connects them."""
        self._refresh()
        target, source = _strip(target), _strip(source)
        cuts = sorted({int(t) for runs in self._runs.values() for t in runs.starts[1:]})
        bounds = [-FOREVER_NS, *cuts, FOREVER_NS]
        out: list[tuple[int, int]] = []
        for lo, hi in zip(bounds, bounds[1:]):
            links = self._tree_at(lo)
            try:
                up_src, up_tgt = self._split_path(target, source, links)
            except TransformError:
                continue
            end = hi - 1 if hi < FOREVER_NS else hi
            for child in up_src + up_tgt:
                runs = self._runs.get(child)
                link = links[child]
                if link.static:
                    continue
                st = link.arrays()[0]
                first = int(st[0]) if runs is None or link is runs.links[0] else lo  # a later run holds its last
                last = int(st[-1]) if runs is None or link is runs.links[-1] else end  # transform until the next
                lo, end = max(lo, first), min(end, last)
            if lo <= end and out and out[-1][1] + 1 >= lo:  # continues the last one
                out[-1] = (out[-1][0], max(out[-1][1], end))
            elif lo <= end:
                out.append((lo, end))
        return out

    def covers(self, target: str, source: str, stamps_ns: np.ndarray) -> np.ndarray:
        """bool per stamp: whether a lookup there works (it lies in one of `intervals`)."""
        s = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        ok = np.zeros(s.shape[0], bool)
        for lo, hi in self.intervals(target, source):
            ok |= (s >= lo) & (s <= hi)
        return ok

    def require_chain(self, target: str, source: str) -> None:
        """TransformError (naming both frames) unless a chain of links connects target and source at some time
        (re-parented frames: the tree at the start of any of their runs)."""
        self._connecting_tree(_strip(target), _strip(source))

    def _connecting_tree(self, target: str, source: str) -> dict[str, _Link]:
        """The tree (child -> link) of the latest time at which a chain connects the two frames: the latest tree,
        else the trees at the starts of the re-parented frames' runs, latest first; TransformError of the latest
        tree when none does."""
        self._refresh()
        try:
            self._split_path(target, source)
            return self._links
        except TransformError as latest:
            for stamp in sorted({int(t) for runs in self._runs.values() for t in runs.starts}, reverse=True):
                links = self._tree_at(stamp)
                try:
                    self._split_path(target, source, links)
                except TransformError:
                    continue
                return links
            raise latest

    def _tree_at(self, stamp: int) -> dict[str, _Link]:
        """The tree at `stamp`: each re-parented frame under the parent of its run there (its first run before)."""
        links = dict(self._links)
        for child, runs in self._runs.items():
            links[child] = runs.links[max(int(np.searchsorted(runs.starts, stamp, side="right")) - 1, 0)]
        return links

    def connected(self, target: str, source: str) -> bool:
        """True when a chain of links connects the two frames (at some time)."""
        try:
            self.require_chain(target, source)
        except TransformError:
            return False
        return True

    def lookup(self, target: str, source: str, stamp_ns: int | None = None,
               tolerance_ns: int = 0) -> np.ndarray:
        """T_target_source (4x4) at stamp_ns (None = the latest of each link)."""
        stamps = None if stamp_ns is None else np.array([int(stamp_ns)], dtype=np.int64)
        return self.lookup_many(target, source, stamps, tolerance_ns=tolerance_ns)[0]

    def lookup_many(self, target: str, source: str, stamps_ns: np.ndarray | None,
                    tolerance_ns: int = 0) -> np.ndarray:
        """T_target_source for each stamp: (N,4,4). Stamps within tolerance_ns outside a link's range clamp.
        Stamps inside a gap of a link are counted (gap_warnings) when the whole lookup succeeds."""
        in_gaps: list[tuple[_Link, np.ndarray]] = []
        T = self._chain_T(target, source, stamps_ns, tolerance_ns, in_gaps)
        for link, stamps in in_gaps:
            link.note_gaps(stamps)
        return T

    def _chain_T(self, target: str, source: str, stamps_ns: np.ndarray | None, tolerance_ns: int,
                 in_gaps: list | None = None) -> np.ndarray:
        """lookup_many; the stamps of links that have gaps go to in_gaps (None: not counted). Stamps are grouped by
        the runs re-parented frames are in at them (module docstring), each group looked up along its own tree; a
        stamp between two runs takes the earlier run's last transform."""
        target, source = _strip(target), _strip(source)
        self._refresh()
        if stamps_ns is None or not self._runs:
            return self._tree_T(target, source, stamps_ns, tolerance_ns, in_gaps, self._links, {})
        s = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        timed = list(self._runs.items())
        picks = np.stack([np.maximum(np.searchsorted(runs.starts, s, side="right") - 1, 0) for _, runs in timed], 1)
        keys, group = np.unique(picks, axis=0, return_inverse=True)
        group = group.reshape(-1)
        out = np.empty((s.shape[0], 4, 4))
        for g, key in enumerate(keys.tolist()):
            idx = np.flatnonzero(group == g)
            links, clamped = dict(self._links), {}
            for (child, runs), k in zip(timed, key):
                links[child] = runs.links[k]
                if k < len(runs.links) - 1:  # not the last run: hold its last transform until the next run
                    clamped[child] = np.minimum(s[idx], runs.ends[k])
            out[idx] = self._tree_T(target, source, s[idx], tolerance_ns, in_gaps, links, clamped)
        return out

    def _tree_T(self, target: str, source: str, stamps_ns: np.ndarray | None, tolerance_ns: int,
                in_gaps: list | None, links: dict[str, "_Link"], stamps_of: dict[str, np.ndarray]) -> np.ndarray:
        """_chain_T along the tree `links` (child -> the link its lookups take); stamps_of: other stamps for some
        children's links."""
        n = 1 if stamps_ns is None else int(np.asarray(stamps_ns).reshape(-1).shape[0])
        up_src, up_tgt = self._split_path(target, source, links)
        T_anc_src = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        for child in up_src:  # source upwards: T_anc_src = T_parent_child @ T_anc_src
            T_anc_src = self._edge(links[child], child, stamps_of.get(child, stamps_ns), n, tolerance_ns,
                                   in_gaps) @ T_anc_src
        T_anc_tgt = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        for child in up_tgt:
            T_anc_tgt = self._edge(links[child], child, stamps_of.get(child, stamps_ns), n, tolerance_ns,
                                   in_gaps) @ T_anc_tgt
        return _inv(T_anc_tgt) @ T_anc_src

    # ----------------------------------------------------------------------------------- internals
    def chain(self, frame: str, links: dict[str, "_Link"] | None = None) -> list[str]:
        """`frame`, its parent, the parent's parent, ... up to a root (in the tree `links`, default the latest);
        TransformError naming the frames when the links form a loop."""
        if links is None:
            self._refresh()
            links = self._links
        frame = _strip(frame)
        chain = [frame]
        seen = {frame: 0}
        while chain[-1] in links:
            parent = links[chain[-1]].parent
            if parent in seen:
                loop = chain[seen[parent]:] + [parent]
                raise TransformError(f"TF links form a loop: {' -> '.join(reversed(loop))} (parent -> child)")
            seen[parent] = len(chain)
            chain.append(parent)
        return chain

    def loops(self) -> list[list[str]]:
        """Each loop of links once, as its frames from parent to child (the first again at the end)."""
        self._refresh()
        found: list[list[str]] = []
        for links in [self._links] + [self._tree_at(int(t)) for runs in self._runs.values() for t in runs.starts]:
            for loop in self._loops_in(links):
                if loop not in found:
                    found.append(loop)
        return found

    def _loops_in(self, links: dict[str, _Link]) -> list[list[str]]:
        """The loops of the tree `links`, each once, from parent to child (the first frame again at the end)."""
        found: list[list[str]] = []
        done: set[str] = set()
        for start in sorted(links):
            path: dict[str, int] = {}
            frame = start
            while frame in links and frame not in done and frame not in path:
                path[frame] = len(path)
                frame = links[frame].parent
            if frame in path:  # walked into this walk's own path: a new loop
                order = list(path)
                loop = order[path[frame]:][::-1]
                i = loop.index(min(loop))
                loop = loop[i:] + loop[:i]
                found.append(loop + [loop[0]])
            done.update(path)
        return found

    def broken_chain(self, frame: str, world: str) -> str:
        """Why the chain of `frame` does not reach `world`: where it stops and which transforms naming that
        frame were rejected (for error messages)."""
        chain = self.chain(frame)
        top = chain[-1]
        text = (f"the TF chain of {frame!r} ({' -> '.join(chain)}) stops at {top!r}, which has no parent link, "
                f"so it does not reach {world!r}")
        if (bad := self.rejected_link(top)) is not None:
            text += f"; transforms {bad[0]} were rejected ({bad[1]})"
        return text

    def rejected_link(self, frame: str) -> tuple[str, str] | None:
        """The first link naming `frame` that had transforms rejected, for error messages: ("'parent' ->
        'child'", "count x reason; ..."), or None."""
        for (p, c), reasons in self.rejected_links.items():
            if frame in (p, c):
                return f"{p!r} -> {c!r}", "; ".join(f"{n} x {r}" for r, n in reasons.items())
        return None

    def _split_path(self, target: str, source: str, links: dict[str, "_Link"] | None = None
                    ) -> tuple[list[str], list[str]]:
        known = set(self.frames())
        for name, role in ((source, "source"), (target, "target")):
            if name not in known:
                avail = ", ".join(sorted(known)) or "none"
                raise TransformError(f"TF lookup {target} <- {source}: {role} frame {name!r} is not in the TF tree "
                                     f"(frames: {avail})")
        a_src, a_tgt = self.chain(source, links), self.chain(target, links)
        common = next((f for f in a_src if f in set(a_tgt)), None)
        if common is None:
            raise TransformError(f"TF lookup {target} <- {source}: no chain of links connects the two frames "
                                 f"(roots {a_tgt[-1]!r} and {a_src[-1]!r})")
        return a_src[: a_src.index(common)], a_tgt[: a_tgt.index(common)]

    def _edge(self, link: "_Link", child: str, stamps_ns: np.ndarray | None, n: int, tolerance_ns: int,
              in_gaps: list | None = None) -> np.ndarray:
        st, tr, qu = link.arrays()
        if link.static or stamps_ns is None:
            if link._last_T is None:
                T = np.eye(4)
                T[:3, :3] = quaternion_to_matrix(qu[-1])
                T[:3, 3] = tr[-1]
                link._last_T = T
            return np.broadcast_to(link._last_T, (n, 4, 4))
        s = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        lo, hi = st[0], st[-1]
        if s.shape[0] == 1 and lo - tolerance_ns <= s[0] <= hi + tolerance_ns:
            if in_gaps is not None and link.gap_starts:
                in_gaps.append((link, s))
            return _edge_one(st, tr, qu, int(s[0]))[None]
        bad = (s < lo - tolerance_ns) | (s > hi + tolerance_ns)
        if bad.any():
            t = int(s[np.flatnonzero(bad)[0]])
            raise TransformError(f"TF link {link.parent} -> {child}: time {_fmt_s(t)} s is outside the buffered "
                                 f"range [{_fmt_s(int(lo))}, {_fmt_s(int(hi))}] s")
        s = np.clip(s, lo, hi)
        if in_gaps is not None and link.gap_starts:
            in_gaps.append((link, s))
        if st.shape[0] == 1:
            trans, quat = np.repeat(tr, s.shape[0], 0), np.repeat(qu, s.shape[0], 0)
        else:
            i1 = np.clip(np.searchsorted(st, s, side="right"), 1, st.shape[0] - 1)
            i0 = i1 - 1
            a = (s - st[i0]).astype(np.float64) / (st[i1] - st[i0]).astype(np.float64)
            a = np.clip(a, 0.0, 1.0)
            trans = tr[i0] + a[:, None] * (tr[i1] - tr[i0])
            quat = slerp(qu[i0], qu[i1], a)
        T = np.zeros((s.shape[0], 4, 4))
        T[:, :3, :3] = quaternion_to_matrix(quat)
        T[:, :3, 3] = trans
        T[:, 3, 3] = 1.0
        return T


def _edge_one(st: np.ndarray, tr: np.ndarray, qu: np.ndarray, s: int) -> np.ndarray:
    """One stamp of one link (within its range), in scalar arithmetic: the per-frame path of iter_frames."""
    n = st.shape[0]
    i1 = min(max(bisect.bisect_right(st, s), 1), n - 1) if n > 1 else 0
    i0 = max(i1 - 1, 0)
    span = int(st[i1]) - int(st[i0])
    a = 0.0 if span <= 0 else min(max((s - int(st[i0])) / span, 0.0), 1.0)
    t = tr[i0] + a * (tr[i1] - tr[i0])
    q0, q1 = qu[i0].tolist(), qu[i1].tolist()
    dot = sum(x * y for x, y in zip(q0, q1))
    if dot < 0:
        q1, dot = [-x for x in q1], -dot
    if dot > 1.0 - 1e-12:
        w0, w1 = 1.0 - a, a
    else:
        theta = math.acos(min(dot, 1.0))
        sin_t = math.sin(theta)
        w0, w1 = math.sin((1 - a) * theta) / sin_t, math.sin(a * theta) / sin_t
    x, y, z, w = (w0 * u + w1 * v for u, v in zip(q0, q1))
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), t[0]],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), t[1]],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), t[2]],
        [0.0, 0.0, 0.0, 1.0],
    ])


def _inv(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (...,4,4)."""
    R = T[..., :3, :3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def _strip(frame: str) -> str:
    """tf2 frame ids have no leading slash; ROS 1 data often has one."""
    return str(frame).lstrip("/")
