"""An MCAP file with chunk indexes but no message indexes (some writers leave them out): rosbags finds no message
in it, so the mcap library reads its chunks."""

from __future__ import annotations

import numpy as np
from mcap.reader import make_reader
from mcap.writer import IndexType, Writer

from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording


def test_frames_as_from_the_indexed_file(sample_dir, tmp_path):
    src = sample_dir / "recording.mcap"
    dst = tmp_path / "chunk_index_only.mcap"
    with src.open("rb") as f, dst.open("wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out, index_types=IndexType.CHUNK)
        w.start(profile="ros2", library="kinfu test")
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channels = {cid: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], c.metadata)
                    for cid, c in summary.channels.items()}
        for _, ch, msg in reader.iter_messages():
            w.add_message(channels[ch.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
        w.finish()
    with open_recording(src) as rec:
        want = list(iter_frames(rec))
    with open_recording(dst) as rec:
        got = list(iter_frames(rec))
        assert rec.count_messages("/hand/pose") == rec.topics["/hand/pose"].count > 0
    assert len(got) == len(want) > 0
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_allclose(a.T_world_camera, b.T_world_camera, atol=1e-12)
