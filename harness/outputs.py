"""Output folders of the jobs, written as a transaction: all or nothing, never into a user's folder.

Every command that writes a folder goes through :func:`output_transaction`:

1. *validate first*: the target's state is checked before any work (``out`` is a file, a user's
   non-empty folder, one of ours without ``overwrite``, inside the input dataset, not creatable);
2. *lock*: ``<out>.lock`` beside the target is locked (``fcntl.flock``); a second run into the same
   folder is refused while the first one runs; the lock file is removed afterwards;
3. *write aside*: the job writes into a temporary folder beside the target (``.<name>.tmp-*``);
4. *commit*: the marker :data:`MARKER` and the completion record :data:`COMPLETE` are written, an
   earlier output is renamed aside, the new folder renamed into place, the earlier one deleted.

An error or Ctrl-C (KeyboardInterrupt) before the commit removes the temporary folder and leaves
``out`` as it was. ``overwrite`` replaces the *whole* earlier output, and only a folder this tool
made (it holds :data:`MARKER`). A folder holding the marker but no completion record is the remains
of a run interrupted by an older version: when it holds nothing but the marker it is replaced
without ``overwrite``; otherwise ``overwrite`` is needed, as for a complete output.
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from harness.data.dataset import Dataset, read_dataset

__all__ = ["MARKER", "COMPLETE", "OutputPathError", "output_folder", "output_transaction", "check_output_target",
           "check_creatable", "check_output_file", "file_transaction",
           "guard_not_inside", "dataset_and_output", "final_paths"]

MARKER = ".mpc-actuator-output"
COMPLETE = ".mpc-actuator-complete"
_TMP = ".tmp-"
_OLD = ".old-"


class OutputPathError(ValueError):
    """An output folder or file that must not be written; the message starts with its path."""


def _lock_path(out: Path) -> Path:
    return out.with_name(out.name + ".lock")


def check_output_target(path: str | Path, overwrite: bool) -> Path:
    """Check that ``path`` may become (or be replaced by) an output folder; write nothing.

    Raises
    ------
    OutputPathError
        ``path`` is a file; or a non-empty folder not made by this tool; or one made by this tool
        (complete, or incomplete with files besides the marker) and ``overwrite`` is false.
    """
    out = Path(path)
    if not out.name or out.name in (".", ".."):
        out = Path(os.path.abspath(out))
    if out.exists() and not out.is_dir():
        raise OutputPathError(f"{out} exists and is not a folder")
    if out.is_symlink():
        raise OutputPathError(f"{out} is a symbolic link; give the folder itself")
    if out.is_dir():
        try:
            names = {p.name for p in out.iterdir()}
        except OSError as e:
            raise OutputPathError(f"{out} cannot be read: {e.strerror or e}") from None
        if not names or names == {MARKER}:
            return out                       # empty, or the remains of an interrupted run: nothing to lose
        if MARKER not in names:
            if not overwrite:
                raise OutputPathError(f"{out} is not empty; choose another folder or pass --overwrite")
            raise OutputPathError(f"{out} is not empty and was not made by mpc-actuator "
                                  f"(no {MARKER} file); refusing to write into it")
        if not overwrite:
            if COMPLETE not in names:
                raise OutputPathError(f"{out} is not empty; it holds an incomplete earlier output (no {COMPLETE}: "
                                      f"an interrupted run); pass --overwrite to replace it")
            raise OutputPathError(f"{out} is not empty; choose another folder or pass --overwrite")
        if "manifest.json" in names and _holds_measured_data(out):
            raise OutputPathError(f"{out} holds a measured (non-synthetic) dataset; measured data are never "
                                  f"overwritten, choose another folder")
    return out


def _holds_measured_data(folder: Path) -> bool:
    """The folder's manifest.json does not say ``"synthetic": true`` (unreadable counts as measured)."""
    try:
        return json.loads((folder / "manifest.json").read_text()).get("synthetic") is not True
    except (OSError, ValueError, AttributeError):
        return True


def check_creatable(out: str | Path) -> None:
    """Refuse a path below a file (its first existing ancestor must be a folder); write nothing.

    Raises
    ------
    OutputPathError
        Naming the path and the file in the way.
    """
    out = Path(out)
    for anc in out.parents:
        if anc.exists() or anc.is_symlink():
            if not anc.is_dir():
                raise OutputPathError(f"{out}: cannot create it, {anc} is a file, not a folder")
            break


def _make_parent(out: Path) -> None:
    parent = out.parent
    check_creatable(out)
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputPathError(f"{out}: cannot create its parent folder {parent}: {e.strerror or e}") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputPathError(f"{out}: its folder {parent} is not writable")


@contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold ``<out>.lock`` (exclusive, non-blocking); refuse if another run holds it."""
    import fcntl
    lock = _lock_path(out)
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as e:
            raise OutputPathError(f"{out}: cannot create the lock file {lock}: {e.strerror or e}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            os.close(fd)
            if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise OutputPathError(f"{out} is being written by another mpc-actuator run (lock file {lock} "
                                      f"is held); wait for it to finish or choose another folder") from None
            raise
        try:                                 # the holder before us may have removed the file: lock the new one
            same = os.path.samestat(os.fstat(fd), os.stat(lock))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        try:
            os.unlink(lock)
        finally:
            os.close(fd)


def _clean_leftovers(out: Path) -> None:
    """Remove temporary folders of earlier runs into ``out`` that were killed (we hold the lock)."""
    for p in out.parent.glob(f".{out.name}{_TMP}*"):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
    for p in out.parent.glob(f".{out.name}{_OLD}*"):   # an earlier output moved aside (as p/x), not yet deleted
        if p.is_dir() and not p.is_symlink() and (not any(p.iterdir()) or (p / "x" / MARKER).exists()):
            shutil.rmtree(p, ignore_errors=True)


def _commit(tmp: Path, out: Path) -> None:
    """Move ``tmp`` into place as ``out``; an earlier ``out`` is moved aside and deleted afterwards."""
    (tmp / MARKER).write_text("output folder of mpc-actuator; --overwrite may replace this whole folder\n")
    (tmp / COMPLETE).write_text(json.dumps({"completed_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                            "pid": os.getpid()}) + "\n")
    if not out.exists():
        os.rename(tmp, out)
        return
    aside = Path(tempfile.mkdtemp(prefix=f".{out.name}{_OLD}", dir=out.parent))
    os.rename(out, aside / "x")              # the earlier output, kept until the new one is in place
    try:
        os.rename(tmp, out)
    except BaseException:
        os.rename(aside / "x", out)
        shutil.rmtree(aside, ignore_errors=True)
        raise
    shutil.rmtree(aside, ignore_errors=True)


@contextmanager
def output_transaction(path: str | Path, overwrite: bool, inputs: tuple = ()) -> Iterator[Path]:
    """Write an output folder as a transaction; yields the temporary folder to write into.

    Parameters
    ----------
    path : str or Path
        The output folder (its parents are created).
    overwrite : bool
        Allow replacing an earlier output of this tool (the whole folder is replaced).
    inputs : tuple of path
        Input folders (datasets) the output must not lie in.

    Raises
    ------
    OutputPathError
        Before any work: the target may not be written (:func:`check_output_target`), lies in an
        input, cannot be created, or another run is writing it.
    """
    out = check_output_target(path, overwrite)
    for d in inputs:
        guard_not_inside(out, d)
    _make_parent(out)
    with _locked(out):
        check_output_target(out, overwrite)  # again, under the lock
        _clean_leftovers(out)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}{_TMP}", dir=out.parent))
        try:
            yield tmp
            _commit(tmp, out)
        except Exception as e:
            e.add_note(f"{out} left as it was")
            raise
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def check_output_file(path: str | Path, overwrite: bool, ours: Callable[[Path], bool], kind: str) -> Path:
    """Check that ``path`` may become (or replace) a single output file; write nothing.

    Parameters
    ----------
    path : str or Path
        The output file.
    overwrite : bool
        Allow replacing an existing file, only one for which ``ours(path)`` is true.
    ours : callable
        Whether an existing file was made by this tool (e.g. an FMU whose author is mpc-actuator).
    kind : str
        What the file is, for the messages ("an FMU made by mpc-actuator").

    Raises
    ------
    OutputPathError
        ``path`` is a folder or a symbolic link, exists without ``overwrite``, or exists and is not
        ``kind``; or cannot be created (below a file).
    """
    out = Path(path)
    if out.is_symlink():
        raise OutputPathError(f"{out} is a symbolic link; give the file itself")
    if out.is_dir():
        raise OutputPathError(f"{out} is a folder; give a file name")
    if out.exists():
        if not overwrite:
            raise OutputPathError(f"{out} exists; pass --overwrite to replace it")
        if not ours(out):
            raise OutputPathError(f"{out} exists and is not {kind}; refusing to replace it")
    check_creatable(out)
    return out


@contextmanager
def file_transaction(path: str | Path, overwrite: bool, ours: Callable[[Path], bool], kind: str) -> Iterator[Path]:
    """Write a single output file as a transaction; yields a temporary file name beside it to write.

    The target is checked first (:func:`check_output_file`), ``<out>.lock`` is held while the file is
    written (a second run into the same file is refused), the target is checked again under the lock,
    and the temporary file atomically replaces the target at the end. An error or Ctrl-C removes the
    temporary file and leaves the target as it was.

    Raises
    ------
    OutputPathError
        As :func:`check_output_file`, or another run is writing the same file.
    """
    out = check_output_file(path, overwrite, ours, kind)
    _make_parent(out)
    with _locked(out):
        check_output_file(out, overwrite, ours, kind)
        fd, tmp = tempfile.mkstemp(prefix=f".{out.name}{_TMP}", suffix=out.suffix, dir=out.parent)
        os.close(fd)
        try:
            yield Path(tmp)
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)      # the mode a plain open() gives (mkstemp makes 0600)
            os.replace(tmp, out)
        except BaseException as e:
            if isinstance(e, Exception):
                e.add_note(f"{out} left as it was")
            raise
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)


def final_paths(paths, tmp: Path, out: Path) -> list[Path]:
    """Paths written into the temporary folder ``tmp`` as they are after the commit (inside ``out``)."""
    res = []
    for p in paths:
        p = Path(p)
        try:
            res.append(Path(out) / p.relative_to(tmp))
        except ValueError:
            res.append(p)
    return res


def output_folder(path: str | Path, overwrite: bool) -> Path:
    """Create (or reuse) an output folder in place and mark it as made by this tool (no transaction).

    Kept for library users that write a folder step by step; the jobs use :func:`output_transaction`.

    Raises
    ------
    OutputPathError
        ``path`` is a file, or is not empty and either ``overwrite`` is false or the folder was
        not made by this tool.
    """
    out = check_output_target(path, overwrite)
    _make_parent(out)
    out.mkdir(exist_ok=True)
    (out / MARKER).write_text("output folder of mpc-actuator; --overwrite may replace files here\n")
    return out


def guard_not_inside(out: str | Path, dataset: str | Path) -> None:
    """Refuse an output folder that is the dataset folder or lies inside it.

    Raises
    ------
    OutputPathError
        ``out`` resolves to ``dataset`` or to a folder below it.
    """
    o, d = Path(out).resolve(), Path(dataset).resolve()
    if o == d or d in o.parents:
        raise OutputPathError(f"{out} is inside the input dataset {dataset}; outputs never go into input data")


def dataset_and_output(dataset: str | Path, out: str | Path, overwrite: bool) -> tuple[Dataset, Path]:
    """Check the output folder of a job on a dataset (outside it, writable), then read the dataset.

    Nothing is written: the job then writes through :func:`output_transaction`.

    Returns
    -------
    tuple of (Dataset, Path)
        The dataset and the checked output folder.

    Raises
    ------
    OutputPathError
        ``out`` lies inside ``dataset`` (checked first) or may not be written into.
    harness.data.dataset.DataFormatError
        The dataset cannot be read.
    """
    guard_not_inside(out, dataset)
    checked = check_output_target(out, overwrite)
    ds = read_dataset(dataset)
    return ds, checked


def stdout_closed() -> bool:
    """True if standard output is a pipe or socket whose reader has gone (poll reports an error on it);
    then it is pointed at /dev/null, so that Python's flush at exit does not report the broken pipe again."""
    import select
    import sys
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        broken = any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))
    except (OSError, ValueError, AttributeError):
        return False
    if broken:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
    return broken
