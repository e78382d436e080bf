"""Counting an MCAP topic's messages in a time window from the file's indexes (no chunk decompressed) gives the
brute-force count, on both MCAP backends, with several chunks, compressed or not, and without message indexes
(read instead, by the mcap library's backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from kinfu_cli.io import recording as recording_module
from kinfu_cli.io.recording import open_recording

NAV2 = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "ros-recordings" / "nav2_turtlebot.mcap"


def _stamps(path) -> dict[str, np.ndarray]:
    """Every message's log time per topic, read message by message (the brute force)."""
    out: dict[str, list[int]] = {}
    with open(path, "rb") as f:
        for _, ch, msg in make_reader(f).iter_messages(log_time_order=False):
            out.setdefault(ch.topic, []).append(msg.log_time)
    return {t: np.array(v) for t, v in out.items()}


def _rewrite(src, dst, *, chunk_size=1 << 20, compression=CompressionType.ZSTD, index_types=IndexType.ALL,
             encoding=None):
    """src's messages in a new MCAP file with other chunking / indexes (encoding: relabel the channels, which
    sends the file to the other backend; counting decodes nothing)."""
    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        w = Writer(g, chunk_size=chunk_size, compression=compression, index_types=index_types)
        w.start(profile="ros1" if encoding == "ros1" else reader.get_header().profile)
        schemas, channels = {}, {}
        for schema, ch, msg in reader.iter_messages():
            if ch.id not in channels:
                if schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                channels[ch.id] = w.register_channel(ch.topic, encoding or ch.message_encoding, schemas[schema.id])
            w.add_message(channels[ch.id], msg.log_time, msg.data, msg.publish_time)
        w.finish()
    return dst


def _windows(stamps: dict[str, np.ndarray], path) -> list[tuple[int | None, int | None]]:
    """Open ends, windows on the chunks' own bounds (whole chunks), on message stamps (edges inclusive) and
    random ones."""
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    every = np.sort(np.concatenate(list(stamps.values())))
    rng = np.random.default_rng(0)
    wins = [(None, None), (None, int(every[len(every) // 2])), (int(every[len(every) // 3]), None),
            (int(every[0]), int(every[-1])), (int(every[-1]) + 1, None), (None, int(every[0]) - 1)]
    wins += [(c.message_start_time, c.message_end_time) for c in chunks]
    if len(chunks) > 1:
        wins.append((chunks[0].message_start_time, chunks[1].message_end_time))
    for _ in range(12):
        a, b = np.sort(rng.choice(every, 2))
        wins.append((int(a), int(b)))
        wins.append((int(a) + int(rng.integers(-3, 4)), int(b) + int(rng.integers(-3, 4))))
    return wins


def _check(path, read_chunks_allowed: bool, monkeypatch):
    stamps = _stamps(path)
    if not read_chunks_allowed:  # the indexes answer: opening a chunk (either backend's reader) fails the test
        import mcap.reader
        import rosbags.rosbag2.storage_mcap

        def no_chunks(*a, **k):
            raise AssertionError("a chunk was read to count")
        monkeypatch.setattr(mcap.reader, "breakup_chunk", no_chunks)
        monkeypatch.setattr(rosbags.rosbag2.storage_mcap, "decompress", no_chunks)
    with open_recording(path) as rec:
        for lo, hi in _windows(stamps, path):
            for topic, t in stamps.items():
                want = int(np.sum((t >= (lo if lo is not None else -1)) & (t <= (hi if hi is not None else 2**63))))
                assert rec.count_messages(topic, lo, hi) == want, (topic, lo, hi)
        assert rec.count_messages("/no/such/topic", 0, 1) == 0


@pytest.mark.parametrize("chunk_size, compression, encoding", [
    (1 << 20, CompressionType.ZSTD, None), (40_000, CompressionType.ZSTD, None), (40_000, CompressionType.NONE, None),
    (40_000, CompressionType.LZ4, "ros1")])  # ros1: the mcap library's backend
def test_indexed_counts_equal_brute_force_without_reading_chunks(sample_dir, tmp_path, monkeypatch, chunk_size,
                                                                  compression, encoding):
    path = _rewrite(sample_dir / "recording.mcap", tmp_path / "r.mcap", chunk_size=chunk_size,
                    compression=compression, encoding=encoding)
    with open(path, "rb") as f:
        assert len(make_reader(f).get_summary().chunk_indexes) > (1 if chunk_size < 1 << 20 else 0)
    with open_recording(path) as rec:
        assert isinstance(rec._backend, recording_module._McapBackend) == (encoding == "ros1")
    _check(path, False, monkeypatch)


def test_sample_recording_counts(sample_dir, monkeypatch):
    _check(sample_dir / "recording.mcap", False, monkeypatch)


def test_without_message_indexes_the_messages_are_read(sample_dir, tmp_path, monkeypatch):
    """(The mcap library's backend: rosbags reads no message at all of such a file.)"""
    path = _rewrite(sample_dir / "recording.mcap", tmp_path / "r.mcap", chunk_size=40_000,
                    index_types=IndexType.CHUNK, encoding="ros1")
    with open(path, "rb") as f:
        assert all(not c.message_index_offsets for c in make_reader(f).get_summary().chunk_indexes)
    _check(path, True, monkeypatch)


@pytest.mark.skipif(not NAV2.exists(), reason="shared data absent")
def test_real_recording_counts(monkeypatch):
    _check(NAV2, False, monkeypatch)
