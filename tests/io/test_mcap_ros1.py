"""MCAP holding ROS 1 encoded messages (as `mcap convert` writes from a .bag) reads like the bag itself."""

from __future__ import annotations

import numpy as np
from mcap.writer import Writer as McapWriter
from rosbags.highlevel import AnyReader
from recordings import make_recording

from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.tf_buffer import TfBuffer


def bag_to_ros1_mcap(bag, out):
    """Copy every raw ROS 1 message of `bag` into an MCAP file (schema encoding ros1msg, message encoding ros1)."""
    with AnyReader([bag]) as reader, open(out, "wb") as f:
        w = McapWriter(f)
        w.start(profile="ros1")
        channels = {}
        for conn in reader.connections:
            name = conn.msgtype.replace("/msg/", "/")
            schema = w.register_schema(name=name, encoding="ros1msg", data=conn.msgdef.data.encode())
            channels[conn.id] = w.register_channel(topic=conn.topic, message_encoding="ros1", schema_id=schema)
        for conn, stamp, raw in reader.messages():
            w.add_message(channel_id=channels[conn.id], log_time=stamp, publish_time=stamp, data=bytes(raw))
        w.finish()
    return out


def test_ros1_encoded_mcap_reads_like_the_bag(tmp_path):
    bag = make_recording(tmp_path / "r.bag", n=6, hand=True)
    mcap = bag_to_ros1_mcap(bag, tmp_path / "r1.mcap")
    with open_recording(bag) as a, open_recording(mcap) as b:
        assert b.format == "mcap"
        assert {k: (v.msgtype, v.count, v.first_ns, v.last_ns) for k, v in a.topics.items()} == \
               {k: (v.msgtype, v.count, v.first_ns, v.last_ns) for k, v in b.topics.items()}
        fa, fb = list(iter_frames(a)), list(iter_frames(b))
        assert len(fa) == len(fb) == 6
        for x, y in zip(fa, fb):
            assert x.stamp_ns == y.stamp_ns
            np.testing.assert_array_equal(x.depth, y.depth)
            np.testing.assert_array_equal(x.color, y.color)
            np.testing.assert_array_equal(x.K, y.K)
            np.testing.assert_allclose(x.T_world_camera, y.T_world_camera, atol=1e-12)
        ta, tb = TfBuffer.from_recording(a), TfBuffer.from_recording(b)
        assert ta.tree() == tb.tree()
    ha, hb = load_hand_trajectory(bag), load_hand_trajectory(mcap)
    np.testing.assert_array_equal(ha.t, hb.t)
    np.testing.assert_array_equal(ha.positions, hb.positions)
