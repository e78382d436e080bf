"""claim_output: an existing file inside an input folder is an input (a fuse folder's mesh.ply, a ROS 2 bag's
metadata.yaml), refused even with force; a new file there is allowed."""

from __future__ import annotations

import pytest

from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.ownership import claim_output


def test_an_existing_file_of_an_input_folder_is_refused_even_with_force(tmp_path):
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("x")
    with pytest.raises(KinfuError) as err:
        claim_output(folder / "metadata.yaml", [folder], force=True, parameter="out")
    assert err.value.parameter == "out" and "input folder" in str(err.value)
    assert claim_output(folder / "new.json", [folder], force=False) == folder / "new.json"
