"""Writing learned faces into the face store's ``faces`` / ``features`` tables, rewriting only what changed.

A face is saved again and again as it is seen; its feature bank replaces one row at a time. :class:`FaceRows`
remembers what one connection last committed of each face (hashes), so a save rewrites only the feature rows that
differ, none when only the counters changed.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.records import LearnedFace
from face_reid_master.storage.database_file import VECTOR_DTYPE

__all__ = ["FaceRows", "RowHashes"]

RowHashes = tuple[int, list[int]]  # hash of all a face's features, hash of each row


class FaceRows:
    """The rows of learned faces as one connection writes them, with what it last committed of each face."""

    def __init__(self) -> None:
        # face id -> its hashes as this connection last committed them
        self._committed: dict[int, RowHashes] = {}

    @staticmethod
    def encode(face: LearnedFace, embedding_dim: int) -> npt.NDArray[np.float32]:
        """The face's features as stored (contiguous little-endian float32); ValueError for an invalid face."""
        if not isinstance(face, LearnedFace):
            raise ValueError(f"expected a LearnedFace, got {type(face).__name__}")
        feats = face.features
        if feats.shape[1] != embedding_dim:
            raise ValueError(f"face {face.face_id}: features have dim {feats.shape[1]}, expected {embedding_dim}")
        if not np.all(np.isfinite(feats)):
            raise ValueError(f"face {face.face_id}: features contain NaN or Inf")
        return np.ascontiguousarray(feats, dtype=VECTOR_DTYPE)

    def write(self, conn: sqlite3.Connection, face: LearnedFace, raw: npt.NDArray[np.float32]) -> RowHashes:
        """Upsert the face's row and its feature rows (``raw``: :meth:`encode`); returns their hashes, for
        :meth:`committed`. Only rows that differ from what was last committed are written (none when no feature
        changed), when the stored row count still matches (else, e.g. after another process touched the face,
        all of them)."""
        fid = face.face_id
        conn.execute(
            "INSERT INTO faces(face_id, name, created_s, last_seen_s, n_observations) VALUES (?, ?, ?, ?, ?) "
            "ON CONFLICT(face_id) DO UPDATE SET name = excluded.name, created_s = excluded.created_s, "
            "last_seen_s = excluded.last_seen_s, n_observations = excluded.n_observations",
            (fid, face.name, face.created_s, face.last_seen_s, face.n_observations),
        )
        digest = hash(raw.tobytes())
        old = self._committed.get(fid)
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

    def committed(self, written: dict[int, RowHashes]) -> None:
        """The rows :meth:`write` returned are committed: the next save of those faces compares with them."""
        self._committed.update(written)

    def unknown(self, face_ids: Iterable[int]) -> None:
        """What is stored of these faces is not known any more (rolled back, or deleted): rewrite them in full."""
        for fid in face_ids:
            self._committed.pop(fid, None)

    @staticmethod
    def delete(conn: sqlite3.Connection, face_ids: list[int]) -> None:
        """Delete these faces and their features (inside the caller's transaction)."""
        conn.executemany("DELETE FROM features WHERE face_id = ?", [(f,) for f in face_ids])
        conn.executemany("DELETE FROM faces WHERE face_id = ?", [(f,) for f in face_ids])
