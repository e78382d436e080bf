"""Write-then-rename helpers, so a failed run never leaves a complete-looking output."""

from __future__ import annotations

import contextlib
import fcntl
import fnmatch
import glob
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.ownership import (MANIFEST, lock_folder, manifest_files, mark_folder_output, owned_entries,
                                      record_tree, record_written, write_manifest_files)


def _ensure_parent(final: Path) -> Path:
    """The folder `final` goes in, created if needed (a one-line KinfuError when it cannot be)."""
    parent = final.parent if str(final.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise KinfuError(f"{parent}: cannot create output folder ({exc.strerror})") from None
    return parent


@contextlib.contextmanager
def _writable(folder: Path) -> Iterator[None]:
    """A folder kinfu cannot write into (read-only, not its user's, a full disk) is one KinfuError naming the
    folder, not the temporary file's name in an OSError."""
    try:
        yield
    except OSError as exc:
        raise KinfuError(f"{folder}: cannot write into this folder ({exc.strerror or exc})") from None


# tempfile's random part of a name: 8 characters (mkstemp / mkdtemp). Debris patterns match exactly the
# names kinfu's temporaries get, so a user's file such as `.report.notes.part.json` is never touched.
_RANDOM = "[a-z0-9_]" * 8


@contextlib.contextmanager
def _locked_dir(path: Path) -> Iterator[Path]:
    """Hold an exclusive lock on kinfu's temporary `path` while it is in use: another run's debris clearing leaves
    it alone (a run writing the same output at the same time deleted the other's half-written folder, which then
    swapped in without its meshes). The lock goes with the process, so a killed run's debris is cleared."""
    with lock_folder(path):  # ownership's: the manifest written into it while the block runs takes it again
        yield path


def _in_use(path: Path) -> bool:
    """Whether a running kinfu holds `path` (see _locked_dir)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # closing releases a lock taken here
    return False


def _clear_debris(parent: Path, *patterns: str) -> None:
    """Remove what a killed earlier run left beside an output: kinfu's own temporary `.part` names only, and not
    while a running kinfu holds them."""
    for stale in (p for pattern in patterns for p in parent.glob(pattern)):
        if _in_use(stale):
            continue
        if stale.is_dir() and not stale.is_symlink():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                stale.unlink()


@contextlib.contextmanager
def scratch_dir(beside: str | os.PathLike) -> Iterator[Path]:
    """A temporary working folder `.NAME.xxxxxxxx.part` beside the output `beside`, removed at the end: what a
    library writes on its way to a single output file (rosbags' bag folder around an .mcap). Locked while in use,
    and a killed run's is cleared by the next one, like atomic_path's temporaries."""
    beside = Path(beside)
    parent = _ensure_parent(beside)
    _clear_debris(parent, f".{glob.escape(beside.stem)}.{_RANDOM}.part")
    with _writable(parent):
        tmp = Path(tempfile.mkdtemp(prefix=f".{beside.stem}.", suffix=".part", dir=parent))
    try:
        with _locked_dir(tmp):
            yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def atomic_path(final: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside `final`; rename it to `final` only if the block succeeds.

    The temporary name keeps the final suffix (writers such as open3d pick the format by it). The written
    file is recorded in its folder's kinfu manifest (see core/ownership.py).
    """
    final = Path(final)
    parent = _ensure_parent(final)
    suffix = final.suffix if suffix is None else suffix
    _clear_debris(parent, f".{glob.escape(final.stem)}.{_RANDOM}.part{glob.escape(suffix)}")
    with _writable(parent):
        fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=f".part{suffix}", dir=parent)
    fcntl.flock(fd, fcntl.LOCK_EX)  # held until the end (see _locked_dir)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual mode
    try:
        yield tmp_path
        with _writable(parent):
            if tmp_path.is_dir() and final.exists():
                _replace_folder(tmp_path, final)
            else:
                os.replace(tmp_path, final)
    except BaseException:
        if tmp_path.is_dir():
            shutil.rmtree(tmp_path, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                tmp_path.unlink()
        raise
    finally:
        os.close(fd)
    record_written(final)


@contextlib.contextmanager
def atomic_dir(final: str | os.PathLike, own: Iterable[str] | None = None, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside `final`; it replaces `final` only if the block succeeds.

    For outputs that are folders (ROS 2 bags, result folders with several files): a new folder appears at once,
    and one replacing kinfu's earlier output leaves no result that looks complete while its entries move (see
    _replace_folder). Entries of an existing `final` that kinfu did not write stay where they are, never moved
    or removed. own: glob patterns of every
    entry the caller writes there (a result folder that other commands may share): kinfu entries matching
    none of them and not written anew (another command's outputs) are carried over too; None: the folder is
    the caller's whole (a bag, a data set). force: a foreign entry with the name of a new output (a user's file,
    or kinfu's edited since) is replaced, as the caller was told to; otherwise the swap stops (KinfuError).
    """
    final = Path(final)
    parent = _ensure_parent(final)
    _clear_debris(parent, f".{glob.escape(final.name)}.{_RANDOM}.part", f".{glob.escape(final.name)}.{_RANDOM}.old.part")
    with _writable(parent):
        tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".part", dir=parent))
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        with _locked_dir(tmp):
            yield tmp
            record_tree(tmp)  # everything in it is kinfu's now; foreign entries keep their place below
            mark_folder_output(tmp)
            with _writable(parent):
                if final.exists() or final.is_symlink():
                    _replace_folder(tmp, final, own, force)
                else:
                    os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    record_written(final)


def _other_outputs(old: Path, new: Path, own: Iterable[str]) -> list[Path]:
    """The entries of `old` kinfu wrote that match none of the `own` patterns and are not written anew: another
    command's outputs in a shared folder."""
    own = tuple(own)
    return [old / n for n in sorted(owned_entries(old) - {MANIFEST})
            if (old / n).exists() and not (new / n).exists() and not any(fnmatch.fnmatchcase(n, p) for p in own)]


def _replace_folder(new: Path, final: Path, own: Iterable[str] | None = None, force: bool = False) -> None:
    """Put the finished folder `new` in place of the kinfu entries of `final`, which keeps the entries kinfu did
    not write where they are.

    A file `final` (a kinfu output, or one the caller was told to overwrite), or a symlink (only the link is
    replaced, never the folder it points to), is replaced. The user's entries never move, at any depth (a user's
    file inside a kinfu-written subfolder too): kinfu's old entries are moved out to a `.old.part` folder beside
    `final` and the new ones moved in, so a run stopped half-way (an error, Ctrl-C, kill -9) can lose only kinfu's
    files; before, the user's entries were moved into the new folder for a single swap, and a run stopped during
    those moves deleted the ones already moved with it. The folder's manifest is written before the new entries
    arrive and the JSON results last, so a run stopped between the moves leaves no result that looks complete. A
    foreign entry with the name of a new output stops the swap before anything moves, unless `force`: then it is
    replaced."""
    if final.is_symlink() or not final.is_dir():
        final.unlink()
        os.replace(new, final)
        return
    others = {p.name for p in _other_outputs(final, new, own)} if own is not None else set()
    plan = _SwapPlan()
    foreign = plan.scan(final, new, "", others)
    if plan.clash and not force:
        raise KinfuError(f"{final}: {', '.join(sorted(plan.clash))} there was not written by kinfu and would be "
                         f"replaced")
    kept = {n: e for n, e in manifest_files(final).items() if n in others}
    with _locked_dir(Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old.part", dir=final.parent))) as old:
        try:
            if not (foreign or others or plan.clash):  # all kinfu's: two renames, never a partial folder
                os.replace(final, old / final.name)
                os.replace(new, final)
                return
            # the JSON results (what marks a result complete) go out first and come in last
            for i, path in enumerate(sorted(plan.out, key=lambda p: p.suffix != ".json")):
                os.replace(path, old / str(i))
            for folder, source in plan.folders:  # top first: each manifest names what is about to arrive
                if source is not None:
                    write_manifest_files(folder, {**manifest_files(source), **(kept if folder == final else {})},
                                         True if folder == final else None)
            for folder, source in reversed(plan.folders):
                if source is None:
                    _forget_folder(folder)
            for folder, source in reversed(plan.folders):  # the top folder, with its JSON results, last
                for entry in sorted(source.iterdir() if source is not None else (),
                                    key=lambda e: (e.suffix == ".json", e.name)):
                    if entry.name != MANIFEST and not entry.name.startswith(f"{MANIFEST}.") and (
                            folder / entry.name) not in plan.merged:
                        os.replace(entry, folder / entry.name)
        finally:
            shutil.rmtree(old, ignore_errors=True)
    shutil.rmtree(new, ignore_errors=True)


class _SwapPlan:
    """What _replace_folder moves: `out`, kinfu's old entries (and foreign ones a new output replaces); `folders`,
    (old folder, new folder or None) of every kinfu folder merged, top first (None: kinfu's subfolder that the new
    output lacks, kept only for the user's entries in it); `merged`, those folders' paths below the top; `clash`,
    foreign entries a new output would replace."""

    def __init__(self) -> None:
        self.out: list[Path] = []
        self.folders: list[tuple[Path, Path | None]] = []
        self.merged: set[Path] = set()
        self.clash: list[str] = []

    def scan(self, old: Path, new: Path | None, rel: str, skip: set[str] | frozenset = frozenset()) -> bool:
        """Plan `old` against `new`; True when a foreign entry stays in it (at any depth)."""
        self.folders.append((old, new))
        mine = owned_entries(old)
        foreign = False
        for entry in sorted(old.iterdir()):
            name = entry.name
            if name in skip or name == MANIFEST or name.startswith(f"{MANIFEST}."):
                continue
            target = None if new is None else new / name
            taken = target is not None and (target.exists() or target.is_symlink())
            if name not in mine:
                if taken:
                    self.clash.append(rel + name)
                    self.out.append(entry)
                else:
                    foreign = True
                continue
            if not (entry.is_dir() and not entry.is_symlink() and (entry / MANIFEST).is_file()):
                self.out.append(entry)  # kinfu's file, or its folder without records of its own: kinfu's whole
                continue
            into = target if taken and target.is_dir() and not target.is_symlink() else None
            marks = len(self.out), len(self.folders), len(self.clash)
            inner_foreign = self.scan(entry, into, rel + name + "/")
            if taken and into is None:  # a new file in place of kinfu's folder: the folder goes whole
                del self.out[marks[0]:], self.folders[marks[1]:], self.clash[marks[2]:]
                if inner_foreign:
                    self.clash.append(rel + name)
                self.out.append(entry)
            else:
                self.merged.add(entry)
                foreign = foreign or inner_foreign
        return foreign


def _forget_folder(folder: Path) -> None:
    """A kinfu subfolder the new output lacks, its kinfu entries moved out: removed when nothing is left, else it
    holds only the user's entries and is theirs (its manifest goes)."""
    with contextlib.suppress(OSError):
        (folder / MANIFEST).unlink()
    with contextlib.suppress(OSError):
        folder.rmdir()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(final: str | os.PathLike, obj: object) -> Path:
    """Write `obj` as indented JSON atomically."""
    final = Path(final)
    with atomic_path(final) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, default=_json_default) + "\n")
    return final


def write_npz(final: str | os.PathLike, arrays: dict) -> Path:
    """Write `arrays` as one .npz atomically (np.load reads it), compressed with zlib level 1: several times
    faster than np.savez_compressed's level 6, and nearly as small for mostly-constant volumes."""
    final = Path(final)
    with atomic_path(final) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
            for name, arr in arrays.items():
                with zf.open(name + ".npy", "w", force_zip64=True) as fh:
                    np.lib.format.write_array(fh, np.asanyarray(arr), allow_pickle=False)
    return final


def _json_default(obj: object) -> object:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
