"""Persistent memory of the master: learned faces (biometric data) in one SQLite file, private to the user.

One file (default :func:`default_db_path`) holds every learned face: its id, optional name, counters and
bounded feature set (``LearnedFace`` of :mod:`face_reid_master.identity.records`; written by :mod:`.face_rows`), and
the people named at run time (``face-reid-faces add``: a name and its photos' embeddings, :mod:`.kept_people`, to
which :meth:`FaceStore.save_person` and the like delegate).  Privacy measures:

* the file, its ``-wal``/``-shm`` companions and backups are mode 0600, a directory we create is 0700;
  an existing file with broader permissions is fixed and a warning logged;
* :meth:`FaceStore.forget` / :meth:`~FaceStore.forget_name` / :meth:`~FaceStore.prune_unnamed` delete a
  person's rows with ``PRAGMA secure_delete=ON`` (freed content is zeroed) and then truncate the WAL, so
  the vectors no longer exist in either file (the filesystem/SSD may still hold old blocks: out of reach);
* one writer at a time: a writable store holds an exclusive ``flock`` on the database file, so the CLI cannot
  edit a store a running node would silently overwrite (:class:`FaceStoreLockedError`); a read-only store takes
  no ``flock`` (it never keeps the master from starting) and reads through SQLite's own locks, beside a writer.

Durability: WAL journal, ``synchronous=FULL`` by default (every commit fsyncs the WAL: survives a
``kill -9`` *and* an OS crash / power loss); ``synchronous="NORMAL"`` still survives a process crash
(committed frames are in the OS page cache) but the last commits may be lost on power loss.
Each ``save_face`` is one transaction committed before it returns.

A corrupt file (not SQLite, failing ``PRAGMA integrity_check``, foreign schema or unknown schema version)
is renamed ``<name>.corrupt-<UTC stamp>`` (with its -wal/-shm), an ERROR is logged and an empty store is
started; :attr:`FaceStore.recovered_from` tells the node.  Not thread-safe: use one store from the thread
that created it (sqlite3's ``check_same_thread`` enforces it).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sqlite3
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.predefined_people import check_person_name
from face_reid_master.identity.records import LearnedFace, check_face_id
from face_reid_master.storage.database_file import (
    SCHEMA_VERSION,
    CorruptStore,
    FaceDatabaseFile,
    bump_max_face_id,
    decode_face,
    salvage_faces,
    scrub_wal,
    transaction,
)
from face_reid_master.storage.errors import FaceStoreError, FaceStoreLockedError
from face_reid_master.storage.face_rows import FaceRows
from face_reid_master.storage.id_ledger import IdLedger
from face_reid_master.storage.kept_people import KeptPeople, PersonSummary
from face_reid_master.storage.private_file import ensure_private_parent, move_aside, open_locked, secure_sidecars

__all__ = [
    "SCHEMA_VERSION",
    "FaceStore",
    "FaceStoreError",
    "FaceStoreLockedError",
    "FaceSummary",
    "PersonSummary",
    "default_db_path",
]

_LOG = logging.getLogger(__name__)

@dataclass(frozen=True)
class FaceSummary:
    """One stored face without its vectors (for listings)."""

    face_id: int
    name: str | None
    n_features: int
    n_observations: int
    created_s: float
    last_seen_s: float


def default_db_path() -> Path:
    """``$FACE_REID_DB`` if set, else ``${XDG_DATA_HOME:-~/.local/share}/face_reid/faces.db``."""
    env = os.environ.get("FACE_REID_DB", "").strip()
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_DATA_HOME", "").strip()
    base = Path(xdg).expanduser() if xdg else Path.home() / ".local" / "share"
    return base / "face_reid" / "faces.db"


def _check_face_id(face_id: Any) -> int:
    return check_face_id(face_id)


def _check_name(name: Any) -> str | None:
    return None if name is None else check_person_name(name)


def _check_arguments(path: Any, retention_unnamed_s: Any, embedding_dim: Any, embedding_space: Any,
                     synchronous: Any) -> None:
    """ValueError naming the first argument of :class:`FaceStore` that is out of its range."""
    if not isinstance(path, (str, Path)) or str(path) in ("", ":memory:"):
        raise ValueError(f"path must be a file path, got {path!r}")
    if retention_unnamed_s is not None:
        if isinstance(retention_unnamed_s, bool) or not isinstance(retention_unnamed_s, (int, float)):
            raise ValueError(f"retention_unnamed_s must be a number or None, got {retention_unnamed_s!r}")
        if not (math.isfinite(retention_unnamed_s) and retention_unnamed_s > 0.0):
            raise ValueError(f"retention_unnamed_s must be finite and > 0, got {retention_unnamed_s!r}")
    if embedding_dim is not None and (
        isinstance(embedding_dim, bool) or not isinstance(embedding_dim, int) or embedding_dim < 1
    ):
        raise ValueError(f"embedding_dim must be an int >= 1 or None, got {embedding_dim!r}")
    if synchronous not in ("FULL", "NORMAL"):
        raise ValueError(f"synchronous must be 'FULL' or 'NORMAL', got {synchronous!r}")
    if embedding_space is not None and (not isinstance(embedding_space, str) or not embedding_space):
        raise ValueError(f"embedding_space must be a non-empty str or None, got {embedding_space!r}")


class FaceStore:
    """SQLite-backed persistent memory of learned faces (see the module docstring for the guarantees).

    ``retention_unnamed_s``: unnamed faces not seen for this long are deleted by :meth:`prune_unnamed`
    (None = keep forever).  ``embedding_dim``: length of the stored vectors; a store written with another
    dimension raises :class:`FaceStoreError` (a different embedder: the operator must decide); None adopts
    the stored dimension (128 for a new store).  ``embedding_space``: the embedder space of the vectors
    (e.g. ``dlib_resnet_v1``); a store of another space raises :class:`FaceStoreError` (faces of two
    networks must never be compared); None adopts the stored space. A store written before spaces were
    recorded is taken to be ``dlib_resnet_v1`` (the only embedder then).
    ``synchronous``: "FULL" (default, power-loss safe) or "NORMAL" (process-crash safe).  ``create``:
    False raises :class:`FaceStoreError` when the file does not exist (used by the CLI).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        retention_unnamed_s: float | None = None,
        embedding_dim: int | None = 128,
        embedding_space: str | None = "dlib_resnet_v1",
        synchronous: str = "FULL",
        create: bool = True,
        read_only: bool = False,
    ) -> None:
        _check_arguments(path, retention_unnamed_s, embedding_dim, embedding_space, synchronous)
        self.path = Path(path).expanduser().absolute()
        self.retention_unnamed_s = None if retention_unnamed_s is None else float(retention_unnamed_s)
        self.read_only = bool(read_only)
        # 0 / "": adopt the stored dimension / space
        self._file = FaceDatabaseFile(self.path, read_only=self.read_only, synchronous=synchronous,
                                      embedding_dim=embedding_dim or 0, embedding_space=embedding_space or "")
        self.recovered_from: Path | None = None  # set when a corrupt file was moved aside at open
        self.lost_face_ids: list[int] = []  # saved once, missing from the database at open (reported loudly)
        self.salvaged_face_ids: list[int] = []  # faces read back from a corrupt file moved aside
        self._ledger = IdLedger(self.path)
        self._rows = FaceRows()  # a face saved again rewrites only the feature rows that changed
        self._people = KeptPeople(self._file)
        self._lock_fd: int | None = None
        self._conn: sqlite3.Connection | None = None
        if (not create or self.read_only) and not os.path.lexists(self.path):
            raise FaceStoreError(f"no face store at {self.path}")
        ensure_private_parent(self.path, self.read_only)
        self._lock_fd = open_locked(self.path, self.read_only)
        try:
            salvaged = self._connect()
        except BaseException:
            self._release_lock()
            raise
        if not self.read_only:
            secure_sidecars(self.path)
        self._check_ledger(salvaged)
        self._people.restore_salvaged(self._db)  # a corrupt file's people, written into the fresh store as its faces

    @property
    def embedding_dim(self) -> int:
        """Length of the stored vectors."""
        return self._file.embedding_dim

    @property
    def embedding_space(self) -> str:
        """The embedder space of the stored vectors."""
        return self._file.embedding_space

    # ------------------------------------------------------------------------------ opening
    def _connect(self) -> list[LearnedFace]:
        """Open the database; a corrupt one is moved aside for a fresh one (then its readable faces, to be saved
        into the fresh store, are returned)."""
        assert self._lock_fd is not None
        try:
            self._conn = self._file.connect(self._lock_fd)
            return []
        except CorruptStore as exc:
            if self.read_only:
                raise FaceStoreError(f"face store {self.path} is damaged ({exc}); left as it is (the master moves "
                                     "it aside when it starts)") from None
            try:
                self._recover(str(exc))
            except OSError as exc2:
                raise FaceStoreError(
                    f"face store {self.path} is corrupt ({exc}) and cannot be moved aside: {exc2}") from exc2
            try:
                self._conn = self._file.connect(self._lock_fd)
            except CorruptStore as exc2:  # a fresh file must work; anything else is an I/O problem
                raise FaceStoreError(f"cannot create a fresh face store at {self.path}: {exc2}") from exc2
            return self._salvage(self.recovered_from) if exc.damaged else []

    def _release_lock(self) -> None:
        # close the connection first: closing any fd of the file drops SQLite's POSIX locks of the process
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def _recover(self, reason: str) -> None:
        """Move the corrupt file (and its -wal/-shm, which must not be replayed into a fresh file) aside."""
        self._release_lock()
        backup = move_aside(self.path)
        _LOG.error(
            "FACE STORE CORRUPT: %s (%s). Moved it to %s and started an EMPTY store: previously learned "
            "faces are not loaded.",
            self.path,
            reason,
            backup,
        )
        self.recovered_from = backup
        self._lock_fd = open_locked(self.path, self.read_only)

    def _salvage(self, backup: Path | None) -> list[LearnedFace]:
        """Every face still readable from the corrupt file moved aside (saved into the fresh store by
        :meth:`_check_ledger`), said loudly."""
        if backup is None:
            return []
        faces, total = salvage_faces(backup, self.embedding_dim)
        self._people.salvage(backup)
        self.salvaged_face_ids = sorted(f.face_id for f in faces)
        _LOG.error("FACE STORE CORRUPT: %s: recovered %d of %s faces from %s (ids %s)", self.path, len(faces), total,
                   backup, ", ".join(map(str, self.salvaged_face_ids[:50])) or "none")
        return faces

    def _check_ledger(self, salvaged: list[LearnedFace]) -> None:
        """Compare the database with the id ledger (faces it lost are reported); the ``salvaged`` faces of a
        corrupt file are written first."""
        if salvaged:
            with self._transaction() as conn:
                for face in salvaged:
                    self._rows.write(conn, face, self._rows.encode(face, self.embedding_dim))
                bump_max_face_id(conn, max(f.face_id for f in salvaged))
        self.lost_face_ids = self._ledger.reconcile(set(self.face_ids()), self._meta_max_face_id(),
                                                    write=not self.read_only)

    # ------------------------------------------------------------------------------ helpers
    @property
    def _db(self) -> sqlite3.Connection:
        if self._conn is None:
            raise FaceStoreError("face store is closed")
        return self._conn

    def _transaction(self) -> contextlib.AbstractContextManager[sqlite3.Connection]:
        return transaction(self._db, self.path)

    def _delete_ids(self, face_ids: list[int]) -> None:
        """Delete faces + features in one transaction, then scrub the WAL (secure_delete zeroed the pages)."""
        if not face_ids:
            return
        self._rows.unknown(face_ids)
        with self._transaction() as conn:
            self._rows.delete(conn, face_ids)
        self._ledger.remove(face_ids)
        scrub_wal(self._db, self.path)

    # ------------------------------------------------------------------------------ public API
    def save_face(self, face: LearnedFace) -> None:
        """Insert or replace one face (row + all its features) in one transaction, committed on return."""
        self.save_faces([face])

    def save_faces(self, faces: Iterable[LearnedFace]) -> int:
        """Insert or replace several faces in one transaction (all or nothing); returns how many."""
        batch = [(f, self._rows.encode(f, self.embedding_dim)) for f in faces]
        ids = [f.face_id for f, _ in batch]
        if len(ids) != len(set(ids)):
            raise ValueError("save_faces: duplicate face ids in the batch")
        if not batch:
            return 0
        try:
            with self._transaction() as conn:
                written = {face.face_id: self._rows.write(conn, face, raw) for face, raw in batch}
                bump_max_face_id(conn, max(ids))
        except BaseException:
            self._rows.unknown(ids)  # rolled back: what is stored is not known any more
            raise
        self._rows.committed(written)
        self._ledger.add(ids)
        return len(batch)

    def load_faces(self) -> list[LearnedFace]:
        """All stored faces sorted by id, features in stored order (exact float32 round trip).

        A face whose stored data is invalid (wrong vector length, NaN, no features) is skipped with an
        ERROR log rather than aborting the load.
        """
        conn = self._db
        meta_rows = conn.execute(
            "SELECT face_id, name, created_s, last_seen_s, n_observations FROM faces ORDER BY face_id"
        ).fetchall()
        vectors: dict[int, list[bytes]] = {}
        for face_id, blob in conn.execute("SELECT face_id, vector FROM features ORDER BY face_id, idx"):
            vectors.setdefault(face_id, []).append(blob)
        out: list[LearnedFace] = []
        for row in meta_rows:
            try:
                out.append(decode_face(row, vectors.get(row[0], []), self.embedding_dim))
            except (ValueError, TypeError) as exc:
                _LOG.error("face store %s: skipping invalid stored face %s: %s", self.path, row[0], exc)
        return out

    def list_faces(self) -> list[FaceSummary]:
        """Summaries of all stored faces (no vectors), sorted by id."""
        rows = self._db.execute(
            "SELECT f.face_id, f.name, COUNT(v.idx), f.n_observations, f.created_s, f.last_seen_s "
            "FROM faces f LEFT JOIN features v ON v.face_id = f.face_id GROUP BY f.face_id ORDER BY f.face_id"
        ).fetchall()
        return [FaceSummary(int(r[0]), r[1], int(r[2]), int(r[3]), float(r[4]), float(r[5])) for r in rows]

    def face_ids(self) -> list[int]:
        """Ids of all stored faces, sorted."""
        return [int(r[0]) for r in self._db.execute("SELECT face_id FROM faces ORDER BY face_id")]

    def max_face_id(self) -> int:
        """Largest face id ever saved or reserved in this store (also after it was forgotten, or lost: the
        ledger); 0 if none. New faces get ids above it."""
        return max(self._meta_max_face_id(), self._ledger.max_id)

    def reserve_face_ids(self, upto: int) -> None:
        """Face ids up to ``upto`` may be handed out: durable on return in the database (one transaction) and in
        the id ledger, so that after any restart (even with one of them lost) new faces get ids above; raises
        :class:`FaceStoreError` (e.g. disk full, read-only) and then the caller must not hand them out."""
        upto = _check_face_id(upto)
        if self.read_only:
            raise FaceStoreError(f"face store {self.path} is open read-only: no face id can be reserved")
        with self._transaction() as conn:
            bump_max_face_id(conn, upto)
        self._ledger.reserve(upto)

    def _meta_max_face_id(self) -> int:
        row = self._db.execute("SELECT value FROM meta WHERE key = 'max_face_id'").fetchone()
        return 0 if row is None else int(row[0])

    def set_name(self, face_id: int, name: str | None) -> bool:
        """Set (or clear with None) the name of a stored face; False if the id is not stored."""
        fid = _check_face_id(face_id)
        name = _check_name(name)
        with self._transaction() as conn:
            cur = conn.execute("UPDATE faces SET name = ? WHERE face_id = ?", (name, fid))
        return cur.rowcount > 0

    def forget(self, face_id: int) -> bool:
        """Delete a face and its vectors for good (zeroed pages, WAL truncated); False if not stored."""
        fid = _check_face_id(face_id)
        if self._db.execute("SELECT 1 FROM faces WHERE face_id = ?", (fid,)).fetchone() is None:
            return False
        self._delete_ids([fid])
        _LOG.info("face store %s: forgot face %d", self.path, fid)
        return True

    def forget_faces(self, face_ids: Iterable[int]) -> list[int]:
        """Delete several faces in one transaction (as :meth:`forget`); returns the ids that were stored."""
        wanted = sorted({_check_face_id(f) for f in face_ids})
        ids = [f for f in wanted if self._db.execute("SELECT 1 FROM faces WHERE face_id = ?", (f,)).fetchone()]
        self._delete_ids(ids)
        if ids:
            _LOG.info("face store %s: forgot faces %s", self.path, ids[:50])
        return ids

    def forget_name(self, name: str) -> list[int]:
        """Delete every face with exactly this name (case-sensitive); returns their ids."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty str, got {name!r}")
        rows = self._db.execute("SELECT face_id FROM faces WHERE name = ? ORDER BY face_id", (name,))
        ids = [int(r[0]) for r in rows]
        self._delete_ids(ids)
        if ids:
            _LOG.info("face store %s: forgot faces %s named %r", self.path, ids, name)
        return ids

    def prune_unnamed(self, now_s: float, keep: Iterable[int] = ()) -> list[int]:
        """Retention: delete unnamed faces with ``last_seen_s < now_s - retention_unnamed_s``.

        ``keep``: face ids never pruned (the node passes faces carried by live tracks, whose stored
        ``last_seen_s`` may be stale).  Returns the deleted ids ([] when retention is None).  The node
        must also :meth:`~face_reid_master.identity.algorithm1.IdentityManagerBase.forget_face` them.
        """
        ids = self.prunable_unnamed(now_s, keep)
        self._delete_ids(ids)
        if ids:
            _LOG.info("face store %s: retention pruned unnamed faces %s", self.path, ids)
        return ids

    def prunable_unnamed(self, now_s: float, keep: Iterable[int] = ()) -> list[int]:
        """The ids :meth:`prune_unnamed` would delete at ``now_s`` (nothing is deleted): the node warns with their
        number when a (new) retention is about to delete stored faces."""
        if isinstance(now_s, bool) or not isinstance(now_s, (int, float, np.floating, np.integer)):
            raise ValueError(f"now_s must be a number of seconds, got {now_s!r}")
        if not math.isfinite(float(now_s)):
            raise ValueError(f"now_s must be finite, got {now_s!r}")
        if self.retention_unnamed_s is None:
            return []
        keep_ids = {_check_face_id(k) for k in keep}
        cutoff = float(now_s) - self.retention_unnamed_s
        return [
            int(r[0])
            for r in self._db.execute(
                "SELECT face_id FROM faces WHERE name IS NULL AND last_seen_s < ? ORDER BY face_id", (cutoff,)
            )
            if int(r[0]) not in keep_ids
        ]

    # ------------------------------------------------------------------------------ people named at run time
    def save_person(self, name: str, embeddings: Any, added_s: float | None = None) -> int:
        """Keep (or replace) a person named at run time: :meth:`KeptPeople.save`."""
        return self._people.save(self._db, name, embeddings, added_s)

    def load_people(self) -> dict[str, npt.NDArray[np.float32]]:
        """The people named at run time, name -> embeddings: :meth:`KeptPeople.load`."""
        return self._people.load(self._db)

    def list_people(self) -> list[PersonSummary]:
        """Summaries of the people named at run time, sorted by name: :meth:`KeptPeople.summaries`."""
        return self._people.summaries(self._db)

    def forget_person(self, name: str) -> bool:
        """Delete a person named at run time for good: :meth:`KeptPeople.forget`."""
        return self._people.forget(self._db, name)

    def integrity_ok(self) -> bool:
        """Run ``PRAGMA integrity_check`` now (diagnostics)."""
        return [r[0] for r in self._db.execute("PRAGMA integrity_check").fetchall()] == ["ok"]

    def close(self) -> None:
        """Checkpoint, close the database and release the process lock (idempotent)."""
        if self._conn is not None:
            try:
                if not self.read_only:
                    with contextlib.suppress(sqlite3.Error):
                        self._conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
                self._conn.close()
            finally:
                self._conn = None
                self._release_lock()
        else:
            self._release_lock()

    def __enter__(self) -> FaceStore:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()
