"""One owner per run folder, and output folders and files checked before any work (`check_out`).

A command that writes a run folder (`experiments.paper --out`, `ccgan.train --workdir`,
`eval.shapes --out`, `mjx_arm.babble --out`) holds an exclusive `fcntl.flock` on a lock file
while it runs, so a second writer is refused at once with the holder's process id instead of
mixing its files with the first's. The kernel drops the lock when its holder dies, however it
dies (`kill -9` included), so a dead writer never blocks the next run; the file itself is removed
when its holder ends normally, and a killed holder's empty file is reused.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import fcntl
import os
import tempfile
from pathlib import Path

LOCK_NAME = ".lock"  # inside the folder it guards (`lock_path`)


class FolderBusyError(RuntimeError):
    """Another live process holds the folder's lock."""


def lock_path(folder: str | os.PathLike, beside: bool = False) -> Path:
    """The lock file of `folder`: ``folder/.lock``, or with `beside` ``.<name>.lock`` next to it
    (for a folder that is replaced as a whole, as `mjx_arm.dataset.save_folder` replaces its)."""
    folder = Path(folder)
    return folder.parent / f".{folder.name}.lock" if beside else folder / LOCK_NAME


class FolderLock:
    """A held lock on a run folder; `release` (also called at exit) drops it and removes its
    file, and the folder when the lock made it and nothing else was written there."""

    def __init__(self, folder: Path, path: Path, fd: int, made: list[Path]):
        self.folder, self.path, self._fd, self._made = folder, path, fd, made

    def release(self) -> None:
        if self._fd is None:
            return
        _HELD.pop(self.path, None)
        with contextlib.suppress(OSError):
            self.path.unlink()  # while still held: no one can lock this file after us
        os.close(self._fd)
        self._fd = None
        for made in self._made:  # innermost first; only folders left empty
            with contextlib.suppress(OSError):
                made.rmdir()

    def __enter__(self) -> FolderLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


_HELD: dict[Path, FolderLock] = {}  # the locks this process holds, by lock file


def _holder(path: Path) -> str:
    try:
        pid = path.read_text().strip()
    except OSError:
        pid = ""
    return f"process {pid}" if pid.isdigit() else "another process"


def lock_folder(folder: str | os.PathLike, beside: bool = False) -> FolderLock:
    """Makes `folder` (and its parents) when missing and takes its lock for this process, until
    `FolderLock.release` or the process's end.

    Args:
      folder: the run folder.
      beside: keep the lock file next to the folder rather than in it (`lock_path`).

    Returns:
      The held lock; the one this process holds already, if it does (a command's `main` called
      again in one process, as tests do, is the same owner).

    Raises:
      FolderBusyError: another process holds it (the message names the folder and its pid).
    """
    folder = Path(folder)
    path = lock_path(folder, beside)
    made = [p for p in (path.parent, *path.parent.parents) if not p.exists()]
    path.parent.mkdir(parents=True, exist_ok=True)
    path = path.parent.resolve() / path.name
    if path in _HELD:
        return _HELD[path]
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise FolderBusyError(
                f"{folder} is in use by {_holder(path)} (lock {path}): one writer per folder;"
                " wait for it to end, stop it, or choose another folder"
            ) from None
        try:  # the previous holder may have removed the file between our open and our lock
            current = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            current = False
        if current:
            break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    lock = FolderLock(folder, path, fd, made)
    _HELD[path] = lock
    atexit.register(lock.release)
    return lock


def check_writable_folder(folder: str | os.PathLike) -> Path:
    """Checks, before any work, that a command can write into `folder` or make it.

    Returns:
      `folder` as a Path.

    Raises:
      NotADirectoryError: `folder`, or a path on the way to it, is a file.
      PermissionError: the folder, or its nearest existing parent, is not writable.
    """
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        way = "" if existing == folder else f", so {folder} cannot be made"
        raise NotADirectoryError(f"{existing} exists and is not a folder{way}")
    way = "" if existing == folder else f", so {folder} cannot be made"
    if not os.access(existing, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot write in {existing}{way}")
    try:  # a read-only mount, or a folder only root's permission bits would let through
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as err:
        raise PermissionError(f"cannot write in {existing}{way} ({err.strerror})") from None
    return folder


def check_writable_file(path: str | os.PathLike) -> Path:
    """Checks, before any work, that a command can write the file `path`: not an existing
    folder, and its folder writable or creatable (`check_writable_folder`).

    Raises:
      IsADirectoryError: `path` is a folder. NotADirectoryError, PermissionError: as
      `check_writable_folder` for its folder.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a folder; a file path is needed")
    check_writable_folder(path.parent)
    return path


def check_out(parser: argparse.ArgumentParser, flag: str, path, file: bool = False) -> Path:
    """A command's output check, before any work: an argparse usage error (exit 2) naming
    `flag` unless `path` is a folder it can write or make (`file`: a file it can write,
    `check_writable_file`).

    Returns:
      `path` as a Path.
    """
    try:
        return check_writable_file(path) if file else check_writable_folder(path)
    except OSError as err:
        parser.error(f"{flag} {path}: {err}")
