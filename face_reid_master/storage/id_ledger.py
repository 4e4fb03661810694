"""The face store's id ledger: a sidecar ``<db>.ids`` listing the face ids saved (ids only, no biometric data).

With it, faces the database lost (a damaged or deleted ``-wal``, a replaced file) are reported at start, and a
face id is never given twice, even when the database lost its last writes: ``max`` is the highest id saved *or
reserved* (:meth:`IdLedger.reserve`: the master hands out no id before it is durable here). Replaced atomically
(temporary file, fsync, rename, directory fsync), mode 0600; a damaged or unreadable ledger is said and started
afresh.
"""

from __future__ import annotations

import contextlib
import logging
import os
import stat
from collections.abc import Iterable
from pathlib import Path

from face_reid_master.storage.errors import FaceStoreError
from face_reid_master.storage.private_file import FILE_MODE

__all__ = ["IdLedger"]

_LOG = logging.getLogger(__name__)
_SUFFIX = ".ids"
_FORMAT = "face_reid_ids/1"
_MAX_BYTES = 10_000_000


class IdLedger:
    """The face ids saved and the highest id ever given or reserved, as the sidecar of database ``db_path`` keeps
    them."""

    def __init__(self, db_path: Path) -> None:
        self.db_path = db_path
        self.path = Path(str(db_path) + _SUFFIX)
        self.ids: set[int] = set()
        self.max_id = 0

    def read(self) -> tuple[int, set[int]]:
        """The highest id and the ids the file holds ((0, {}) when there is none or it cannot be read: said)."""
        try:
            # O_NONBLOCK: a FIFO put in its place must not hang the open (it is refused just below)
            fd = os.open(self.path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            return 0, set()
        except OSError as exc:
            _LOG.error("face store %s: cannot read the id ledger %s (%s): lost faces cannot be detected",
                       self.db_path, self.path, exc)
            return 0, set()
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            _LOG.error("face store %s: the id ledger %s is not a regular file: lost faces cannot be detected",
                       self.db_path, self.path)
            return 0, set()
        with os.fdopen(fd, "r", encoding="ascii", errors="replace") as f:
            lines = f.read(_MAX_BYTES).splitlines()
        try:
            if lines[0] != _FORMAT:
                raise ValueError(f"unknown format {lines[0][:40]!r}")
            return int(lines[1].split()[1]), {int(v) for v in lines[2].split()[1:]}
        except (IndexError, ValueError) as exc:
            _LOG.error("face store %s: the id ledger %s is damaged (%s): lost faces cannot be detected this time",
                       self.db_path, self.path, exc)
            return 0, set()

    def reconcile(self, stored: set[int], stored_max: int, write: bool) -> list[int]:
        """Take the database's ``stored`` ids and its highest id ``stored_max`` against the file: the ids the
        database lost (said loudly; new faces get ids above every id ever given), the file rewritten (``write``)
        when it differs."""
        ledger_max, ledger_ids = self.read()
        lost = sorted(ledger_ids - stored)
        self.max_id = max(ledger_max, stored_max, max(stored, default=0))
        if lost:
            _LOG.error(
                "FACE STORE LOST FACES: %s: faces %s were saved but are not in the database (its last writes were "
                "lost: a damaged or deleted -wal, or a replaced file); new faces get ids above %d, never these",
                self.db_path, ", ".join(map(str, lost[:50])), self.max_id)
        self.ids = set(stored)
        if write and (ledger_ids != stored or ledger_max != self.max_id):
            self.write()
        return lost

    def add(self, face_ids: Iterable[int]) -> None:
        """Faces were saved: the file is rewritten when one is new."""
        new = set(face_ids) - self.ids
        if new:
            self.ids |= new
            self.max_id = max(self.max_id, *new)
            self.write()

    def reserve(self, upto: int) -> None:
        """Ids up to ``upto`` may be handed out: durable in the file on return (FaceStoreError, nothing reserved,
        when it cannot be written)."""
        if upto <= self.max_id:
            return
        before, self.max_id = self.max_id, upto
        try:
            self.write()
        except FaceStoreError:
            self.max_id = before
            raise

    def remove(self, face_ids: Iterable[int]) -> None:
        """Faces were deleted (their ids stay given: the highest id is kept)."""
        self.ids -= set(face_ids)
        self.write()

    def write(self) -> None:
        """Replace the file atomically with :attr:`ids` and :attr:`max_id`."""
        text = f"{_FORMAT}\nmax {self.max_id}\nids {' '.join(map(str, sorted(self.ids)))}\n"
        tmp = Path(str(self.path) + ".tmp")
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0),
                         FILE_MODE)
            with os.fdopen(fd, "w", encoding="ascii") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
            dfd = os.open(self.path.parent, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError as exc:
            raise FaceStoreError(f"face store {self.db_path}: cannot write the id ledger: {exc}") from exc
