"""Persistent memory of the master: learned faces (biometric data) in one SQLite file, private to the user.

One file (default :func:`default_db_path`) holds every learned face: its id, optional name, counters and
bounded feature set (``LearnedFace`` of :mod:`face_reid_master.identity.records`).  Privacy measures:

* the file, its ``-wal``/``-shm`` companions and backups are mode 0600, a directory we create is 0700;
  an existing file with broader permissions is fixed and a warning logged;
* :meth:`FaceStore.forget` / :meth:`~FaceStore.forget_name` / :meth:`~FaceStore.prune_unnamed` delete a
  person's rows with ``PRAGMA secure_delete=ON`` (freed content is zeroed) and then truncate the WAL, so
  the vectors no longer exist in either file (the filesystem/SSD may still hold old blocks: out of reach);
* one process at a time: the store holds an exclusive ``flock`` on the database file, so the CLI cannot
  edit a store a running node would silently overwrite (:class:`FaceStoreLockedError`).

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
import dataclasses
import datetime as _dt
import errno
import fcntl
import logging
import math
import os
import sqlite3
import stat
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.predefined_people import check_person_name
from face_reid_master.identity.records import LearnedFace, check_face_id

__all__ = [
    "SCHEMA_VERSION",
    "FaceStore",
    "FaceStoreError",
    "FaceStoreLockedError",
    "FaceSummary",
    "default_db_path",
]

_LOG = logging.getLogger(__name__)

SCHEMA_VERSION = 1
_FILE_MODE = 0o600
_DIR_MODE = 0o700
_SIDECARS = ("-wal", "-shm")
_LEDGER_SUFFIX = ".ids"  # face ids ever saved (no biometric data): lost rows are detected, ids never reused
_LEDGER_FORMAT = "face_reid_ids/1"
_DEFAULT_DIM = 128
_LEGACY_SPACE = "dlib_resnet_v1"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_VECTOR_DTYPE = np.dtype("<f4")  # little-endian float32 on every platform

_SCHEMA = f"""
CREATE TABLE meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE faces (
    face_id INTEGER PRIMARY KEY CHECK (face_id >= 1),
    name TEXT NULL,
    created_s REAL NOT NULL,
    last_seen_s REAL NOT NULL,
    n_observations INTEGER NOT NULL CHECK (n_observations >= 0)
);
CREATE TABLE features (
    face_id INTEGER NOT NULL REFERENCES faces(face_id) ON DELETE CASCADE,
    idx INTEGER NOT NULL CHECK (idx >= 0),
    vector BLOB NOT NULL,
    PRIMARY KEY (face_id, idx)
) WITHOUT ROWID;
CREATE INDEX faces_name ON faces(name);
INSERT INTO meta(key, value) VALUES ('schema_version', '{SCHEMA_VERSION}');
"""
_EXPECTED_TABLES = {"meta", "faces", "features"}
# tables earlier versions kept beside the faces (body pairs of a retired online body-metric update): dropped on open
_RETIRED_TABLES = ("body_pairs",)
_RETIRED_META = ("body_pairs_subspace",)


class FaceStoreError(RuntimeError):
    """The face store cannot be used (configuration or I/O problem; corruption is recovered instead)."""


class FaceStoreLockedError(FaceStoreError):
    """Another process (normally the running master node) has the store open."""


class _CorruptStore(Exception):
    """Internal: the file is not a usable face store (reason in args[0]); ``damaged``: a face store whose file
    was damaged (its readable faces are worth salvaging), not another format or schema."""

    def __init__(self, reason: str, damaged: bool = False) -> None:
        super().__init__(reason)
        self.damaged = damaged


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


def _utc_stamp() -> str:
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")


def _check_face_id(face_id: Any) -> int:
    return check_face_id(face_id)


def _check_name(name: Any) -> str | None:
    return None if name is None else check_person_name(name)


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
        if not isinstance(path, (str, Path)) or str(path) in ("", ":memory:"):
            raise ValueError(f"path must be a file path, got {path!r}")
        if retention_unnamed_s is not None:
            if isinstance(retention_unnamed_s, bool) or not isinstance(retention_unnamed_s, (int, float)):
                raise ValueError(f"retention_unnamed_s must be a number or None, got {retention_unnamed_s!r}")
            if not (math.isfinite(retention_unnamed_s) and retention_unnamed_s > 0.0):
                raise ValueError(f"retention_unnamed_s must be finite and > 0, got {retention_unnamed_s!r}")
            retention_unnamed_s = float(retention_unnamed_s)
        if embedding_dim is not None and (
            isinstance(embedding_dim, bool) or not isinstance(embedding_dim, int) or embedding_dim < 1
        ):
            raise ValueError(f"embedding_dim must be an int >= 1 or None, got {embedding_dim!r}")
        if synchronous not in ("FULL", "NORMAL"):
            raise ValueError(f"synchronous must be 'FULL' or 'NORMAL', got {synchronous!r}")
        self.path = Path(path).expanduser().absolute()
        self.retention_unnamed_s = retention_unnamed_s
        self.embedding_dim: int = 0 if embedding_dim is None else embedding_dim  # 0: take the store's
        if embedding_space is not None and (not isinstance(embedding_space, str) or not embedding_space):
            raise ValueError(f"embedding_space must be a non-empty str or None, got {embedding_space!r}")
        self.embedding_space: str = embedding_space or ""  # "": take the store's
        self.synchronous = synchronous
        self.read_only = bool(read_only)
        self.recovered_from: Path | None = None  # set when a corrupt file was moved aside at open
        self.lost_face_ids: list[int] = []  # saved once, missing from the database at open (reported loudly)
        self.salvaged_face_ids: list[int] = []  # faces read back from a corrupt file moved aside
        self._ledger_ids: set[int] = set()
        self._ledger_max = 0
        # face id -> (hash of all its features, hash of each row), as this connection last committed them: a face
        # saved again rewrites only the rows that changed (the feature bank replaces one row at a time), none
        # when its features did not change (then only its counters)
        self._row_hashes: dict[int, tuple[int, list[int]]] = {}
        self._lock_fd: int | None = None
        self._conn: sqlite3.Connection | None = None
        if (not create or self.read_only) and not os.path.lexists(self.path):
            raise FaceStoreError(f"no face store at {self.path}")
        self._ensure_parent()
        self._open_locked_file()
        salvaged: list[LearnedFace] = []
        try:
            self._conn = self._connect_and_validate()
        except _CorruptStore as exc:
            if self.read_only:
                self._release_lock()
                raise FaceStoreError(f"face store {self.path} is damaged ({exc}); left as it is (the master moves "
                                     "it aside when it starts)") from None
            try:
                self._recover(str(exc))
            except OSError as exc2:
                self._release_lock()
                raise FaceStoreError(
                    f"face store {self.path} is corrupt ({exc}) and cannot be moved aside: {exc2}"
                ) from exc2
            try:
                self._conn = self._connect_and_validate()
            except _CorruptStore as exc2:  # a fresh file must work; anything else is an I/O problem
                self._release_lock()
                raise FaceStoreError(f"cannot create a fresh face store at {self.path}: {exc2}") from exc2
            salvaged = self._salvage(self.recovered_from) if exc.damaged else []
        except BaseException:
            self._release_lock()
            raise
        if not self.read_only:
            self._secure_sidecars()
        self._check_ledger(salvaged)

    # ------------------------------------------------------------------------------ opening
    def _ensure_parent(self) -> None:
        parent = self.path.parent
        if not parent.exists() and not self.read_only:
            parent.mkdir(mode=_DIR_MODE, parents=True, exist_ok=True)
            os.chmod(parent, _DIR_MODE)  # mkdir's mode is filtered by the umask
        with contextlib.suppress(FileNotFoundError):
            mode = stat.S_IMODE(os.stat(parent).st_mode)
            if mode & 0o022:
                raise FaceStoreError(
                    f"face store directory {parent} can be written by other users (mode {mode:o}): they could "
                    "replace or link the database and its -wal; keep it in a private directory (e.g. mode 700)")

    def _open_locked_file(self) -> None:
        """Create (0600) or open the file (never through a symlink, only our own), fix broader permissions, take
        the process lock (exclusive; shared when read-only)."""
        flags = os.O_RDONLY if self.read_only else os.O_RDWR | os.O_CREAT
        flags |= os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
        try:
            fd = os.open(self.path, flags, _FILE_MODE)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise FaceStoreError(f"face store {self.path} is a symbolic link: give the real path (a link "
                                     "could send the biometric data anywhere)") from None
            raise FaceStoreError(f"cannot open face store {self.path}: {exc}") from exc
        try:
            info = os.fstat(fd)
            if not stat.S_ISREG(info.st_mode):
                raise FaceStoreError(f"face store {self.path} is not a regular file")
            if info.st_uid != os.geteuid():
                raise FaceStoreError(f"face store {self.path} belongs to user id {info.st_uid}, not to this user "
                                     f"({os.geteuid()}): refused")
            mode = stat.S_IMODE(info.st_mode)
            if mode & ~_FILE_MODE and self.read_only:
                _LOG.warning("face store %s has permissions %o, broader than 600 for biometric data (left as "
                             "they are: read-only)", self.path, mode)
            elif mode & ~_FILE_MODE:
                try:
                    os.fchmod(fd, _FILE_MODE)
                except OSError as exc:
                    raise FaceStoreError(
                        f"face store {self.path} has permissions {mode:o} and cannot be restricted to 600: {exc}"
                    ) from exc
                _LOG.warning(
                    "face store %s had permissions %o, broader than 600 for biometric data: fixed to 600",
                    self.path,
                    mode,
                )
            try:
                fcntl.flock(fd, (fcntl.LOCK_SH if self.read_only else fcntl.LOCK_EX) | fcntl.LOCK_NB)
            except BlockingIOError as exc:
                raise FaceStoreLockedError(
                    f"face store {self.path} is in use by another process (is the master node running?)"
                ) from exc
        except BaseException:
            os.close(fd)
            raise
        self._lock_fd = fd

    def _release_lock(self) -> None:
        # close the connection first: closing any fd of the file drops SQLite's POSIX locks of the process
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None

    def _connect_and_validate(self) -> sqlite3.Connection:
        assert self._lock_fd is not None
        head = os.pread(self._lock_fd, len(_SQLITE_MAGIC), 0)
        if head and head != _SQLITE_MAGIC:
            # Never hand a foreign file to SQLite: with a -wal beside it, closing would delete that -wal.
            # (An empty file is fine: a new store, or one whose whole content is still in the WAL.)
            raise _CorruptStore("not an SQLite database (bad header)")
        try:
            if self.read_only:
                conn = sqlite3.connect(f"{self.path.as_uri()}?mode=ro", uri=True, isolation_level=None, timeout=5.0)
            else:
                conn = sqlite3.connect(self.path, isolation_level=None, timeout=5.0)
        except sqlite3.Error as exc:
            raise FaceStoreError(f"cannot open face store {self.path}: {exc}") from exc
        try:
            # connection-level settings only: nothing may touch a file we have not recognised yet
            conn.execute("PRAGMA secure_delete=ON")
            conn.execute("PRAGMA foreign_keys=ON")
            conn.execute("PRAGMA trusted_schema=OFF")
            self._validate_or_init(conn)
            if not self.read_only:
                self._enable_wal(conn)
                conn.execute(f"PRAGMA synchronous={self.synchronous}")
                self._drop_retired(conn)
        except BaseException:
            conn.close()
            raise
        return conn

    @staticmethod
    def _drop_retired(conn: sqlite3.Connection) -> None:
        """Delete what earlier versions stored beside the faces and no longer use (secure_delete zeroes it; the
        WAL is truncated once the store is open)."""
        present = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()}
        retired = [t for t in _RETIRED_TABLES if t in present]
        if not retired:
            return
        conn.execute("BEGIN IMMEDIATE")
        for table in retired:
            conn.execute(f"DROP TABLE {table}")
        conn.executemany("DELETE FROM meta WHERE key = ?", [(k,) for k in _RETIRED_META])
        conn.execute("COMMIT")
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")

    def _enable_wal(self, conn: sqlite3.Connection) -> None:
        try:
            mode = conn.execute("PRAGMA journal_mode=WAL").fetchone()[0]
        except sqlite3.DatabaseError as exc:
            raise _CorruptStore(f"cannot switch to WAL ({exc})") from exc
        if str(mode).lower() != "wal":
            raise FaceStoreError(f"face store {self.path}: cannot enable the WAL journal (got {mode!r})")

    def _validate_or_init(self, conn: sqlite3.Connection) -> None:
        try:
            check = [r[0] for r in conn.execute("PRAGMA integrity_check").fetchall()]
            if check != ["ok"]:
                raise _CorruptStore("integrity_check failed: " + "; ".join(str(c) for c in check[:5]), damaged=True)
            tables = {
                r[0]
                for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
                if not str(r[0]).startswith("sqlite_")
            }
            if not tables and self.read_only:
                raise _CorruptStore("an empty file, not a face store")
            if not tables:
                if not self.embedding_dim:
                    self.embedding_dim = _DEFAULT_DIM
                self._enable_wal(conn)  # before the first write: the schema goes straight into the WAL
                conn.executescript("BEGIN IMMEDIATE;" + _SCHEMA + "COMMIT;")
                self._set_meta(conn, "embedding_dim", str(self.embedding_dim))
                self.embedding_space = self.embedding_space or _LEGACY_SPACE
                self._set_meta(conn, "embedding_space", self.embedding_space)
                return
            if not _EXPECTED_TABLES <= tables:
                raise _CorruptStore(f"not a face store (tables {sorted(tables)})")
            meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
            if meta.get("schema_version") != str(SCHEMA_VERSION):
                raise _CorruptStore(f"unknown schema version {meta.get('schema_version')!r}")
            dim = meta.get("embedding_dim")
            if not self.embedding_dim:  # embedding_dim=None: adopt the store's (tools such as the CLI)
                self.embedding_dim = int(dim) if dim is not None and dim.isdigit() and int(dim) > 0 else _DEFAULT_DIM
            if dim is None and not self.read_only:
                self._set_meta(conn, "embedding_dim", str(self.embedding_dim))
            elif dim != str(self.embedding_dim):
                raise FaceStoreError(
                    f"face store {self.path} holds {dim}-dimensional features but embedding_dim is "
                    f"{self.embedding_dim} (a different embedder?): use another file or delete this one"
                )
            space = meta.get("embedding_space")
            if space is None:  # written before spaces were recorded: the dlib embedder was the only one
                space = _LEGACY_SPACE
                if (not self.embedding_space or self.embedding_space == space) and not self.read_only:
                    self._set_meta(conn, "embedding_space", space)
            if not self.embedding_space:
                self.embedding_space = space
            elif space != self.embedding_space:
                raise FaceStoreError(
                    f"face store {self.path} holds faces of embedder space {space!r} but this master compares "
                    f"{self.embedding_space!r}: faces of different networks cannot be compared; set the master's "
                    f"embedding_space to {space!r} to keep using these faces (the cameras must send that space or "
                    "a joint one containing it), or give db_path another file to start a new memory"
                )
        except sqlite3.DatabaseError as exc:
            raise _CorruptStore(f"unreadable database ({exc})", damaged=True) from exc

    @staticmethod
    def _set_meta(conn: sqlite3.Connection, key: str, value: str) -> None:
        conn.execute(
            "INSERT INTO meta(key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = excluded.value",
            (key, value),
        )

    def _recover(self, reason: str) -> None:
        """Move the corrupt file (and its -wal/-shm, which must not be replayed into a fresh file) aside."""
        stamp = _utc_stamp()
        backup = self.path.with_name(f"{self.path.name}.corrupt-{stamp}")
        n = 1
        while backup.exists():
            backup = self.path.with_name(f"{self.path.name}.corrupt-{stamp}-{n}")
            n += 1
        self._release_lock()
        os.replace(self.path, backup)
        os.chmod(backup, _FILE_MODE)
        for suffix in _SIDECARS:
            side = Path(str(self.path) + suffix)
            if side.exists():
                target = Path(str(backup) + suffix)
                os.replace(side, target)
                os.chmod(target, _FILE_MODE)
        _LOG.error(
            "FACE STORE CORRUPT: %s (%s). Moved it to %s and started an EMPTY store: previously learned "
            "faces are not loaded.",
            self.path,
            reason,
            backup,
        )
        self.recovered_from = backup
        self._open_locked_file()

    def _salvage(self, backup: Path | None) -> list[LearnedFace]:
        """Every face still readable from the corrupt file moved aside (saved into the fresh store by
        :meth:`_check_ledger`), said loudly (a damaged index or page rarely takes every face with it)."""
        if backup is None:
            return []
        faces: list[LearnedFace] = []
        total: int | str = "?"
        try:
            conn = sqlite3.connect(f"{backup.as_uri()}?mode=ro", uri=True)
        except sqlite3.Error:
            return []
        try:
            conn.execute("PRAGMA trusted_schema=OFF")
            rows = conn.execute("SELECT face_id, name, created_s, last_seen_s, n_observations FROM faces").fetchall()
            total = len(rows)
            for row in rows:
                try:
                    blobs = [b for (b,) in conn.execute(
                        "SELECT vector FROM features WHERE face_id = ? ORDER BY idx", (row[0],))]
                    face = self._decode_face(row, blobs)
                    try:
                        name = _check_name(face.name)
                    except ValueError:  # a name that is no longer accepted is dropped, not the face
                        name = None
                    faces.append(dataclasses.replace(face, name=name))
                except (sqlite3.Error, ValueError, TypeError, OverflowError):
                    continue
        except sqlite3.Error:
            pass
        finally:
            conn.close()
        self.salvaged_face_ids = sorted(f.face_id for f in faces)
        _LOG.error("FACE STORE CORRUPT: %s: recovered %d of %s faces from %s (ids %s)", self.path, len(faces), total,
                   backup, ", ".join(map(str, self.salvaged_face_ids[:50])) or "none")
        return faces

    def _secure_sidecars(self) -> None:
        """SQLite gives -wal/-shm the database file's mode; enforce 0600 anyway."""
        for suffix in _SIDECARS:
            side = Path(str(self.path) + suffix)
            with contextlib.suppress(FileNotFoundError):
                if stat.S_IMODE(side.stat().st_mode) & ~_FILE_MODE:
                    os.chmod(side, _FILE_MODE)

    # ------------------------------------------------------------------------------ id ledger
    @property
    def ledger_path(self) -> Path:
        """The sidecar listing the face ids saved (ids only): lost database rows are detected with it and face
        ids are never reused, even when the database lost its last writes or was replaced."""
        return Path(str(self.path) + _LEDGER_SUFFIX)

    def _check_ledger(self, salvaged: list[LearnedFace]) -> None:
        """Compare the database with the ledger: report faces it lost (loudly), keep the id high-water mark;
        the ``salvaged`` faces of a corrupt file are written first."""
        ledger_max, ledger_ids = self._read_ledger()
        if salvaged:
            with self._transaction() as conn:
                for face in salvaged:
                    self._write_face(conn, face, self._encode(face))
                self._bump_max_face_id(conn, max(f.face_id for f in salvaged))
        stored = set(self.face_ids())
        self.lost_face_ids = sorted(ledger_ids - stored)
        self._ledger_max = max(ledger_max, self._meta_max_face_id(), max(stored, default=0))
        if self.lost_face_ids:
            _LOG.error(
                "FACE STORE LOST FACES: %s: faces %s were saved but are not in the database (its last writes were "
                "lost: a damaged or deleted -wal, or a replaced file); new faces get ids above %d, never these",
                self.path, ", ".join(map(str, self.lost_face_ids[:50])), self._ledger_max)
        self._ledger_ids = stored
        if not self.read_only and (ledger_ids != stored or ledger_max != self._ledger_max):
            self._write_ledger()

    def _read_ledger(self) -> tuple[int, set[int]]:
        try:
            fd = os.open(self.ledger_path, os.O_RDONLY | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0))
        except FileNotFoundError:
            return 0, set()
        except OSError as exc:
            _LOG.error("face store %s: cannot read the id ledger %s (%s): lost faces cannot be detected",
                       self.path, self.ledger_path, exc)
            return 0, set()
        with os.fdopen(fd, "r", encoding="ascii", errors="replace") as f:
            lines = f.read(10_000_000).splitlines()
        try:
            if lines[0] != _LEDGER_FORMAT:
                raise ValueError(f"unknown format {lines[0][:40]!r}")
            return int(lines[1].split()[1]), {int(v) for v in lines[2].split()[1:]}
        except (IndexError, ValueError) as exc:
            _LOG.error("face store %s: the id ledger %s is damaged (%s): lost faces cannot be detected this time",
                       self.path, self.ledger_path, exc)
            return 0, set()

    def _write_ledger(self) -> None:
        """Replace the ledger atomically (temporary file, fsync, rename, directory fsync)."""
        text = f"{_LEDGER_FORMAT}\nmax {self._ledger_max}\nids {' '.join(map(str, sorted(self._ledger_ids)))}\n"
        tmp = Path(str(self.ledger_path) + ".tmp")
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0),
                         _FILE_MODE)
            with os.fdopen(fd, "w", encoding="ascii") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.ledger_path)
            dfd = os.open(self.path.parent, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError as exc:
            raise FaceStoreError(f"face store {self.path}: cannot write the id ledger: {exc}") from exc

    def _note_saved(self, face_ids: Iterable[int]) -> None:
        new = set(face_ids) - self._ledger_ids
        if new:
            self._ledger_ids |= new
            self._ledger_max = max(self._ledger_max, *new)
            self._write_ledger()

    # ------------------------------------------------------------------------------ helpers
    @property
    def _db(self) -> sqlite3.Connection:
        if self._conn is None:
            raise FaceStoreError("face store is closed")
        return self._conn

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        conn = self._db
        try:
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield conn
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    with contextlib.suppress(sqlite3.Error):
                        conn.execute("ROLLBACK")
                raise
        except sqlite3.Error as exc:
            raise FaceStoreError(f"face store {self.path}: {exc}") from exc

    def _encode(self, face: LearnedFace) -> npt.NDArray[np.float32]:
        """The face's features as stored (contiguous little-endian float32); ValueError for an invalid face."""
        if not isinstance(face, LearnedFace):
            raise ValueError(f"expected a LearnedFace, got {type(face).__name__}")
        feats = face.features
        if feats.shape[1] != self.embedding_dim:
            raise ValueError(
                f"face {face.face_id}: features have dim {feats.shape[1]}, expected {self.embedding_dim}"
            )
        if not np.all(np.isfinite(feats)):
            raise ValueError(f"face {face.face_id}: features contain NaN or Inf")
        return np.ascontiguousarray(feats, dtype=_VECTOR_DTYPE)

    def _write_face(self, conn: sqlite3.Connection, face: LearnedFace, raw: npt.NDArray[np.float32]
                    ) -> tuple[int, list[int]]:
        """Upsert the face's row and its feature rows; returns the hash of all its features and of each row (for
        :attr:`_row_hashes` once committed). Only rows that differ from what this connection last committed are
        written (none when no feature changed), when the stored row count still matches (else, e.g. after
        another process touched the face, all of them)."""
        fid = face.face_id
        conn.execute(
            "INSERT INTO faces(face_id, name, created_s, last_seen_s, n_observations) VALUES (?, ?, ?, ?, ?) "
            "ON CONFLICT(face_id) DO UPDATE SET name = excluded.name, created_s = excluded.created_s, "
            "last_seen_s = excluded.last_seen_s, n_observations = excluded.n_observations",
            (fid, face.name, face.created_s, face.last_seen_s, face.n_observations),
        )
        digest = hash(raw.tobytes())
        old = self._row_hashes.get(fid)
        same_count = old is not None and conn.execute("SELECT COUNT(*) FROM features WHERE face_id = ?",
                                                      (fid,)).fetchone()[0] == len(old[1])
        if same_count and old is not None and old[0] == digest and len(old[1]) == raw.shape[0]:
            return old  # the features are stored as they are
        rows = [(fid, i, raw[i].tobytes()) for i in range(raw.shape[0])]
        hashes = [hash(r[2]) for r in rows]
        if same_count and old is not None:
            changed = [r for i, r in enumerate(rows) if i >= len(old[1]) or old[1][i] != hashes[i]]
            conn.executemany("INSERT INTO features(face_id, idx, vector) VALUES (?, ?, ?) "
                             "ON CONFLICT(face_id, idx) DO UPDATE SET vector = excluded.vector", changed)
            if len(old[1]) > len(rows):
                conn.execute("DELETE FROM features WHERE face_id = ? AND idx >= ?", (fid, len(rows)))
        else:
            conn.execute("DELETE FROM features WHERE face_id = ?", (fid,))
            conn.executemany("INSERT INTO features(face_id, idx, vector) VALUES (?, ?, ?)", rows)
        return digest, hashes

    @staticmethod
    def _bump_max_face_id(conn: sqlite3.Connection, face_id: int) -> None:
        conn.execute(
            "INSERT INTO meta(key, value) VALUES ('max_face_id', ?) ON CONFLICT(key) DO UPDATE SET "
            "value = CAST(MAX(CAST(value AS INTEGER), CAST(excluded.value AS INTEGER)) AS TEXT)",
            (str(face_id),),
        )

    def _delete_ids(self, face_ids: list[int]) -> None:
        """Delete faces + features in one transaction, then scrub the WAL (secure_delete zeroed the pages)."""
        if not face_ids:
            return
        for f in face_ids:
            self._row_hashes.pop(f, None)
        with self._transaction() as conn:
            conn.executemany("DELETE FROM features WHERE face_id = ?", [(f,) for f in face_ids])
            conn.executemany("DELETE FROM faces WHERE face_id = ?", [(f,) for f in face_ids])
        self._ledger_ids -= set(face_ids)
        self._write_ledger()
        self._scrub_wal()

    def _scrub_wal(self) -> None:
        """Checkpoint every WAL frame into the (zeroed) database pages and truncate the WAL to 0 bytes."""
        try:
            busy, _, _ = self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
        except sqlite3.Error as exc:
            raise FaceStoreError(f"face store {self.path}: WAL checkpoint failed: {exc}") from exc
        if busy:
            _LOG.warning(
                "face store %s: WAL checkpoint blocked by a reader; deleted data may stay in %s-wal until "
                "the next checkpoint",
                self.path,
                self.path.name,
            )

    # ------------------------------------------------------------------------------ public API
    def save_face(self, face: LearnedFace) -> None:
        """Insert or replace one face (row + all its features) in one transaction, committed on return."""
        self.save_faces([face])

    def save_faces(self, faces: Iterable[LearnedFace]) -> int:
        """Insert or replace several faces in one transaction (all or nothing); returns how many."""
        batch = [(f, self._encode(f)) for f in faces]
        ids = [f.face_id for f, _ in batch]
        if len(ids) != len(set(ids)):
            raise ValueError("save_faces: duplicate face ids in the batch")
        if not batch:
            return 0
        try:
            with self._transaction() as conn:
                written = {face.face_id: self._write_face(conn, face, raw) for face, raw in batch}
                self._bump_max_face_id(conn, max(ids))
        except BaseException:
            for fid in ids:  # rolled back: what is stored is not known any more
                self._row_hashes.pop(fid, None)
            raise
        self._row_hashes.update(written)
        self._note_saved(ids)
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
                out.append(self._decode_face(row, vectors.get(row[0], [])))
            except (ValueError, TypeError) as exc:
                _LOG.error("face store %s: skipping invalid stored face %s: %s", self.path, row[0], exc)
        return out

    def _decode_face(self, row: tuple[Any, ...], blobs: list[Any]) -> LearnedFace:
        """A face from its ``faces`` row (id, name, created, last seen, observations) and its vector blobs;
        ValueError / TypeError when they are not a valid face of this store."""
        width = self.embedding_dim * _VECTOR_DTYPE.itemsize
        if not blobs or any(not isinstance(b, bytes) or len(b) != width for b in blobs):
            raise ValueError(f"{len(blobs)} stored vectors, expected >= 1 of {width} bytes each")
        feats = np.frombuffer(b"".join(blobs), dtype=_VECTOR_DTYPE).reshape(len(blobs), -1).astype(np.float32)
        face_id, name, created_s, last_seen_s, n_obs = row
        return LearnedFace(face_id, feats, name, created_s, last_seen_s, n_obs)

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
        """Largest face id ever saved in this store (also after it was forgotten, or lost: the ledger); 0 if
        none."""
        return max(self._meta_max_face_id(), self._ledger_max)

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

    def integrity_ok(self) -> bool:
        """Run ``PRAGMA integrity_check`` now (diagnostics)."""
        return [r[0] for r in self._db.execute("PRAGMA integrity_check").fetchall()] == ["ok"]

    @property
    def closed(self) -> bool:
        return self._conn is None

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
