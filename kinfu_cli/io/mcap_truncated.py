"""An MCAP file cut short (the recorder was killed, the disk filled): read up to its last whole chunk.

Such a file has no footer and no summary, so neither rosbags nor the mcap library's seeking reader opens it. The
records before the cut are intact: this backend streams them (mcap's StreamReader), once to learn the topics,
counts and stamps, and again for each pass over the messages, sorting each chunk by log time, and stops
quietly where the file stops. What was lost is said in `problem` (the recording reports it as a warning).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from kinfu_cli.core.errors import RecordingError

MCAP_MAGIC = b"\x89MCAP0\r\n"


def is_truncated_mcap(path: Path) -> bool:
    """An MCAP file (its first bytes say so) whose last 8 bytes are not the closing magic."""
    try:
        with path.open("rb") as f:
            head = f.read(8)
            f.seek(0, 2)
            size = f.tell()
            if head != MCAP_MAGIC:
                return False
            if size < 16:  # the magic and hardly more: cut within its first record
                return True
            f.seek(size - 8)
            return f.read(8) != MCAP_MAGIC
    except OSError:
        return False


class TruncatedMcap:
    """The messages of a truncated MCAP file up to its last whole record: the Recording backend protocol."""

    stamps_known = True

    def __init__(self, path: Path):
        from mcap_ros1.decoder import DecoderFactory as Ros1Decoder
        from mcap_ros2.decoder import DecoderFactory as Ros2Decoder

        self.path = path
        self._factories = [Ros2Decoder(), Ros1Decoder()]
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        stamps: dict[int, list[int]] = {}
        self.read_bytes = 0
        for rec in self._records():
            if isinstance(rec, Message):
                stamps.setdefault(rec.channel_id, []).append(rec.log_time)
        self.stamps = {cid: np.sort(np.asarray(s, dtype=np.int64)) for cid, s in stamps.items()}
        size = path.stat().st_size
        n = sum(len(s) for s in self.stamps.values())
        self.problem = (f"{path}: MCAP file truncated (no footer: the recording was cut short): read {n} messages "
                        f"from the first {self.read_bytes} of {size} bytes; the rest is lost")
        if not self.channels:
            raise RecordingError(f"{path}: MCAP file truncated at byte {size} (no footer) within its first records "
                                 f"or chunk: not a complete MCAP file, nothing whole to read")

    def _records(self) -> Iterator[object]:
        """Schema, Channel and Message records in file order (each chunk's messages by log time), up to the cut."""
        with self.path.open("rb") as f:
            reader = StreamReader(f, emit_chunks=True, record_size_limit=1 << 31)
            it = reader.records
            while True:
                try:
                    rec = next(it)
                except StopIteration:
                    return
                except Exception:  # the cut: a record or chunk that does not end
                    return
                self.read_bytes = f.tell()
                inner = [rec]
                if isinstance(rec, Chunk):
                    try:
                        inner = breakup_chunk(rec, validate_crc=False)
                    except Exception:
                        return
                    inner.sort(key=lambda r: r.log_time if isinstance(r, Message) else -1)
                for r in inner:
                    if isinstance(r, Schema):
                        self.schemas[r.id] = r
                    elif isinstance(r, Channel):
                        self.channels[r.id] = r
                    yield r

    # ---- the Recording backend protocol --------------------------------------------------------------
    def _type(self, cid: int) -> str:
        ch = self.channels[cid]
        schema = self.schemas.get(ch.schema_id)
        return schema.name if schema is not None else ""

    def topic_infos(self) -> dict:
        from kinfu_cli.io.recording import _extend, _topic_infos

        infos = _topic_infos((ch.topic, self._type(cid), len(self.stamps.get(cid, ())))
                             for cid, ch in self.channels.items())
        for cid, s in self.stamps.items():
            if len(s):
                _extend(infos[self.channels[cid].topic], int(s[0]), int(s[-1]))
        return infos

    def fill_stamps(self, infos: dict) -> None:
        return None

    def time_range(self) -> tuple[int | None, int | None]:
        firsts = [int(s[0]) for s in self.stamps.values() if len(s)]
        lasts = [int(s[-1]) for s in self.stamps.values() if len(s)]
        return (min(firsts), max(lasts)) if firsts else (None, None)

    def count(self, topic: str, start_ns: int | None, end_ns: int | None) -> int:
        lo = -(1 << 62) if start_ns is None else int(start_ns)
        hi = (1 << 62) if end_ns is None else int(end_ns)
        return sum(int(np.searchsorted(s, hi, "right") - np.searchsorted(s, lo, "left"))
                   for cid, s in self.stamps.items() if self.channels[cid].topic == topic)

    def messages(self, topics, start_ns, end_ns):
        from kinfu_cli.io.messages import normalize_msgtype

        want = None if topics is None else set(topics)
        decoders: dict[int, object] = {}
        for rec in self._records():
            if not isinstance(rec, Message):
                continue
            ch = self.channels.get(rec.channel_id)
            if ch is None or (want is not None and ch.topic not in want):
                continue
            if (start_ns is not None and rec.log_time < start_ns) or (end_ns is not None and rec.log_time > end_ns):
                continue
            if rec.channel_id not in decoders:
                decoders[rec.channel_id] = self._decoder(ch)
            try:
                msg = decoders[rec.channel_id](rec.data)
            except Exception as exc:  # one corrupt message: Recording decides whether to skip it
                from kinfu_cli.io.recording import Undecodable, _short_text

                reason = _short_text(exc)
                msg = Undecodable(rec.log_time, reason, f"{self.path}: topic {ch.topic}: cannot decode a message at "
                                                        f"t={rec.log_time} ns ({reason})")
            yield ch.topic, normalize_msgtype(self._type(rec.channel_id)), rec.log_time, msg

    def _decoder(self, ch: Channel):
        schema = self.schemas.get(ch.schema_id)
        for factory in self._factories:
            dec = factory.decoder_for(ch.message_encoding, schema)
            if dec is not None:
                return dec
        raise RecordingError(f"{self.path}: topic {ch.topic}: messages in encoding {ch.message_encoding!r} cannot "
                             f"be decoded as ROS 1 or ROS 2 messages")
