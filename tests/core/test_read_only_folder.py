"""A folder kinfu cannot write into (read-only, another user's, a full disk) is one line naming the folder,
exit 2, no traceback, for single commands and `kinfu batch`. The sandbox runs as root (chmod stops nothing), so
the denial is simulated where kinfu's atomic writer asks the system for its temporary file or folder.

Before: `kinfu poi REC -o RO/pois.json` said `kinfu: error: RO/.pois.3k9x_a1b.part.json: Permission denied` (the
temporary file, not the folder); `kinfu batch` with its lock taken but manifest.json not writable did the same.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.batch.engine import Engine
from kinfu_cli.cli import cli
from kinfu_cli.core.atomic import write_json
from kinfu_cli.core.errors import KinfuError


@pytest.fixture
def read_only(tmp_path, monkeypatch) -> Path:
    """A folder in which no temporary file or folder can be made, nor anything renamed into."""
    ro = tmp_path / "ro"
    ro.mkdir()

    def denied(path) -> bool:
        return path is not None and Path(os.path.abspath(path)).is_relative_to(ro)

    def guard(real, where):
        def call(*args, **kwargs):
            path = where(args, kwargs)
            if denied(path):
                raise PermissionError(13, "Permission denied", os.path.join(str(path), ".x.3k9x_a1b.part"))
            return real(*args, **kwargs)
        return call

    monkeypatch.setattr(tempfile, "mkstemp", guard(tempfile.mkstemp, lambda a, k: k.get("dir")))
    monkeypatch.setattr(tempfile, "mkdtemp", guard(tempfile.mkdtemp, lambda a, k: k.get("dir")))
    monkeypatch.setattr(os, "replace", guard(os.replace, lambda a, k: os.path.dirname(a[1])))
    return ro


def test_the_atomic_writer_names_the_folder(read_only):
    with pytest.raises(KinfuError, match=f"^{read_only}: cannot write into this folder \\(Permission denied\\)$"):
        write_json(read_only / "x.json", {})
    assert list(read_only.iterdir()) == []


def test_a_single_command_is_one_line_naming_the_folder(read_only, sample_dir):
    res = CliRunner().invoke(cli, ["poi", str(sample_dir / "recording.mcap"), "-o", str(read_only / "pois.json")])
    # refused before the work now (claim_output makes and removes a probe there), naming the folder all the same
    line = one_line_error(res, f"cannot write into the folder {read_only} (Permission denied)")
    assert ".part" not in line and ".kinfu-probe" not in line


def test_batch_is_one_line_naming_the_folder(read_only, sample_dir, tmp_path, monkeypatch):
    """The lock is taken (the lock file exists from an earlier run), manifest.json cannot be written."""
    out = read_only / "batch"
    out.mkdir()
    (out / ".kinfu-batch.lock").write_text("kinfu batch lock pid 1\n")
    plan = tmp_path / "plan.toml"
    plan.write_text(f'output = "{out}"\nstages = ["poi"]\nrecordings = ["{sample_dir / "recording.mcap"}"]\n')
    client = SimpleNamespace(submit=lambda *a, key, pure: SimpleNamespace(key=key), cancel=lambda f: None,
                             close=lambda: None)  # no cluster: the run stops before any task result is read
    monkeypatch.setattr("kinfu_cli.commands.batch.connect", lambda *a: Engine(client, None, "test"))
    res = CliRunner().invoke(cli, ["batch", str(plan), "--quiet"])
    one_line_error(res, f"cannot write into the folder {out} (Permission denied)")
    assert sorted(p.name for p in out.iterdir()) == [".kinfu-batch.lock"]
