"""A corrupt message on a static TF topic is an error naming the file, topic and stamp: its links are sent once,
so skipping it (as a corrupt /tf message is) would leave the tree without them and blame the tree."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.tf_buffer import is_static_tf_topic
from kinfu_cli.io.writers import RecordingWriter
from tests.conftest import one_line_error
from tests.recordings import T0, S


def _static_split(path, static_topic="/tf_static"):
    """Four static messages (the second garbage) and a /tf stream: half a topic corrupt at most, as /tf allows."""
    with RecordingWriter(path) as w:
        conn = w._conn(static_topic, "tf2_msgs/msg/TFMessage")
        for k in range(4):
            if k == 1:
                w._writer.write(conn, T0 + k, b"\xff\xfe\x01garbage")
            else:
                msg = w._type("tf2_msgs/msg/TFMessage")(transforms=[])
                w._write(static_topic, "tf2_msgs/msg/TFMessage", T0 + k, msg)
        for k in range(10):
            w.write_tf(T0 + k * S // 10, [("world", "base_link", np.eye(4))])
    return path


@pytest.mark.parametrize("topic", ["/tf_static", "/robot/tf_static"])
def test_a_corrupt_static_tf_message_is_an_error(tmp_path, topic):
    path = _static_split(tmp_path / "bad.mcap", topic)
    with open_recording(path) as rec:
        with pytest.raises(RecordingError, match=rf"bad\.mcap: topic {topic}: cannot decode .* at t={T0 + 1} ns"
                                                 r".*static TF message is not skipped"):
            list(rec.messages([topic]))
        assert list(rec.messages(["/tf"]))  # the moving /tf stream still reads
    res = CliRunner().invoke(cli, ["info", str(path)])
    one_line_error(res, "bad.mcap", topic, f"t={T0 + 1} ns", "static TF")


def test_static_tf_topic_names():
    assert is_static_tf_topic("/tf_static") and is_static_tf_topic("/ns/tf_static") and is_static_tf_topic("tf_static")
    assert not is_static_tf_topic("/tf") and not is_static_tf_topic("/tf_static_debug")
