"""A file of biometric data on disk: private to the user, locked against a second process, moved aside whole.

The file is created 0600 (an existing one with broader permissions is fixed, with a warning) in a directory
other users cannot write; it is never opened through a symbolic link and must belong to this user; an
exclusive ``flock`` keeps a second writer out (a read-only open takes none: SQLite's own locks let it read beside
the writer, and it must never keep the master from starting). A damaged file is renamed
``<name>.corrupt-<UTC stamp>`` together with its SQLite ``-wal`` / ``-shm``, which must never be replayed into
a fresh file.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import fcntl
import logging
import os
import stat
from pathlib import Path

from face_reid_master.storage.errors import FaceStoreError, FaceStoreLockedError

__all__ = ["FILE_MODE", "SIDECARS", "ensure_private_parent", "move_aside", "open_locked", "secure_sidecars"]

_LOG = logging.getLogger(__name__)

FILE_MODE = 0o600
_DIR_MODE = 0o700
SIDECARS = ("-wal", "-shm")


def ensure_private_parent(path: Path, read_only: bool) -> None:
    """Create the file's directory (0700) unless ``read_only``; refuse one other users can write."""
    parent = path.parent
    if not parent.exists() and not read_only:
        parent.mkdir(mode=_DIR_MODE, parents=True, exist_ok=True)
        os.chmod(parent, _DIR_MODE)  # mkdir's mode is filtered by the umask
    with contextlib.suppress(FileNotFoundError):
        mode = stat.S_IMODE(os.stat(parent).st_mode)
        if mode & 0o022:
            raise FaceStoreError(
                f"face store directory {parent} can be written by other users (mode {mode:o}): they could "
                "replace or link the database and its -wal; keep it in a private directory (e.g. mode 700)")


def open_locked(path: Path, read_only: bool) -> int:
    """Create (0600) or open the file (never through a symlink, only our own), fix broader permissions, take
    the process lock (exclusive; none when read-only); its file descriptor."""
    flags = os.O_RDONLY if read_only else os.O_RDWR | os.O_CREAT
    # O_NONBLOCK: opening a FIFO (or a device) put there would wait for a writer forever; refused just below
    flags |= os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    for suffix in SIDECARS:  # SQLite opens these itself: a FIFO there would hang it
        _check_regular(Path(str(path) + suffix))
    try:
        fd = os.open(path, flags, FILE_MODE)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise FaceStoreError(f"face store {path} is a symbolic link: give the real path (a link "
                                 "could send the biometric data anywhere)") from None
        raise FaceStoreError(f"cannot open face store {path}: {exc}") from exc
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise FaceStoreError(f"face store {path} is not a regular file ({_kind(info.st_mode)})")
        if info.st_uid != os.geteuid():
            raise FaceStoreError(f"face store {path} belongs to user id {info.st_uid}, not to this user "
                                 f"({os.geteuid()}): refused")
        _restrict(fd, path, stat.S_IMODE(info.st_mode), read_only)
        if read_only:  # a reader takes no flock: it reads beside a running master and never keeps one from starting
            return fd
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as exc:
            raise FaceStoreLockedError(
                f"face store {path} is in use by another process (is the master node running?)") from exc
    except BaseException:
        os.close(fd)
        raise
    return fd


def _kind(mode: int) -> str:
    """What a file that is not a regular one is, in a word (for the error)."""
    for test, kind in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISDIR, "a directory"), (stat.S_ISLNK, "a symbolic link"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device")):
        if test(mode):
            return kind
    return "not a file"


def _check_regular(path: Path) -> None:
    """FaceStoreError when ``path`` exists and is not a regular file (a missing one is fine)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if not stat.S_ISREG(mode):
        raise FaceStoreError(f"face store file {path} is not a regular file ({_kind(mode)}): refused")


def _restrict(fd: int, path: Path, mode: int, read_only: bool) -> None:
    """Permissions broader than 0600 are fixed (read-only: only said)."""
    if not mode & ~FILE_MODE:
        return
    if read_only:
        _LOG.warning("face store %s has permissions %o, broader than 600 for biometric data (left as "
                     "they are: read-only)", path, mode)
        return
    try:
        os.fchmod(fd, FILE_MODE)
    except OSError as exc:
        raise FaceStoreError(
            f"face store {path} has permissions {mode:o} and cannot be restricted to 600: {exc}") from exc
    _LOG.warning("face store %s had permissions %o, broader than 600 for biometric data: fixed to 600", path, mode)


def secure_sidecars(path: Path) -> None:
    """SQLite gives -wal/-shm the database file's mode; enforce 0600 anyway."""
    for suffix in SIDECARS:
        side = Path(str(path) + suffix)
        with contextlib.suppress(FileNotFoundError):
            if stat.S_IMODE(side.stat().st_mode) & ~FILE_MODE:
                os.chmod(side, FILE_MODE)


def move_aside(path: Path) -> Path:
    """Rename the file and its -wal/-shm to ``<name>.corrupt-<UTC stamp>[-n]`` (0600); the new name. The caller
    has released its lock."""
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    backup = path.with_name(f"{path.name}.corrupt-{stamp}")
    n = 1
    while backup.exists():
        backup = path.with_name(f"{path.name}.corrupt-{stamp}-{n}")
        n += 1
    os.replace(path, backup)
    os.chmod(backup, FILE_MODE)
    for suffix in SIDECARS:
        side = Path(str(path) + suffix)
        if side.exists():
            target = Path(str(backup) + suffix)
            os.replace(side, target)
            os.chmod(target, FILE_MODE)
    return backup
