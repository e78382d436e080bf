"""Which files kinfu wrote, so it replaces only its own outputs and never an input or a user's file.

Every file or folder kinfu writes through `core.atomic` is recorded in a manifest, `.kinfu-manifest.json`,
in the folder that holds it: name -> size and modification time (ns) as written. A path is kinfu's when
its folder's manifest lists it with the same size and time (a file the user replaced or edited since is
theirs again), or, for a folder output, when it holds a manifest of its own. `claim_output` is called
before any work: it refuses an output that is an input, lies above an input, is empty, or exists without
being kinfu's (unless `force`).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from kinfu_cli.core.errors import KinfuError

MANIFEST = ".kinfu-manifest.json"


class ForeignOutputError(KinfuError):
    """The output path exists and kinfu did not write it; `force` would write over it."""


def _read_manifest(folder: Path) -> dict[str, dict]:
    try:
        doc = json.loads((folder / MANIFEST).read_text())
    except (OSError, ValueError, RecursionError):  # unreadable or damaged: nothing is recorded as kinfu's
        return {}
    files = doc.get("files") if isinstance(doc, dict) else None
    return files if isinstance(files, dict) else {}


def _stat_entry(path: Path) -> dict:
    st = path.stat()
    return {"size": st.st_size if path.is_file() else None, "mtime_ns": st.st_mtime_ns,
            "kind": "folder" if path.is_dir() else "file"}


def record_written(path: str | os.PathLike) -> None:
    """Add `path` (just written by kinfu) to its folder's manifest; the manifest is replaced atomically.

    Best effort: a folder where the manifest cannot be written only loses the ownership record."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    files = _read_manifest(folder)
    with contextlib.suppress(OSError):
        files[path.name] = _stat_entry(path)
        _write_manifest(folder, files)


def _write_manifest(folder: Path, files: dict[str, dict]) -> None:
    """Replace `folder`'s manifest atomically; best effort (an unwritable folder only loses the record)."""
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f"{MANIFEST}.", suffix=".part", dir=folder)
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # mkstemp makes 0600: a colleague's run could not tell kinfu's files apart
        with os.fdopen(fd, "w") as fh:
            json.dump({"written_by": "kinfu", "files": files}, fh, indent=1, sort_keys=True)
        os.replace(tmp, folder / MANIFEST)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def record_tree(folder: str | os.PathLike) -> None:
    """Record every entry under `folder` (just written by kinfu, whatever library wrote each file) in the
    manifest of the folder that holds it, so a later run can tell kinfu's files from a user's at any depth.

    Best effort, like `record_written`."""
    folder = Path(folder)
    for sub in [p for p in folder.rglob("*") if p.is_dir() and not p.is_symlink()] + [folder]:
        files = _read_manifest(sub)
        entries = [e for e in sub.iterdir() if e.name != MANIFEST and not e.name.startswith(f"{MANIFEST}.")]
        if all(e.name in files for e in entries):
            continue
        with contextlib.suppress(OSError):
            for e in entries:
                files.setdefault(e.name, _stat_entry(e))
            _write_manifest(sub, files)


def written_by_kinfu(path: str | os.PathLike) -> bool:
    """True when kinfu wrote `path` and nobody changed it since (see the module docstring)."""
    path = Path(path)
    if path.is_dir() and (path / MANIFEST).is_file():
        return True
    entry = _read_manifest(path.parent if str(path.parent) else Path(".")).get(path.name)
    if not isinstance(entry, dict) or not path.exists():
        return False
    now = _stat_entry(path)
    return entry.get("kind") == now["kind"] and (now["kind"] == "folder" or (
        entry.get("size") == now["size"] and entry.get("mtime_ns") == now["mtime_ns"]))


def changed_since_written(path: str | os.PathLike) -> list[str]:
    """The files kinfu recorded at `path` (a file, or every file of a kinfu folder, at any depth where a manifest
    records them) that still exist but were changed since (size or time): a user's now, relative to `path`'s
    folder."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir() and not path.is_symlink():
        if not (path / MANIFEST).is_file():
            return []
        out = []
        for name, entry in sorted(_read_manifest(path).items()):
            sub = path / name
            if isinstance(entry, dict) and entry.get("kind") == "folder" and sub.is_dir():
                out += [f"{path.name}/{c}" for c in changed_since_written(sub)]
            elif isinstance(entry, dict) and sub.is_file() and not written_by_kinfu(sub):
                out.append(f"{path.name}/{name}")
        return out
    entry = _read_manifest(folder).get(path.name)
    return [path.name] if isinstance(entry, dict) and path.is_file() and not written_by_kinfu(path) else []


def owned_entries(folder: str | os.PathLike) -> set[str]:
    """Names inside a kinfu output folder that kinfu wrote (the manifest itself included)."""
    folder = Path(folder)
    return {n for n in _read_manifest(folder) if written_by_kinfu(folder / n)} | {MANIFEST}


def _inside(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def claim_output(output: str | os.PathLike | None, inputs: Iterable[str | os.PathLike] = (), *,
                 force: bool = False, parameter: str = "output") -> Path:
    """Check that kinfu may write `output`, before any work is done; returns it as a Path.

    Refused always: an empty path, the current folder or one above it, an output that is one of `inputs`,
    a folder that holds one of them (replacing it would destroy the input), or an existing file inside an input
    folder (a fuse folder, a ROS 2 bag, a ground-truth folder: the command may read it). Refused unless `force`: an existing path kinfu did not write.
    """
    if output is None or str(output).strip() == "":
        raise KinfuError("expected a path, got an empty one", parameter=parameter)
    out = Path(output)
    real = Path(os.path.realpath(out))
    if _inside(Path(os.getcwd()).resolve(), real):
        raise KinfuError(f"{out} is the current folder or holds it; name a new or kinfu-written path",
                         parameter=parameter)
    for inp in inputs:
        if inp is None or str(inp) == "":
            continue
        src = Path(os.path.realpath(inp))
        if real == src:
            raise KinfuError(f"{out} is also an input; choose another output path", parameter=parameter)
        if _inside(src, real):
            raise KinfuError(f"{out} contains the input {inp}; writing it would replace the input",
                             parameter=parameter)
        if src.is_dir() and _inside(real, src) and real.is_file():  # e.g. eval fusion out/fuse -o out/fuse/mesh.ply
            raise KinfuError(f"{out} is a file of the input folder {inp}; writing it would replace the input; "
                             f"choose another output path", parameter=parameter)
    if out.exists() and not force and not written_by_kinfu(out):
        what = "folder" if out.is_dir() else "file"
        raise ForeignOutputError(f"{out}: an existing {what} that kinfu did not write; choose another path",
                                 parameter=parameter)
    if out.is_file() and not force and _part_of_folder_output(real):  # grasp --plot seg/segments.ply
        raise ForeignOutputError(f"{out} is a file of the kinfu output folder {out.parent}, written with it as one "
                                 f"result (replacing it alone would break that result); choose another path",
                                 parameter=parameter)
    return out


def _part_of_folder_output(path: Path) -> bool:
    """Whether the file `path` lies in a folder that kinfu wrote whole (its parent's manifest lists the folder)."""
    entry = _read_manifest(path.parent.parent).get(path.parent.name)
    return isinstance(entry, dict) and entry.get("kind") == "folder"
