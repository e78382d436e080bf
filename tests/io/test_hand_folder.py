"""A folder of Polhemus .traj files given where one trajectory is expected, and a file where a data set folder
is expected, are named as such.

Before: `kinfu poi hand-polhemus/pick_and_place` said "folder has no metadata.yaml, expected a ROS 2 bag folder";
`kinfu eval poi hand-polhemus/pick_and_place/user1_cup0.traj` said "no such data set folder" of a file that exists.
"""

import pytest

from kinfu_cli.core.errors import KinfuError
from kinfu_cli.evaluation.poi import find_tasks
from kinfu_cli.io.hand import load_hand_trajectory

SAMPLE = "1 0 0 0.1\n0 1 0 0.2\n0 0 1 0.3\n0 0 0 1\n\n"


def test_a_folder_of_traj_files_is_not_called_a_broken_ros2_bag(tmp_path):
    (tmp_path / "pick_and_place").mkdir()
    (tmp_path / "pick_and_place" / "user1_cup0.traj").write_text(SAMPLE * 3)
    for folder in (tmp_path, tmp_path / "pick_and_place"):
        with pytest.raises(KinfuError) as err:
            load_hand_trajectory(folder)
        msg = str(err.value)
        assert "folder of trajectory files" in msg and "user1_cup0.traj" in msg and "metadata.yaml" not in msg


def test_eval_given_one_traj_file_points_at_its_folder(tmp_path):
    f = tmp_path / "user1_cup0.traj"
    f.write_text(SAMPLE * 3)
    with pytest.raises(KinfuError) as err:
        find_tasks(f)
    assert "a file" in str(err.value) and str(tmp_path) in str(err.value)
    assert "no such" not in str(err.value)
