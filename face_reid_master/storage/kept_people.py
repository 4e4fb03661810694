"""The people named at run time (``face-reid-faces add``: a name and its photos' embeddings) kept in the face store's
file: saved, loaded, listed, forgotten for good, and read back from a damaged file moved aside.

Their ``people`` / ``person_features`` tables are created with the file (:mod:`.database_file`); this module is
what :class:`~face_reid_master.storage.face_store.FaceStore` delegates to for them, beside its learned faces.
"""

from __future__ import annotations

import logging
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.predefined_people import check_person_name
from face_reid_master.storage.database_file import VECTOR_DTYPE, FaceDatabaseFile, scrub_wal, transaction
from face_reid_master.storage.errors import FaceStoreError

__all__ = ["KeptPeople", "PersonSummary", "SalvagedPerson", "salvage_people"]

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class PersonSummary:
    """One person named at run time, without the embeddings (for listings)."""

    name: str
    n_embeddings: int
    added_s: float


@dataclass(frozen=True)
class SalvagedPerson:
    """A person read back from a damaged face store: the name, (k, dim) float32 embeddings, when added."""

    name: str
    embeddings: npt.NDArray[np.float32]
    added_s: float


def _decode(blobs: list[Any], dim: int) -> npt.NDArray[np.float32]:
    """The (k, ``dim``) float32 embeddings stored as these vector blobs; ValueError when they are not valid."""
    width = dim * VECTOR_DTYPE.itemsize
    if any(not isinstance(b, bytes) or len(b) != width for b in blobs):
        raise ValueError(f"stored vectors are not {width} bytes each")
    rows = np.frombuffer(b"".join(blobs), dtype=VECTOR_DTYPE).reshape(len(blobs), -1).astype(np.float32)
    if not np.all(np.isfinite(rows)):
        raise ValueError("stored vectors hold NaN or Inf")
    return rows


def salvage_people(backup: Path, dim: int) -> list[SalvagedPerson]:
    """Every person named at run time still readable from a corrupt face store moved aside to ``backup``."""
    out: list[SalvagedPerson] = []
    try:
        conn = sqlite3.connect(f"{backup.as_uri()}?mode=ro", uri=True)
    except sqlite3.Error:
        return out
    try:
        conn.execute("PRAGMA trusted_schema=OFF")
        for name, added_s in conn.execute("SELECT name, added_s FROM people ORDER BY name").fetchall():
            try:
                blobs = [b for (b,) in conn.execute("SELECT vector FROM person_features WHERE name = ? ORDER BY idx",
                                                    (name,))]
                if blobs:
                    out.append(SalvagedPerson(check_person_name(name), _decode(blobs, dim), float(added_s)))
            except (sqlite3.Error, ValueError, TypeError):
                continue
    except sqlite3.Error:  # no people tables (an earlier version), or unreadable
        pass
    finally:
        conn.close()
    return out


class KeptPeople:
    """The people named at run time in the face store of ``file`` (its path, mode and embedding length), read and
    written through the store's connection ``conn`` (passed to each call: the store owns it and closes it)."""

    def __init__(self, file: FaceDatabaseFile) -> None:
        self._file = file
        self._salvaged: list[SalvagedPerson] = []  # read from a corrupt file, to be written into the fresh one

    @staticmethod
    def _present(conn: sqlite3.Connection) -> bool:
        """Whether the file has the people tables (a store of an earlier version opened read-only has not)."""
        return conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'person_features'"
                            ).fetchone() is not None

    def save(self, conn: sqlite3.Connection, name: str, embeddings: Any, added_s: float | None = None) -> int:
        """Keep (or replace) ``name`` with the (k, embedding_dim) embeddings of their photos, committed on return;
        how many embeddings. ValueError for a bad name or array, FaceStoreError on a read-only store."""
        name = check_person_name(name)
        dim = self._file.embedding_dim
        rows = np.asarray(embeddings)
        if rows.ndim != 2 or rows.shape[0] < 1 or rows.shape[1] != dim:
            raise ValueError(f"embeddings of {name!r} must have shape (k >= 1, {dim}), got {rows.shape}")
        if rows.dtype == np.bool_ or not np.issubdtype(rows.dtype, np.number) or not np.all(np.isfinite(rows)):
            raise ValueError(f"embeddings of {name!r} must be finite real numbers")
        if self._file.read_only:
            raise FaceStoreError(f"face store {self._file.path} is open read-only: {name!r} cannot be kept")
        raw = np.ascontiguousarray(rows, dtype=VECTOR_DTYPE)
        stamp = time.time() if added_s is None else float(added_s)
        with transaction(conn, self._file.path):
            conn.execute("DELETE FROM person_features WHERE name = ?", (name,))
            conn.execute("INSERT INTO people(name, added_s) VALUES (?, ?) ON CONFLICT(name) DO UPDATE SET "
                         "added_s = excluded.added_s", (name, stamp))
            conn.executemany("INSERT INTO person_features(name, idx, vector) VALUES (?, ?, ?)",
                             [(name, i, raw[i].tobytes()) for i in range(raw.shape[0])])
        return int(raw.shape[0])

    def load(self, conn: sqlite3.Connection) -> dict[str, npt.NDArray[np.float32]]:
        """Name -> (k, embedding_dim) float32, names sorted (a person whose stored data is invalid is skipped with
        an ERROR log)."""
        if not self._present(conn):
            return {}
        blobs: dict[str, list[bytes]] = {}
        for name, blob in conn.execute("SELECT p.name, v.vector FROM people p JOIN person_features v "
                                       "ON v.name = p.name ORDER BY p.name, v.idx"):
            blobs.setdefault(name, []).append(blob)
        out: dict[str, npt.NDArray[np.float32]] = {}
        for name, rows in blobs.items():
            try:
                check_person_name(name)
                out[name] = _decode(rows, self._file.embedding_dim)
            except ValueError as exc:
                _LOG.error("face store %s: skipping an invalid stored person: %s", self._file.path, exc)
        return out

    def summaries(self, conn: sqlite3.Connection) -> list[PersonSummary]:
        """Summaries of the kept people (no vectors), sorted by name."""
        if not self._present(conn):
            return []
        rows = conn.execute("SELECT p.name, COUNT(v.idx), p.added_s FROM people p LEFT JOIN person_features v "
                            "ON v.name = p.name GROUP BY p.name ORDER BY p.name").fetchall()
        return [PersonSummary(str(r[0]), int(r[1]), float(r[2])) for r in rows]

    def forget(self, conn: sqlite3.Connection, name: str) -> bool:
        """Delete ``name`` and their embeddings for good (zeroed pages, WAL truncated); False if not kept."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"name must be a non-empty str, got {name!r}")
        if not self._present(conn) or not conn.execute("SELECT 1 FROM people WHERE name = ?", (name,)).fetchone():
            return False
        with transaction(conn, self._file.path):
            conn.execute("DELETE FROM person_features WHERE name = ?", (name,))
            conn.execute("DELETE FROM people WHERE name = ?", (name,))
        scrub_wal(conn, self._file.path)
        _LOG.info("face store %s: forgot the person %r", self._file.path, name)
        return True

    def salvage(self, backup: Path) -> None:
        """Read the people still readable from the corrupt file moved aside to ``backup`` (said loudly); they are
        written into the fresh store by :meth:`restore_salvaged`."""
        self._salvaged = salvage_people(backup, self._file.embedding_dim)
        if self._salvaged:
            _LOG.error("FACE STORE CORRUPT: %s: recovered %d person(s) named at run time from %s", self._file.path,
                       len(self._salvaged), backup)

    def restore_salvaged(self, conn: sqlite3.Connection) -> None:
        """Write the people read by :meth:`salvage` into the fresh store, as the salvaged faces are."""
        salvaged, self._salvaged = self._salvaged, []
        for person in salvaged:
            self.save(conn, person.name, person.embeddings, person.added_s)
