"""Label values that do not fit int64 are refused: a uint64 label 2**64-1 wrapped to -1 and its points were
silently scored as not labelled."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.labelled_cloud import LabelsFileError, read_labelled_cloud


@pytest.mark.parametrize("labels", [np.full(5, 2 ** 64 - 1, np.uint64), np.array([0, 1, 2 ** 63 - 1, 1, 0]),
                                    np.array([0, 1, -2 ** 63, 1, 0])])
def test_labels_beyond_int64_are_refused(tmp_path, labels):
    path = tmp_path / "l.npz"
    np.savez(path, points=np.random.default_rng(0).random((5, 3)), labels=labels)
    with pytest.raises(LabelsFileError, match="below 2\\*\\*62") as info:
        read_labelled_cloud(path)
    assert str(path) in str(info.value)


def test_ordinary_unsigned_labels_read(tmp_path):
    path = tmp_path / "l.npz"
    np.savez(path, points=np.zeros((3, 3)), labels=np.array([0, 7, 3], np.uint64))
    assert read_labelled_cloud(path).labels.tolist() == [0, 7, 3]
