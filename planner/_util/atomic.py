"""Atomic file writes that never follow a link: a temporary file in the target's folder, then
``os.replace``.

A reader never sees a half-written file: either the old file (or none) or the complete new
one. The temporary file is created with ``O_CREAT | O_EXCL | O_NOFOLLOW`` under a name with
128 random bits (``.NAME.PID.RANDOM.tmp``), so a file or link planted in advance is never
opened; ``os.replace`` puts the new file *in place of* a link at the final path (the link's
target is not written). The file is created with mode ``0o666`` and the kernel applies the
user's umask (no process-wide ``umask`` call, which would race with other threads).

Temporary files of a process that was killed (SIGKILL, power loss) stay behind; the next
write to the same path removes those whose process no longer runs
(:func:`remove_stale_temporaries`).
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

_SUFFIX = ".tmp"
_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)


def temporary_name(path: str | os.PathLike[str]) -> Path:
    """A fresh, unpredictable temporary name beside ``path``:
    ``.NAME.PID.RANDOM.tmp`` (the pid lets a later run tell whether its writer still runs)."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(16)}{_SUFFIX}")


def _owner_alive(name: str, stem: str) -> bool:
    """Whether the process that created temporary ``name`` (of target ``stem``) runs."""
    middle = name[len(stem) + 1 : -len(_SUFFIX)]  # "PID.RANDOM"
    pid_text, _, rest = middle.partition(".")
    if not pid_text.isdigit() or not rest:
        return True  # not one of ours: leave it alone
    pid = int(pid_text)
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files (and folders, see :func:`new_temporary_folder`) left beside
    ``path`` by writers that no longer run; returns what was removed.

    Only entries named like :func:`temporary_name` with the pid of a process that does not
    exist, owned by this user, are removed; links are removed as links (never followed).
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    stem = f".{path.name}"
    removed: list[Path] = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        if not (name.startswith(stem + ".") and name.endswith(_SUFFIX)):
            continue
        if _owner_alive(name, stem):
            continue
        entry = folder / name
        try:
            info = entry.lstat()
            if info.st_uid != os.getuid():
                continue
            if stat.S_ISDIR(info.st_mode):
                shutil.rmtree(entry)
            else:
                entry.unlink()
        except OSError:
            continue
        removed.append(entry)
    return removed


def create_exclusive(path: str | os.PathLike[str]) -> int:
    """Create ``path`` for writing, failing if anything (also a dangling link) exists there;
    returns the file descriptor. The mode is ``0o666`` less the umask."""
    return os.open(path, _FLAGS | _CLOEXEC, 0o666)


@contextmanager
def atomic_write(
    path: str | os.PathLike[str], mode: str = "wb", *, fsync: bool = False, **open_kwargs: Any
) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` for writing (``mode`` ``"wb"`` or ``"w"``); on a
    clean exit it replaces ``path``, on an exception (also ``KeyboardInterrupt``) it is
    deleted and ``path`` is untouched.

    ``fsync`` flushes the data to disk before the rename. Text mode defaults to UTF-8 with
    ``"\\n"`` newlines. The folder of ``path`` must exist. Stale temporary files of ``path``
    left by killed writers are removed first.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    if mode == "w":
        open_kwargs.setdefault("encoding", "utf-8")
        open_kwargs.setdefault("newline", "\n")
    remove_stale_temporaries(path)
    while True:
        tmp = temporary_name(path)
        try:
            fd = create_exclusive(tmp)
            break
        except FileExistsError:  # 2^-128 odds, or a planted entry: draw another name
            continue
    try:
        with os.fdopen(fd, mode, **open_kwargs) as f:
            yield f
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def new_temporary_folder(path: str | os.PathLike[str]) -> Path:
    """Create a fresh private folder (mode ``0o700``) beside ``path``, named like
    :func:`temporary_name`, for a writer that must be given a file *name* (a library that
    opens the file itself): no other user can plant a link inside it. The caller removes it
    (:func:`shutil.rmtree`); stale ones of killed writers are removed first."""
    path = Path(path)
    remove_stale_temporaries(path)
    while True:
        folder = temporary_name(path)
        try:
            os.mkdir(folder, 0o700)
            return folder
        except FileExistsError:
            continue
