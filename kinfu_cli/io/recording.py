"""One streamed reader over MCAP, ROS 1 .bag and ROS 2 bag folders.

`open_recording(path)` detects the container by its first bytes (not its name) and reads it with rosbags'
AnyReader (ROS 1 bags, ROS 2 folders with sqlite3 or mcap storage, MCAP files with cdr messages) or with
the mcap library plus mcap-ros1/ros2 decoders (MCAP files holding ROS 1 encoded messages). Messages are
decoded one at a time while iterating, so memory does not grow with the length of the recording.

Message types are reported in ROS 2 style, `pkg/msg/Name` (rosbags' convention), whatever the container.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
from mcap.exceptions import DecoderNotFoundError
from mcap.reader import make_reader

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.mcap_truncated import TruncatedMcap, is_truncated_mcap
from kinfu_cli.io.messages import normalize_msgtype
from kinfu_cli.io.realsense_bag import sdk_image
from kinfu_cli.io.tf_buffer import TF_TYPES, is_static_tf_topic

_ROS1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_KINDS = "a ROS 1 .bag, an MCAP file or a ROS 2 bag folder (metadata.yaml)"
# message types of which a corrupt message is skipped (and counted) rather than fatal: TF, whose many small
# samples are interpolated across a lost one (not on a static TF topic, see is_static_tf_topic); a topic with
# more than this share corrupt is refused
SKIPPABLE_TYPES = TF_TYPES
MAX_CORRUPT_SHARE = 0.5


@dataclass
class TopicInfo:
    """One topic: message type(s), message count, first/last log stamps (ns) and mean rate (Hz).

    first_ns / last_ns are read on first use (from the ROS 1 index at once; for MCAP and ROS 2 bags by one pass
    over the raw records of the whole recording, without decoding), so opening a recording stays cheap.
    """

    name: str
    msgtype: str
    count: int
    msgtypes: list[str] = field(default_factory=list)
    _first: int | None = field(default=None, repr=False)
    _last: int | None = field(default=None, repr=False)
    _loader: Callable[[], None] | None = field(default=None, repr=False, compare=False)

    def _ensure(self) -> None:
        if self._loader is not None:
            self._loader()

    @property
    def first_ns(self) -> int | None:
        self._ensure()
        return self._first

    @property
    def last_ns(self) -> int | None:
        self._ensure()
        return self._last

    @property
    def rate_hz(self) -> float | None:
        first, last = self.first_ns, self.last_ns
        if self.count < 2 or first is None or last is None or last <= first:
            return None
        return (self.count - 1) / ((last - first) * 1e-9)

    def as_dict(self) -> dict:
        return {"name": self.name, "msgtype": self.msgtype, "msgtypes": self.msgtypes, "count": self.count,
                "first_ns": self.first_ns, "last_ns": self.last_ns, "rate_hz": self.rate_hz}


def _lone_mcap(path: Path) -> Path | None:
    """The one .mcap file of a folder without metadata.yaml: `ros2 bag record` writes the metadata when it stops,
    so a recording that was killed leaves just its storage file."""
    if not path.is_dir() or (path / "metadata.yaml").is_file():
        return None
    files = list(path.glob("*.mcap"))
    return files[0] if len(files) == 1 else None


def detect_format(path: str | os.PathLike) -> str:
    """'bag', 'mcap' or 'ros2' (a bag folder) from the file's first bytes; RecordingError otherwise."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file or folder, expected {_KINDS}")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            if len(list(path.glob("*.db3"))) == 1:
                raise RecordingError(f"{path}: folder has no metadata.yaml (a ROS 2 recording that was cut short?); "
                                     f"`ros2 bag reindex` writes it")
            raise RecordingError(f"{path}: folder has no metadata.yaml, expected a ROS 2 bag folder")
        return "ros2"
    try:
        with path.open("rb") as f:
            head = f.read(16)
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read ({exc.strerror})") from None
    if not head:
        raise RecordingError(f"{path}: empty file, expected {_KINDS}")
    if head.startswith(_ROS1_MAGIC):
        return "bag"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    if len(head) < len(_MCAP_MAGIC) and _MCAP_MAGIC.startswith(head):
        raise RecordingError(f"{path}: MCAP file truncated at byte {len(head)} (within its magic): not a complete "
                             f"MCAP file, nothing to read")
    if head.startswith(_SQLITE_MAGIC) and (path.parent / "metadata.yaml").is_file():
        return "ros2"
    raise RecordingError(f"{path}: not a recording (unknown header {head[:12]!r}), expected {_KINDS}")


class Recording:
    """An open recording. Use as a context manager, or call close()."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.problems: list[str] = []  # what could not be read (a cut-short file), for the run's warnings
        lone = _lone_mcap(self.path)
        if lone is not None:
            self.problems.append(f"{self.path}: ROS 2 bag folder without metadata.yaml (its recording was cut "
                                 f"short?): read its one MCAP file {lone.name}")
            self.path = lone
        self.format = detect_format(self.path)
        if self.format == "ros2" and self.path.is_file():
            self.path = self.path.parent
        self._stack = contextlib.ExitStack()
        self._topics: dict[str, TopicInfo] | None = None
        self._corrupt: dict[str, tuple[int, str]] = {}  # topic -> (most corrupt messages skipped in a pass, line)
        self._backend: _Backend
        try:
            if self.format == "mcap" and is_truncated_mcap(self.path):
                self._backend = TruncatedMcap(self.path)
                self.problems.append(self._backend.problem)
            elif self.format == "mcap" and _mcap_needs_mcap_lib(self.path):
                self._backend = _McapBackend(self.path, self._stack)
            else:
                self._backend = _RosbagsBackend(self.path, self.format, self._stack)
                self.problems += self._backend.storage_problems
        except BaseException:
            self._stack.close()
            raise

    # context manager
    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._stack.close()

    def __repr__(self) -> str:
        return f"Recording({str(self.path)!r}, format={self.format!r})"

    # summary
    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> TopicInfo, sorted by name (counts and types from the container's index/summary)."""
        if self._topics is None:
            infos = self._backend.topic_infos()
            if not self._backend.stamps_known:
                def load() -> None:
                    for info in infos.values():
                        info._loader = None
                    self._backend.fill_stamps(infos)

                for info in infos.values():
                    info._loader = load
            self._topics = dict(sorted(infos.items()))
        return self._topics

    @property
    def start_ns(self) -> int | None:
        """Log stamp (ns) of the earliest message; None for an empty recording."""
        return self._backend.time_range()[0]

    @property
    def end_ns(self) -> int | None:
        """Log stamp (ns) of the latest message; None for an empty recording."""
        return self._backend.time_range()[1]

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) * 1e-9

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    def topics_of_type(self, *msgtypes: str) -> list[str]:
        """Topics carrying any of `msgtypes` (either naming style)."""
        want = {normalize_msgtype(m) for m in msgtypes}
        return [name for name, info in self.topics.items() if want & set(info.msgtypes)]

    def require_topic(self, topic: str, what: str = "topic") -> TopicInfo:
        """TopicInfo of `topic` or RecordingError naming it and listing the available ones."""
        info = self.topics.get(topic)
        if info is None:
            avail = ", ".join(self.topics) or "none"
            raise RecordingError(f"{self.path}: {what} {topic!r} not found{self.cut_note()} (available topics: "
                                 f"{avail})")
        return info

    def cut_note(self) -> str:
        """'' for a whole file; for a truncated one, where it was cut, to say after "not found": what is missing
        may be in the lost part."""
        if not isinstance(self._backend, TruncatedMcap):
            return ""
        return (f" in the readable part of the file: MCAP file truncated (the recording was cut short), only its "
                f"first {self._backend.read_bytes} of {self.path.stat().st_size} bytes could be read")

    # messages
    def typed_messages(self, topics: Iterable[str] | str | None = None, start_ns: int | None = None,
                       end_ns: int | None = None) -> Iterator[tuple[str, str, int, object]]:
        """Yield (topic, msgtype, log stamp ns, decoded message) in log-time order; end_ns is inclusive."""
        if isinstance(topics, str):
            topics = [topics]
        if topics is not None:
            topics = list(topics)
            for t in topics:
                self.require_topic(t)
        read: dict[str, int] = {}
        skipped: dict[str, list[Undecodable]] = {}
        try:
            for topic, msgtype, stamp, msg in self._backend.messages(topics, start_ns, end_ns):
                read[topic] = read.get(topic, 0) + 1
                if isinstance(msg, Undecodable):
                    if msgtype not in SKIPPABLE_TYPES:
                        raise RecordingError(msg.error)
                    if is_static_tf_topic(topic):
                        raise RecordingError(f"{msg.error}; a static TF message is not skipped: its links are "
                                             f"sent once and no other message gives them")
                    skipped.setdefault(topic, []).append(msg)
                    continue
                yield topic, msgtype, stamp, msg
        finally:
            for topic, bad in skipped.items():
                self._note_corrupt(topic, len(bad), read[topic], bad[0])
        for topic, bad in skipped.items():
            if len(bad) > MAX_CORRUPT_SHARE * read[topic]:
                raise RecordingError(f"{bad[0].error}; {len(bad)} of the {read[topic]} messages read on {topic} "
                                     f"cannot be decoded (expected at most {MAX_CORRUPT_SHARE:.0%} corrupt)")

    def _note_corrupt(self, topic: str, n: int, of: int, first: "Undecodable") -> None:
        """Say (once, in problems) that n of `of` messages on `topic` were skipped as corrupt; a later pass over
        the topic replaces the line when it skipped more."""
        seen, line = self._corrupt.get(topic, (0, None))
        if n <= seen:
            return
        text = (f"{self.path}: topic {topic}: skipped {n} corrupt message{'s' if n > 1 else ''} of {of} read "
                f"(the first at t={first.stamp} ns: {first.reason})")
        if line in self.problems:
            self.problems[self.problems.index(line)] = text
        else:
            self.problems.append(text)
        self._corrupt[topic] = (n, text)

    def messages(self, topics: Iterable[str] | str | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[tuple[str, int, object]]:
        """Yield (topic, log stamp ns, decoded message) in log-time order; end_ns is inclusive."""
        for topic, _, stamp, msg in self.typed_messages(topics, start_ns, end_ns):
            yield topic, stamp, msg

    def count_messages(self, topic: str, start_ns: int | None = None, end_ns: int | None = None) -> int:
        """Messages on `topic` with log stamps in [start_ns, end_ns] (None: open), read without decoding them."""
        if topic not in self.topics:
            return 0
        if start_ns is None and end_ns is None:
            return self.topics[topic].count
        if start_ns is not None and end_ns is not None and start_ns > end_ns:
            return 0
        return self._backend.count(topic, start_ns, end_ns)

    def first_message(self, topic: str) -> object | None:
        for _, _, msg in self.messages([topic]):
            return msg
        return None


def open_recording(path: str | os.PathLike) -> Recording:
    """Open a ROS 1 .bag, MCAP file or ROS 2 bag folder; RecordingError naming the file when it cannot."""
    return Recording(path)


@dataclass
class Undecodable:
    """What a backend yields in place of a message it cannot decode: Recording.typed_messages skips it (counted)
    for SKIPPABLE_TYPES and raises `error` otherwise."""

    stamp: int
    reason: str
    error: str


# ------------------------------------------------------------------------------------------- backends
class _Backend(Protocol):
    """What a container backend (rosbags AnyReader, mcap) provides to Recording."""

    stamps_known = False  # True when topic_infos() fills first/last stamps itself

    def topic_infos(self) -> dict[str, TopicInfo]: ...

    def fill_stamps(self, infos: dict[str, TopicInfo]) -> None: ...

    def time_range(self) -> tuple[int | None, int | None]: ...

    def messages(self, topics, start_ns, end_ns) -> Iterator[tuple[str, str, int, object]]: ...

    def count(self, topic: str, start_ns: int | None, end_ns: int | None) -> int: ...


def _short_text(exc: BaseException) -> str:
    text = " ".join(str(a) for a in exc.args) or type(exc).__name__
    text = text.replace("\n", " ").strip()
    return text[:200] + "..." if len(text) > 200 else text


def _read_error(path: Path, exc: BaseException, kind: str) -> RecordingError:
    text = _short_text(exc)
    hint = "; `rosbag reindex` repairs a bag whose recording was cut short" if kind == "ROS 1 bag" else ""
    return RecordingError(f"{path}: cannot read {kind} ({text}); the file may be truncated or corrupt{hint}")


_KIND_NAMES = {"bag": "ROS 1 bag", "ros2": "ROS 2 bag", "mcap": "MCAP file"}


class _RosbagsBackend(_Backend):
    def __init__(self, path: Path, fmt: str, stack: contextlib.ExitStack):
        # rosbags takes a good part of a second to import: only when a recording is opened
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self.fmt = fmt
        self.kind = _KIND_NAMES[fmt]
        self.sdk_trailer: set[int] = set()  # connections of RealSense SDK images with depth_units appended
        open_path = path
        # AnyReader picks the reader by the suffix (.bag: ROS 1, else ROS 2 / MCAP); the format was detected by
        # the first bytes: a file named otherwise is opened through a symlink with the right suffix
        want = {"bag": ".bag", "mcap": ".mcap"}.get(fmt)
        if want is not None and path.is_file() and path.suffix != want:
            tmp = Path(tempfile.mkdtemp(prefix="kinfu-rec-"))
            stack.callback(shutil.rmtree, tmp, True)
            open_path = tmp / (path.name + want)
            open_path.symlink_to(path.resolve())
        try:
            # ROS 2 bags before Iron store no message definitions: decode standard types with Humble's
            self.reader = AnyReader([open_path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            self.reader.open()
        except Exception as exc:  # rosbags raises its own errors, struct/zstd errors, KeyError on bad schemas
            raise _read_error(path, exc, self.kind) from None
        stack.callback(self._close)
        self.storage_counts = self._storage_counts() if fmt == "ros2" else None
        self.storage_span = self._storage_span() if fmt == "ros2" else None
        self.storage_problems = self._count_disagreements() + self._span_disagreement()

    def _storage_counts(self) -> dict[str, int] | None:
        """Messages per topic as a ROS 2 bag's storage files hold them (rosbags reads the sqlite3 database's
        count, an MCAP file's statistics, when it opens them), rather than as metadata.yaml says; None when
        rosbags does not show them."""
        counts: dict[str, int] = {}
        try:
            for storage in self.reader.readers[0].storage.storages:
                for conn in storage.connections:
                    counts[conn.topic] = counts.get(conn.topic, 0) + int(conn.msgcount)
        except Exception:  # another rosbags layout: metadata.yaml's counts stand
            return None
        return counts

    def _count_disagreements(self) -> list[str]:
        """A problem when metadata.yaml's message counts are not what the storage holds (the storage's are used)."""
        if self.storage_counts is None:
            return []
        listed: dict[str, int] = {}
        for conn in self.reader.connections:
            listed[conn.topic] = listed.get(conn.topic, 0) + conn.msgcount
        wrong = [f"{topic} {n} listed, {self.storage_counts.get(topic, 0)} stored" for topic, n in listed.items()
                 if n != self.storage_counts.get(topic, 0)]
        if not wrong:
            return []
        return [f"{self.path}: metadata.yaml's message counts disagree with its storage on {len(wrong)} "
                f"topic{'s' if len(wrong) > 1 else ''} ({'; '.join(wrong)}): the stored counts are used"]

    def _storage_span(self) -> tuple[int | None, int | None] | None:
        """First and last log stamps (ns) a ROS 2 bag's storage files hold (rosbags reads the sqlite3 database's
        MIN/MAX timestamp, an MCAP file's statistics, when it opens them), (None, None) when they hold no message;
        None when rosbags does not show them (metadata.yaml's span stands)."""
        try:
            spans = [(int(st.metadata.start_time), int(st.metadata.end_time) - 1)  # rosbags' end is exclusive
                     for st in self.reader.readers[0].storage.storages if st.metadata.message_count]
        except Exception:  # another rosbags layout
            return None
        return (min(a for a, _ in spans), max(b for _, b in spans)) if spans else (None, None)

    def _span_disagreement(self) -> list[str]:
        """A problem when metadata.yaml's starting_time / duration are not the span the storage holds."""
        if self.storage_span is None or self.storage_span == self._listed_span():
            return []

        def text(span):
            a, b = span
            return "none" if a is None else f"{a} .. {b} ns ({(b - a) * 1e-9:.3f} s)"

        return [f"{self.path}: metadata.yaml's time span (starting_time, duration) disagrees with its storage: "
                f"{text(self._listed_span())} listed, {text(self.storage_span)} stored: the stored span is used"]

    def _listed_span(self) -> tuple[int | None, int | None]:
        if not self.reader.connections or sum(c.msgcount for c in self.reader.connections) == 0:
            return None, None
        try:
            return int(self.reader.start_time), int(self.reader.end_time) - 1  # rosbags' end is exclusive
        except Exception as exc:
            raise _read_error(self.path, exc, self.kind) from None

    def _close(self) -> None:
        with contextlib.suppress(Exception):
            self.reader.close()

    def topic_infos(self) -> dict[str, TopicInfo]:
        infos = _topic_infos((c.topic, c.msgtype, c.msgcount) for c in self.reader.connections)
        if self.storage_counts is not None:  # a ROS 2 bag: what its storage holds, not what metadata.yaml says
            for name, info in infos.items():
                info.count = self.storage_counts.get(name, 0)
        # first/last stamps: from the ROS 1 index at once; else one pass over the raw records, when asked for
        if self.stamps_known:
            reader = self.reader.readers[0]
            for conn in self.reader.connections:
                idx = reader.indexes.get(conn.id) or []
                if idx:
                    _extend(infos[conn.topic], idx[0].time, idx[-1].time)
        return infos

    @property
    def stamps_known(self) -> bool:
        """True for ROS 1 bags (rosbags reads them with its rosbag1 reader), whose index holds every stamp."""
        return self.fmt == "bag"

    def fill_stamps(self, infos: dict[str, TopicInfo]) -> None:
        try:
            for conn, stamp, _ in self.reader.messages():
                _extend(infos[conn.topic], stamp, stamp)
        except Exception as exc:
            raise _read_error(self.path, exc, self.kind) from None

    def time_range(self) -> tuple[int | None, int | None]:
        """A ROS 2 bag's span as its storage holds it, else as the container lists it."""
        return self.storage_span if self.storage_span is not None else self._listed_span()

    def count(self, topic: str, start_ns: int | None, end_ns: int | None) -> int:
        conns = [c for c in self.reader.connections if c.topic == topic]
        lo, hi = -1 if start_ns is None else start_ns, float("inf") if end_ns is None else end_ns
        try:
            if self.stamps_known:  # ROS 1: the index holds every stamp
                indexes = self.reader.readers[0].indexes
                return sum(lo <= i.time <= hi for c in conns for i in indexes.get(c.id) or [])
            if self.fmt == "mcap" and conns:  # the MCAP indexes hold every stamp too
                with self.path.open("rb") as f:
                    indexed = _mcap_indexed_count(f, make_reader(f).get_summary(), topic, start_ns, end_ns)
                if indexed is not None:
                    return indexed
            stop = None if end_ns is None else int(end_ns) + 1
            return sum(1 for _ in self.reader.messages(connections=conns, start=start_ns, stop=stop)) if conns else 0
        except Exception as exc:
            raise _read_error(self.path, exc, self.kind) from None

    def messages(self, topics, start_ns, end_ns):
        conns = self.reader.connections if topics is None else [c for c in self.reader.connections
                                                               if c.topic in set(topics)]
        if not conns:
            return
        stop = None if end_ns is None else int(end_ns) + 1
        try:
            gen = self.reader.messages(connections=conns, start=start_ns, stop=stop)
            for conn, stamp, raw in gen:
                if conn.id in self.sdk_trailer:  # (decoded at once: not first refused)
                    msg = sdk_image(self.reader.deserialize, raw, conn.msgtype)
                    if msg is not None:
                        yield conn.topic, normalize_msgtype(conn.msgtype), stamp, msg
                        continue
                try:
                    msg = self.reader.deserialize(raw, conn.msgtype)
                except Exception as exc:
                    msg = sdk_image(self.reader.deserialize, raw, conn.msgtype) if self.fmt == "bag" else None
                    if msg is not None:  # a RealSense SDK image with its depth_units appended
                        self.sdk_trailer.add(conn.id)
                        yield conn.topic, normalize_msgtype(conn.msgtype), stamp, msg
                        continue
                    reason = _short_text(exc)
                    msg = Undecodable(stamp, reason, f"{self.path}: topic {conn.topic}: cannot decode a "
                                                     f"{conn.msgtype} message at t={stamp} ns ({reason})")
                yield conn.topic, normalize_msgtype(conn.msgtype), stamp, msg
        except RecordingError:
            raise
        except Exception as exc:
            raise _read_error(self.path, exc, self.kind) from None


def _topic_infos(connections: Iterable[tuple[str, str, int]]) -> dict[str, TopicInfo]:
    """TopicInfos from (topic, msgtype, count) per connection; a topic's msgtype is its most frequent one."""
    infos: dict[str, TopicInfo] = {}
    type_counts: dict[str, dict[str, int]] = {}
    for topic, msgtype, count in connections:
        mt = normalize_msgtype(msgtype)
        info = infos.setdefault(topic, TopicInfo(topic, mt, 0))
        info.count += count
        tc = type_counts.setdefault(topic, {})
        tc[mt] = tc.get(mt, 0) + count
    for name, tc in type_counts.items():
        infos[name].msgtypes = sorted(tc, key=lambda m: -tc[m])
        infos[name].msgtype = infos[name].msgtypes[0]
    return infos


def _extend(info: TopicInfo, first: int, last: int) -> None:
    info._first = first if info._first is None else min(info._first, first)
    info._last = last if info._last is None else max(info._last, last)


def _mcap_indexed_count(stream, summary, topic: str, start_ns: int | None, end_ns: int | None) -> int | None:
    """Messages on `topic` with log times in [start_ns, end_ns] from an MCAP file's summary (chunk indexes) and
    message indexes (each chunk's log times, stored uncompressed after it), so no chunk is read or decompressed
    (counting by reading cost a second pass over every chunk the frames were then read from): a chunk inside
    the window counts its index entries, one across its edge the entries in the window. None when the file has
    no chunk index or a chunk the window touches has no message index: the caller reads the messages."""
    if summary is None or not summary.chunk_indexes:
        return None
    lo = -1 if start_ns is None else int(start_ns)
    hi = 2**63 - 1 if end_ns is None else int(end_ns)  # log times as int64 (a float would round them)
    channels = {cid for cid, ch in summary.channels.items() if ch.topic == topic}
    total = 0
    for chunk in summary.chunk_indexes:
        if chunk.message_end_time < lo or chunk.message_start_time > hi:
            continue
        if not chunk.message_index_offsets:
            return None
        inside = lo <= chunk.message_start_time and chunk.message_end_time <= hi
        for cid in channels.intersection(chunk.message_index_offsets):
            # a Message Index record: opcode u8, record length u64, channel id u16, then the entries' byte
            # length u32 and the entries, (log time u64, offset u64) each
            stream.seek(chunk.message_index_offsets[cid] + 1 + 8 + 2)
            size = struct.unpack("<I", stream.read(4))[0]
            if inside:
                total += size // 16
            else:
                times = np.frombuffer(stream.read(size), dtype="<i8")[::2]
                total += int(np.count_nonzero((times >= lo) & (times <= hi)))
    return total


def _mcap_needs_mcap_lib(path: Path) -> bool:
    """True when an MCAP file holds messages rosbags cannot decode (ROS 1 encoding), or chunk indexes without
    message indexes (rosbags then finds no message at all; the mcap library reads the chunks)."""
    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:
        return False  # no summary: let rosbags report (or cope)
    if summary is None:
        return False
    if any(not ci.message_index_offsets for ci in summary.chunk_indexes):
        return True
    return any(ch.message_encoding not in ("cdr", "") for ch in summary.channels.values())


class _McapBackend(_Backend):
    """MCAP via the mcap library with ROS 1 and ROS 2 decoders (for ROS 1 encoded MCAP files, and files whose
    chunks have no message indexes)."""

    def __init__(self, path: Path, stack: contextlib.ExitStack):
        # the ROS message decoders take a fifth of a second to import: only for ROS 1 encoded MCAP files
        from mcap_ros1.decoder import DecoderFactory as Ros1Decoder
        from mcap_ros2.decoder import DecoderFactory as Ros2Decoder

        self.path = path
        self._factories = [Ros1Decoder(), Ros2Decoder()]
        self._decoders: dict[int, Callable[[bytes], object]] = {}
        try:
            self.file = stack.enter_context(path.open("rb"))
            self.reader = make_reader(self.file, decoder_factories=self._factories)
            self.summary = self.reader.get_summary()
        except Exception as exc:
            raise _read_error(path, exc, "MCAP file") from None
        if self.summary is None:
            raise RecordingError(f"{path}: MCAP file has no summary section (written incompletely?)")

    def topic_infos(self) -> dict[str, TopicInfo]:
        s = self.summary
        counts = s.statistics.channel_message_counts if s.statistics else {}
        return _topic_infos((ch.topic, s.schemas[ch.schema_id].name if ch.schema_id in s.schemas else "",
                             int(counts.get(cid, 0))) for cid, ch in s.channels.items())

    def fill_stamps(self, infos: dict[str, TopicInfo]) -> None:
        try:
            for _, ch, msg in self.reader.iter_messages(log_time_order=False):
                _extend(infos[ch.topic], msg.log_time, msg.log_time)
        except Exception as exc:
            raise _read_error(self.path, exc, "MCAP file") from None

    def time_range(self) -> tuple[int | None, int | None]:
        st = self.summary.statistics
        if st is None or st.message_count == 0:
            return None, None
        return int(st.message_start_time), int(st.message_end_time)

    def count(self, topic: str, start_ns: int | None, end_ns: int | None) -> int:
        """From the MCAP indexes (no chunk decompressed); a file without them is read message by message."""
        try:
            indexed = _mcap_indexed_count(self.file, self.summary, topic, start_ns, end_ns)
            if indexed is not None:
                return indexed
            stop = None if end_ns is None else int(end_ns) + 1
            return sum(1 for _ in self.reader.iter_messages(topics=[topic], starting_at=start_ns, ending_before=stop,
                                                            log_time_order=False))
        except Exception as exc:
            raise _read_error(self.path, exc, "MCAP file") from None

    def messages(self, topics, start_ns, end_ns):
        stop = None if end_ns is None else int(end_ns) + 1
        try:
            for schema, ch, msg in self.reader.iter_messages(topics=topics, starting_at=start_ns,
                                                             ending_before=stop, log_time_order=True):
                msgtype = schema.name if schema else ""
                decode = self._decoder(schema, ch)
                try:
                    decoded = decode(msg.data)
                except Exception as exc:  # one corrupt message: Recording decides whether to skip it
                    reason = _short_text(exc)
                    decoded = Undecodable(msg.log_time, reason, f"{self.path}: topic {ch.topic}: cannot decode a "
                                                                f"{msgtype} message at t={msg.log_time} ns ({reason})")
                yield ch.topic, normalize_msgtype(msgtype), msg.log_time, decoded
        except RecordingError:
            raise
        except DecoderNotFoundError as exc:  # not damage: a channel in an encoding no ROS decoder reads
            raise RecordingError(f"{self.path}: a channel of this MCAP file cannot be decoded as ROS 1 or ROS 2 "
                                 f"messages ({_short_text(exc)}); the topics kinfu reads must carry ROS "
                                 f"messages") from None
        except Exception as exc:
            raise _read_error(self.path, exc, "MCAP file") from None

    def _decoder(self, schema, channel) -> Callable[[bytes], object]:
        """The ROS 1 or ROS 2 decoder of a channel; DecoderNotFoundError when neither reads its encoding."""
        decoder = self._decoders.get(channel.id)
        if decoder is None:
            decoder = next((d for f in self._factories
                            if (d := f.decoder_for(channel.message_encoding, schema)) is not None), None)
            if decoder is None:
                raise DecoderNotFoundError(f"no decoder for message encoding {channel.message_encoding}, "
                                           f"schema {schema.name if schema else None}")
            self._decoders[channel.id] = decoder
        return decoder
