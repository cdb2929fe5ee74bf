"""Files and folders written whole or not at all, and the temporaries a killed writer leaves.

A dataset is written to a temporary beside its target and renamed into place, so a reader never
sees half a file; temporaries carry their writer's process id, so a later run can tell a dead
writer's leftovers from a live one's.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def write_atomically(path: Path, write) -> Path:
    """Calls write(binary file) on a temporary file beside `path`, syncs it, renames it over
    `path`; removes the temporary on any error."""
    fd, tmp = tempfile.mkstemp(prefix=temporary_prefix(path), suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~umask())  # mkstemp makes 0600 files; honour the umask instead
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def temporary_prefix(path: Path) -> str:
    """Temporaries of `path` are named ``.<name>.<pid>.<random>.tmp`` (``.old`` for a folder
    being replaced), beside it, so that a later process can tell whether their writer is dead."""
    return f".{path.name}.{os.getpid()}."


def _alive(pid: int) -> bool:
    """Whether process `pid` runs on this machine (signal 0 only checks; it sends nothing)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike) -> list[Path]:
    """Removes the temporaries of `path` (a dataset file or a run folder) that a killed process
    left beside it.

    A temporary whose writer still runs is left alone. A folder moved aside for replacement
    (``.old``) whose writer died before renaming the new folder into place is the only copy of
    the earlier run: it is put back at `path` when `path` is missing, removed otherwise.

    Returns:
      The temporaries removed or put back.
    """
    path = Path(path)
    if not path.parent.is_dir():
        return []
    prefix = f".{path.name}."
    done = []
    for entry in sorted(path.parent.iterdir()):
        name = entry.name
        if not name.startswith(prefix) or not name.endswith((".tmp", ".old")):
            continue
        pid = name[len(prefix) :].split(".", 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue  # not one of ours (e.g. ".out.npz.<pid>...tmp" beside folder "out"), or live
        if name.endswith(".old") and not path.exists():
            os.replace(entry, path)
        elif entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        done.append(entry)
    return done


def umask() -> int:
    """The process's umask (read by setting and restoring it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def fsync_dir(folder: Path) -> None:
    """Makes a folder's entries (new files, renames) durable."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def link_or_copy(source: Path, dest: Path) -> Path:
    """Puts the file `source` at `dest` whole or not at all: a hard link where the file system
    allows (no second copy on disk or in a packed run folder), else a copy. For caches that are
    only ever replaced whole (`write_atomically`), never written in place. Returns dest."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(f".{dest.name}.tmp")
    tmp.unlink(missing_ok=True)
    try:
        os.link(source, tmp)
    except OSError:
        shutil.copyfile(source, tmp)
    tmp.replace(dest)
    return dest
