"""The face store's SQLite database: its schema, and opening a file as one (recognised, checked, set up).

A file is handed to SQLite only when it is empty (a new store) or starts with SQLite's header; it must pass
``PRAGMA integrity_check``, hold the face tables at a known schema version and the expected embedding length
and space (another embedder's faces must never be compared: :class:`FaceStoreError`). Anything else is a
:class:`CorruptStore` (the store moves the file aside); a damaged face store's readable faces are salvaged
(:func:`salvage_faces`). Connections use ``secure_delete`` (freed content zeroed) and the WAL journal.
Tables of earlier versions that are no longer used are dropped, their bytes with them, on the first writable
open.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_master.identity.predefined_people import check_person_name
from face_reid_master.identity.records import LearnedFace
from face_reid_master.storage.errors import FaceStoreError

__all__ = ["SCHEMA_VERSION", "VECTOR_DTYPE", "CorruptStore", "FaceDatabaseFile", "bump_max_face_id", "decode_face",
           "salvage_faces", "scrub_wal", "set_meta", "transaction"]

_LOG = logging.getLogger(__name__)

SCHEMA_VERSION = 1
_DEFAULT_DIM = 128
_LEGACY_SPACE = "dlib_resnet_v1"
_SQLITE_MAGIC = b"SQLite format 3\x00"
VECTOR_DTYPE = np.dtype("<f4")  # little-endian float32 on every platform

# people named at run time (face-reid-faces add): their photos' embeddings, kept like the gallery folder's. Added
# without a new schema version (an earlier version opens such a file and ignores these tables)
_PEOPLE_SCHEMA = """
CREATE TABLE IF NOT EXISTS people (
    name TEXT PRIMARY KEY,
    added_s REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS person_features (
    name TEXT NOT NULL REFERENCES people(name) ON DELETE CASCADE,
    idx INTEGER NOT NULL CHECK (idx >= 0),
    vector BLOB NOT NULL,
    PRIMARY KEY (name, idx)
) WITHOUT ROWID;
"""
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
{_PEOPLE_SCHEMA}
INSERT INTO meta(key, value) VALUES ('schema_version', '{SCHEMA_VERSION}');
"""
_EXPECTED_TABLES = {"meta", "faces", "features"}
# tables earlier versions kept beside the faces (body pairs of a retired online body-metric update): dropped on open
_RETIRED_TABLES = ("body_pairs",)
_RETIRED_META = ("body_pairs_subspace",)


class CorruptStore(Exception):
    """The file is not a usable face store (reason in args[0]); ``damaged``: a face store whose file
    was damaged (its readable faces are worth salvaging), not another format or schema."""

    def __init__(self, reason: str, damaged: bool = False) -> None:
        super().__init__(reason)
        self.damaged = damaged


def set_meta(conn: sqlite3.Connection, key: str, value: str) -> None:
    conn.execute(
        "INSERT INTO meta(key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = excluded.value",
        (key, value),
    )


@contextlib.contextmanager
def transaction(conn: sqlite3.Connection, path: Path) -> Iterator[sqlite3.Connection]:
    """``BEGIN IMMEDIATE`` ... ``COMMIT`` on ``conn``, rolled back on any error; SQLite errors become
    :class:`FaceStoreError` naming ``path``."""
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
        raise FaceStoreError(f"face store {path}: {exc}") from exc


def bump_max_face_id(conn: sqlite3.Connection, face_id: int) -> None:
    """Raise the store's ``max_face_id`` (never lowered: new faces get ids above it) to ``face_id``."""
    conn.execute(
        "INSERT INTO meta(key, value) VALUES ('max_face_id', ?) ON CONFLICT(key) DO UPDATE SET "
        "value = CAST(MAX(CAST(value AS INTEGER), CAST(excluded.value AS INTEGER)) AS TEXT)",
        (str(face_id),),
    )


def scrub_wal(conn: sqlite3.Connection, path: Path) -> None:
    """Checkpoint every WAL frame into the (zeroed) database pages and truncate the WAL to 0 bytes: what was
    deleted is then gone from both files."""
    try:
        busy, _, _ = conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
    except sqlite3.Error as exc:
        raise FaceStoreError(f"face store {path}: WAL checkpoint failed: {exc}") from exc
    if busy:
        _LOG.warning("face store %s: WAL checkpoint blocked by a reader; deleted data may stay in %s-wal until the "
                     "next checkpoint", path, path.name)


class FaceDatabaseFile:
    """How a face store's file is opened as its database: ``read_only``, ``synchronous`` ("FULL" / "NORMAL"),
    the ``embedding_dim`` / ``embedding_space`` asked for (0 / "": adopt the stored ones, known after
    :meth:`connect`)."""

    def __init__(self, path: Path, *, read_only: bool, synchronous: str, embedding_dim: int,
                 embedding_space: str) -> None:
        self.path = path
        self.read_only = read_only
        self.synchronous = synchronous
        self.embedding_dim = embedding_dim
        self.embedding_space = embedding_space

    def connect(self, fd: int) -> sqlite3.Connection:
        """The database of the locked file ``fd``, recognised, checked and set up (or created); CorruptStore
        when it is not a usable face store."""
        head = os.pread(fd, len(_SQLITE_MAGIC), 0)
        if head and head != _SQLITE_MAGIC:
            # Never hand a foreign file to SQLite: with a -wal beside it, closing would delete that -wal.
            # (An empty file is fine: a new store, or one whose whole content is still in the WAL.)
            raise CorruptStore("not an SQLite database (bad header)")
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
                self._add_people_tables(conn)
        except BaseException:
            conn.close()
            raise
        return conn

    @staticmethod
    def _add_people_tables(conn: sqlite3.Connection) -> None:
        """A store written before people were kept gains their (empty) tables."""
        present = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()}
        if not {"people", "person_features"} <= present:
            conn.executescript("BEGIN IMMEDIATE;" + _PEOPLE_SCHEMA + "COMMIT;")

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
            raise CorruptStore(f"cannot switch to WAL ({exc})") from exc
        if str(mode).lower() != "wal":
            raise FaceStoreError(f"face store {self.path}: cannot enable the WAL journal (got {mode!r})")

    def _validate_or_init(self, conn: sqlite3.Connection) -> None:
        try:
            check = [r[0] for r in conn.execute("PRAGMA integrity_check").fetchall()]
            if check != ["ok"]:
                raise CorruptStore("integrity_check failed: " + "; ".join(str(c) for c in check[:5]), damaged=True)
            tables = {
                r[0]
                for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
                if not str(r[0]).startswith("sqlite_")
            }
            if not tables and self.read_only:
                raise CorruptStore("an empty file, not a face store")
            if not tables:
                if not self.embedding_dim:
                    self.embedding_dim = _DEFAULT_DIM
                self._enable_wal(conn)  # before the first write: the schema goes straight into the WAL
                conn.executescript("BEGIN IMMEDIATE;" + _SCHEMA + "COMMIT;")
                set_meta(conn, "embedding_dim", str(self.embedding_dim))
                self.embedding_space = self.embedding_space or _LEGACY_SPACE
                set_meta(conn, "embedding_space", self.embedding_space)
                return
            if not _EXPECTED_TABLES <= tables:
                raise CorruptStore(f"not a face store (tables {sorted(tables)})")
            meta = dict(conn.execute("SELECT key, value FROM meta").fetchall())
            if meta.get("schema_version") != str(SCHEMA_VERSION):
                raise CorruptStore(f"unknown schema version {meta.get('schema_version')!r}")
            dim = meta.get("embedding_dim")
            if not self.embedding_dim:  # embedding_dim=None: adopt the store's (tools such as the CLI)
                self.embedding_dim = int(dim) if dim is not None and dim.isdigit() and int(dim) > 0 else _DEFAULT_DIM
            if dim is None and not self.read_only:
                set_meta(conn, "embedding_dim", str(self.embedding_dim))
            elif dim != str(self.embedding_dim):
                raise FaceStoreError(
                    f"face store {self.path} holds {dim}-dimensional features but embedding_dim is "
                    f"{self.embedding_dim} (a different embedder?): use another file or delete this one"
                )
            space = meta.get("embedding_space")
            if space is None:  # written before spaces were recorded: the dlib embedder was the only one
                space = _LEGACY_SPACE
                if (not self.embedding_space or self.embedding_space == space) and not self.read_only:
                    set_meta(conn, "embedding_space", space)
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
            raise CorruptStore(f"unreadable database ({exc})", damaged=True) from exc


def decode_face(row: tuple[Any, ...], blobs: list[Any], dim: int) -> LearnedFace:
    """A face from its ``faces`` row (id, name, created, last seen, observations) and its vector blobs of ``dim``
    values each; ValueError / TypeError when they are not a valid face."""
    width = dim * VECTOR_DTYPE.itemsize
    if not blobs or any(not isinstance(b, bytes) or len(b) != width for b in blobs):
        raise ValueError(f"{len(blobs)} stored vectors, expected >= 1 of {width} bytes each")
    feats = np.frombuffer(b"".join(blobs), dtype=VECTOR_DTYPE).reshape(len(blobs), -1).astype(np.float32)
    face_id, name, created_s, last_seen_s, n_obs = row
    return LearnedFace(face_id, feats, name, created_s, last_seen_s, n_obs)


def salvage_faces(backup: Path, dim: int) -> tuple[list[LearnedFace], int | str]:
    """Every face still readable from a corrupt face store moved aside to ``backup`` (a damaged index or page
    rarely takes every face with it), and how many it held ("?" when unknown)."""
    faces: list[LearnedFace] = []
    total: int | str = "?"
    try:
        conn = sqlite3.connect(f"{backup.as_uri()}?mode=ro", uri=True)
    except sqlite3.Error:
        return [], total
    try:
        conn.execute("PRAGMA trusted_schema=OFF")
        rows = conn.execute("SELECT face_id, name, created_s, last_seen_s, n_observations FROM faces").fetchall()
        total = len(rows)
        for row in rows:
            try:
                blobs = [b for (b,) in conn.execute(
                    "SELECT vector FROM features WHERE face_id = ? ORDER BY idx", (row[0],))]
                face = decode_face(row, blobs, dim)
                try:
                    name = None if face.name is None else check_person_name(face.name)
                except ValueError:  # a name that is no longer accepted is dropped, not the face
                    name = None
                faces.append(dataclasses.replace(face, name=name))
            except (sqlite3.Error, ValueError, TypeError, OverflowError):
                continue
    except sqlite3.Error:
        pass
    finally:
        conn.close()
    return faces, total

