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
import fcntl
import json
import os
import re
import shutil
import tempfile
import threading
import time
from collections.abc import Iterable
from pathlib import Path

from kinfu_cli.core.errors import KinfuError

MANIFEST = ".kinfu-manifest.json"


class ForeignOutputError(KinfuError):
    """The output path exists and kinfu did not write it; `force` would write over it."""


# folders this thread holds a lock on (lock_folder): flock conflicts between two opens in one process too, so a
# thread takes a lock it holds again without waiting; another thread (a Dask worker's) waits for it
_HELD = threading.local()


@contextlib.contextmanager
def lock_folder(folder: str | os.PathLike):
    """Hold an exclusive flock on the folder itself (no lock file among a user's files) until the block ends; the
    kernel drops it when the process dies. Taking it again inside the block, in this process, does not wait."""
    key = os.path.realpath(folder)
    held = _HELD.__dict__.setdefault("folders", set())
    if key in held:
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        held.add(key)
        yield
    finally:
        held.discard(key)
        os.close(fd)


@contextlib.contextmanager
def _manifest_lock(folder: Path):
    """Hold `folder`'s lock while its manifest is read, changed and replaced: runs writing into one folder at
    once lost each other's entries (4 processes writing 60 files each left 102 of the 240 recorded, and the next
    run refused the others as not kinfu's). Best effort: a folder that cannot be opened or locked is updated
    without it."""
    with contextlib.ExitStack() as stack:
        with contextlib.suppress(OSError):
            stack.enter_context(lock_folder(folder))
        yield


# manifest path -> ((inode, size, mtime ns), its document): a check of a folder's n files read its manifest of n
# entries n times (3,000 segment files: 5.8 s to claim the folder); a manifest is only ever replaced whole (a new
# inode and time), so a document read at the same inode, size and time is the one on disk
_DOCS: dict[str, tuple[tuple[int, int, int], dict]] = {}
_DOCS_KEPT = 256


def _read_doc(folder: Path) -> dict:
    """The manifest document of `folder` ({} when it has none or it is damaged); do not change it (shared)."""
    path = folder / MANIFEST
    try:
        st = path.stat()
        key = (st.st_ino, st.st_size, st.st_mtime_ns)
        hit = _DOCS.get(str(path))
        if hit is not None and hit[0] == key:
            return hit[1]
        doc = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError):  # unreadable or damaged: nothing is recorded as kinfu's
        return {}
    doc = doc if isinstance(doc, dict) else {}
    if len(_DOCS) >= _DOCS_KEPT:
        _DOCS.clear()
    _DOCS[str(path)] = (key, doc)
    return doc


def _read_manifest(folder: Path) -> dict[str, dict]:
    """name -> entry of `folder`'s manifest, shared with every reader of this version: copy it to change it."""
    files = _read_doc(folder).get("files")
    return files if isinstance(files, dict) else {}


def manifest_files(folder: str | os.PathLike) -> dict[str, dict]:
    """The entries `folder`'s manifest records (name -> size, time, kind); {} when it has none."""
    return dict(_read_manifest(Path(folder)))


def write_manifest_files(folder: str | os.PathLike, files: dict[str, dict], whole: bool | None = None) -> None:
    """Replace the entries `folder`'s manifest records; whole: kinfu wrote the folder whole (None: as it said)."""
    _write_manifest(Path(folder), files, whole)


def mark_folder_output(folder: str | os.PathLike) -> None:
    """Record in `folder`'s manifest that kinfu wrote the folder whole (an output folder): it is kinfu's wherever
    it is moved. A folder that only holds some kinfu file (a user's folder given as `-o folder/pois.json`) has a
    manifest too, but is not kinfu's."""
    with _manifest_lock(Path(folder)):
        _write_manifest(Path(folder), _read_manifest(Path(folder)), whole=True)


def _stat_entry(path: Path) -> dict:
    st = path.stat()
    return {"size": st.st_size if path.is_file() else None, "mtime_ns": st.st_mtime_ns,
            "kind": "folder" if path.is_dir() else "file"}


def record_written(path: str | os.PathLike) -> None:
    """Add `path` (just written by kinfu) to its folder's manifest; the manifest is replaced atomically.

    Best effort: a folder where the manifest cannot be written only loses the ownership record."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    with _manifest_lock(folder):
        files = dict(_read_manifest(folder))
        with contextlib.suppress(OSError):
            files[path.name] = _stat_entry(path)
            _write_manifest(folder, files)


def _write_manifest(folder: Path, files: dict[str, dict], whole: bool | None = None) -> None:
    """Replace `folder`'s manifest atomically; best effort (an unwritable folder only loses the record). whole:
    kinfu wrote the folder whole (None: as the manifest said)."""
    tmp = None
    if whole is None:
        whole = _read_doc(folder).get("folder_output") is True
    # read from disk after this: a rewrite within the clock's tick may have the inode number, size and time of the
    # document it replaces
    _DOCS.pop(str(folder / MANIFEST), None)
    _clear_stale_temporaries(folder)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f"{MANIFEST}.", suffix=".part", dir=folder)
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # mkstemp makes 0600: a colleague's run could not tell kinfu's files apart
        with os.fdopen(fd, "w") as fh:
            json.dump({"written_by": "kinfu", **({"folder_output": True} if whole else {}), "files": files}, fh,
                      indent=1, sort_keys=True)
        os.replace(tmp, folder / MANIFEST)
    except BaseException as exc:  # Ctrl-C too: no temporary is left
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        if not isinstance(exc, OSError):
            raise


# a manifest's temporary older than this was left by a killed run (a manifest is written in milliseconds)
STALE_TEMPORARY_S = 60.0


def _clear_stale_temporaries(folder: Path) -> None:
    """Remove the manifest temporaries a killed run left in `folder` (not a running one's: they are fresh)."""
    now = time.time()
    for stale in folder.glob(f"{MANIFEST}.{'[a-z0-9_]' * 8}.part"):
        with contextlib.suppress(OSError):
            if now - stale.stat().st_mtime > STALE_TEMPORARY_S:
                stale.unlink()


def record_tree(folder: str | os.PathLike) -> None:
    """Record every entry under `folder` (just written by kinfu, whatever library wrote each file) in the
    manifest of the folder that holds it, so a later run can tell kinfu's files from a user's at any depth.

    Best effort, like `record_written`."""
    folder = Path(folder)
    for sub in [p for p in folder.rglob("*") if p.is_dir() and not p.is_symlink()] + [folder]:
        with _manifest_lock(sub):
            files = dict(_read_manifest(sub))
            entries = [e for e in sub.iterdir() if e.name != MANIFEST and not e.name.startswith(f"{MANIFEST}.")]
            if (sub / MANIFEST).is_file() and all(e.name in files for e in entries):
                continue  # (an empty folder gets a manifest too: it is kinfu's, not a user's)
            with contextlib.suppress(OSError):
                for e in entries:
                    files.setdefault(e.name, _stat_entry(e))
                _write_manifest(sub, files)


def written_by_kinfu(path: str | os.PathLike) -> bool:
    """True when kinfu wrote `path` and nobody changed it since (see the module docstring)."""
    path = Path(path)
    if path.is_symlink():  # kinfu writes no links: one at a kinfu name is the user's (stat would follow it)
        return False
    entry = _read_manifest(path.parent if str(path.parent) else Path(".")).get(path.name)
    if path.is_dir():
        # kinfu's folder holds kinfu's records and was written whole (its own mark, or its parent's record of
        # it), or holds nothing but kinfu's entries: a user's folder that received a kinfu file beside the user's
        # own, or that a user put where kinfu's subfolder was, is not
        if not (path / MANIFEST).is_file():
            return False
        if _read_doc(path).get("folder_output") is True or (isinstance(entry, dict)
                                                            and entry.get("kind") == "folder"):
            return True
        return holds_only_kinfu_entries(path)
    if not isinstance(entry, dict) or not path.exists():
        return False
    now = _stat_entry(path)
    return entry.get("kind") == now["kind"] and (now["kind"] == "folder" or (
        entry.get("size") == now["size"] and entry.get("mtime_ns") == now["mtime_ns"]))


#: the names of kinfu's temporaries (core.atomic's `.NAME.xxxxxxxx[.old].part[.ext]`, a manifest's
#: `.kinfu-manifest.json.xxxxxxxx.part`): never a user's file
TEMPORARY_NAME = re.compile(r"^\..+\.[a-z0-9_]{8}(\.old)?\.part(\..*)?$")


def holds_only_kinfu_entries(folder: Path) -> bool:
    """Whether every entry of `folder` (its manifest and kinfu's temporaries aside) is one its manifest records
    unchanged, at any depth: what may be removed whole."""
    files = _read_manifest(folder)
    for e in folder.iterdir():
        if e.name == MANIFEST or TEMPORARY_NAME.match(e.name):
            continue
        entry = files.get(e.name)
        if not isinstance(entry, dict) or e.is_symlink():
            return False
        if e.is_dir():
            if not ((e / MANIFEST).is_file() and holds_only_kinfu_entries(e)):
                return False
        elif {k: entry.get(k) for k in ("size", "mtime_ns", "kind")} != _stat_entry(e):
            return False
    return True


def remove_written(path: str | os.PathLike) -> tuple[list[Path], list[Path]]:
    """Remove what kinfu wrote at `path` and nobody changed since: a file, or a folder (whole when it holds nothing
    else). What is not kinfu's stays where it is: a user's entry in a kinfu folder (at any depth), and a file kinfu
    wrote that was changed since. The kinfu folder holding one keeps its record (the next kinfu output there still
    keeps the user's entries without being forced), and its JSON results go first, so a removal stopped half-way
    leaves no result that looks complete. Returns (removed, kept): the paths removed, and those kept that lie in a
    kinfu folder or that kinfu wrote; a path kinfu never wrote is left alone and in neither list."""
    path = Path(path)
    if not written_by_kinfu(path):
        return [], ([path] if path.is_file() and changed_since_written(path) else [])
    if path.is_dir() and holds_only_kinfu_entries(path):
        shutil.rmtree(path, ignore_errors=True)
    elif path.is_dir():
        return _remove_written_entries(path)
    else:
        with contextlib.suppress(OSError):
            path.unlink()
    return [path], []


def _remove_written_entries(folder: Path) -> tuple[list[Path], list[Path]]:
    """remove_written for the entries of a kinfu folder holding a user's entry somewhere; its manifest then lists
    what stays."""
    removed: list[Path] = []
    kept: list[Path] = []
    with _manifest_lock(folder):
        files = _read_manifest(folder)
        entries = [e for e in folder.iterdir() if e.name != MANIFEST and not TEMPORARY_NAME.match(e.name)]
        for e in sorted(entries, key=lambda e: (e.suffix != ".json", e.name)):  # the results first
            if e.name not in files or e.is_symlink():
                kept.append(e)
            elif e.is_dir():
                if not (e / MANIFEST).is_file():
                    kept.append(e)  # no record of what is inside: not known to be kinfu's
                elif holds_only_kinfu_entries(e):
                    shutil.rmtree(e, ignore_errors=True)
                    removed.append(e)
                else:
                    inner_removed, inner_kept = _remove_written_entries(e)
                    removed += inner_removed
                    kept += inner_kept
            elif written_by_kinfu(e):
                with contextlib.suppress(OSError):
                    e.unlink()
                removed.append(e)
            else:
                kept.append(e)  # changed since kinfu wrote it: the user's now
        gone = {e.name for e in removed if e.parent == folder and not e.exists()}
        if gone:
            _write_manifest(folder, {n: entry for n, entry in files.items() if n not in gone})
    return removed, kept


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
    _check_writable_path(out, parameter)
    if out.exists() and not force and not written_by_kinfu(out):
        what = "folder" if out.is_dir() else "file"
        raise ForeignOutputError(f"{out}: an existing {what} that kinfu did not write; choose another path",
                                 parameter=parameter)
    changed = changed_since_written(out) if out.is_dir() and not out.is_symlink() and not force else []
    if changed:  # a copy (cp -r), or files edited since: found here, not after the work when the swap stops
        more = f" and {len(changed) - 3} more" if len(changed) > 3 else ""
        raise ForeignOutputError(f"{out}: {', '.join(changed[:3])}{more} there changed since kinfu wrote them (a "
                                 f"copy, or edited: the user's now) and would be replaced; choose another path",
                                 parameter=parameter)
    if out.is_file() and not force and _part_of_folder_output(real):  # grasp --plot seg/segments.ply
        raise ForeignOutputError(f"{out} is a file of the kinfu output folder {out.parent}, written with it as one "
                                 f"result (replacing it alone would break that result); choose another path",
                                 parameter=parameter)
    return out


def recording_folders(recording: str | os.PathLike | None) -> list[Path]:
    """The folders a recording input is read from whole: the recording itself when it is a folder (a ROS 2 bag),
    else the ROS 2 bag folder one of its files lies in (a metadata.yaml beside it); [] for a recording file in a
    plain folder. Anything written inside one joins the recording (the next run reads it with it), unlike a new
    file beside an input in a plain folder, which claim_output allows."""
    if recording is None or str(recording) == "":
        return []
    path = Path(recording)
    if path.is_dir():
        return [path]
    return [path.parent] if path.is_file() and (path.parent / "metadata.yaml").is_file() else []


def refuse_inside_folders(output: str | os.PathLike, folders: Iterable[str | os.PathLike | None], *,
                          parameter: str = "output") -> None:
    """KinfuError when `output` lies inside one of `folders`, inputs read whole (recording_folders): writing there
    would change the input."""
    real = Path(os.path.realpath(output))
    for folder in folders:
        if folder is None or str(folder) == "":
            continue
        src = Path(os.path.realpath(folder))
        if src.is_dir() and src in real.parents:
            raise KinfuError(f"{output} is inside the input folder {folder}; write it elsewhere", parameter=parameter)


def _part_of_folder_output(path: Path) -> bool:
    """Whether the file `path` lies in a folder that kinfu wrote whole (its parent's manifest lists the folder)."""
    entry = _read_manifest(path.parent.parent).get(path.parent.name)
    return isinstance(entry, dict) and entry.get("kind") == "folder"


# kinfu writes an output as a temporary `.NAME.xxxxxxxx.old.part` beside it first: a name this much shorter than
# the file system's limit (255 bytes) fits
NAME_MARGIN = 24


def _check_writable_path(out: Path, parameter: str) -> None:
    """KinfuError, before any work, for an output kinfu could not write after it: its name reserved for kinfu's
    own records, a name too long for its temporary, a file where a folder of its path must be, or a nearest
    existing folder that cannot be written."""
    if out.name in ("", ".", ".."):
        raise KinfuError(f"{out}: expected a path ending in a file or folder name", parameter=parameter)
    if out.name == MANIFEST or out.name.startswith(".kinfu-"):
        raise KinfuError(f"{out}: the name is kinfu's own record of what it wrote; choose another name",
                         parameter=parameter)
    limit = 255 - NAME_MARGIN
    if len(os.fsencode(out.name)) > limit:
        raise KinfuError(f"{out.name[:40]}...: a name of {len(os.fsencode(out.name))} bytes; expected at most "
                         f"{limit} (kinfu writes it under a longer temporary name first)", parameter=parameter)
    folder, missing = out.parent if str(out.parent) else Path("."), None
    while not folder.exists() and folder != folder.parent:
        if folder.is_symlink():
            break  # a broken link: said when the folder is made
        folder, missing = folder.parent, folder
    if folder.exists() and not folder.is_dir():
        raise KinfuError(f"{out}: {folder} is a file, not a folder", parameter=parameter)
    if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
        raise KinfuError(f"{out}: cannot write into the folder {folder} (permission denied)", parameter=parameter)
    if folder.is_dir():
        _probe_folder(out, folder, missing, parameter)


def _probe_folder(out: Path, folder: Path, missing: Path | None, parameter: str) -> None:
    """Make and remove what the output's path needs in its nearest existing folder: `missing`, the first folder
    of its path not there yet, or (None) a temporary file. os.access answers yes to root where nothing can be made
    (/proc, a read-only mount), and the run then failed only after its work, its warnings already printed."""
    try:
        if missing is not None:
            try:
                missing.mkdir()
            except FileExistsError:  # made meanwhile (another run): it can be made
                return
            with contextlib.suppress(OSError):
                missing.rmdir()
        else:
            fd, probe = tempfile.mkstemp(prefix=".kinfu-probe-", dir=folder)
            os.close(fd)
            os.unlink(probe)
    except OSError as exc:
        raise KinfuError(f"{out}: cannot write into the folder {folder} ({exc.strerror or exc})",
                         parameter=parameter) from None
