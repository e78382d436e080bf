"""Write-then-rename helpers, so a failed run never leaves a complete-looking output."""

from __future__ import annotations

import contextlib
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
from kinfu_cli.core.ownership import MANIFEST, owned_entries, record_tree, record_written


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


def _clear_debris(parent: Path, *patterns: str) -> None:
    """Remove what a killed earlier run left beside an output: kinfu's own temporary `.part` names only."""
    for stale in (p for pattern in patterns for p in parent.glob(pattern)):
        if stale.is_dir() and not stale.is_symlink():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                stale.unlink()


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
    os.close(fd)
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
    record_written(final)


@contextlib.contextmanager
def atomic_dir(final: str | os.PathLike, own: Iterable[str] | None = None, force: bool = False) -> Iterator[Path]:
    """Yield a temporary folder beside `final`; it replaces `final` only if the block succeeds.

    For outputs that are folders (ROS 2 bags, result folders with several files): the whole folder appears
    at once, so a killed run leaves no folder that looks complete or mixes old and new files. Entries of an
    existing `final` that kinfu did not write are carried over, never removed. own: glob patterns of every
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
        yield tmp
        record_tree(tmp)  # everything in it is kinfu's now; foreign entries are carried over only below
        with _writable(parent):
            if final.exists():
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
    """Swap the finished folder `new` in for `final`, keeping the entries of `final` kinfu did not write.

    A file `final` (a kinfu output, or one the caller was told to overwrite) is replaced. Foreign entries are
    carried over at any depth: a user's file inside a kinfu-written subfolder (one with its own manifest)
    survives too. A foreign entry with the name of a new output stops the swap (the new outputs stay in `new`
    and the error says so), unless `force`: then it is replaced."""
    if not final.is_dir():
        final.unlink()
        os.replace(new, final)
        return
    others = _other_outputs(final, new, own) if own is not None else []
    moves, clash = _foreign_moves(final, new, skip={p.name for p in others})
    if clash and not force:
        raise KinfuError(f"{final}: {', '.join(sorted(clash))} there was not written by kinfu and would be replaced")
    for src, dst in moves:
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.replace(src, dst)
    for src in others:  # still kinfu's: recorded in the new folder's manifest
        os.replace(src, new / src.name)
        record_written(new / src.name)
    old = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old.part", dir=final.parent))
    os.replace(final, old / final.name)
    os.replace(new, final)
    shutil.rmtree(old, ignore_errors=True)


def _foreign_moves(old: Path, new: Path, rel: str = "", skip: set[str] | frozenset = frozenset()
                   ) -> tuple[list[tuple[Path, Path]], list[str]]:
    """(source, destination) of every entry under `old` kinfu did not write, and the names that clash with
    new outputs. A kinfu-written subfolder is searched only when it records its own entries (a manifest);
    one without (written before per-folder records) is kinfu's whole, as it always was. `skip`: top-level
    names moved whole elsewhere."""
    mine = owned_entries(old)
    moves: list[tuple[Path, Path]] = []
    clash: list[str] = []
    for entry in old.iterdir():
        if entry.name in skip:
            continue
        target = new / entry.name
        if entry.name not in mine:
            if target.exists() or target.is_symlink():
                clash.append(rel + entry.name)
            else:
                moves.append((entry, target))
        elif entry.is_dir() and not entry.is_symlink() and (entry / MANIFEST).is_file():
            if target.exists() and not target.is_dir():
                continue  # a kinfu folder replaced by a kinfu file: nothing of the user's can be inside a file
            sub_moves, sub_clash = _foreign_moves(entry, target, rel + entry.name + "/")
            moves += sub_moves
            clash += sub_clash
    return moves, clash


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
