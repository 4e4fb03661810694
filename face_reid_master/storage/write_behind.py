"""A face store whose saves are committed by a worker thread: the master's frame loop never waits for a commit.

A commit fsyncs the WAL (``synchronous=FULL``): milliseconds to tens of milliseconds on a real disk, during
which a master applying 600 frames/s falls behind. :class:`WriteBehindStore` opens the store on its one worker
thread (so one thread uses the SQLite connection, as :class:`~face_reid_master.storage.face_store.FaceStore`
requires) and runs every call there, in the order made:

- ``save_faces`` hands the faces over and returns at once; faces handed over before the worker got to them
  are written together (the newest snapshot of each face, one transaction);
- every other method (load, forget, prune, list, ...) waits for its result, after the saves handed over
  before it: a face forgotten after a save stays forgotten.

A failed save is logged and counted (:attr:`write_failures`, the reason of the last in :attr:`last_error`,
:attr:`last_write_ok` whether the most recent write succeeded: the node's health reads them); what is lost is
what a synchronous save that raised would have lost. Attributes (``recovered_from``, ``path``, ...) are read
from the store as they are.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from face_reid_master.identity.records import LearnedFace
from face_reid_master.storage.errors import reason_of
from face_reid_master.storage.face_store import FaceStore

__all__ = ["WriteBehindStore"]

_LOG = logging.getLogger(__name__)
_MAX_ERROR_CHARS = 300


class WriteBehindStore:
    """``open_store`` (called on the worker; its exception is raised here) wrapped as described above."""

    def __init__(self, open_store: Callable[[], FaceStore]) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="face-store")
        try:
            self._store = self._pool.submit(open_store).result()
        except BaseException:
            self._pool.shutdown(wait=True)
            raise
        self._lock = threading.Lock()
        self._pending: dict[int, LearnedFace] = {}
        self._scheduled = False
        self.write_failures = 0  # save batches that raised (logged)
        self.last_error = ""  # the reason of the last failed write ("" = none yet)
        self.last_write_ok: bool | None = None  # whether the most recent write succeeded (None: none yet)

    def save_faces(self, faces: Iterable[LearnedFace]) -> int:
        """Hand ``faces`` to the worker (a newer snapshot of a face replaces one not yet written); how many."""
        batch = list(faces)
        with self._lock:
            for face in batch:
                self._pending[face.face_id] = face
            if batch and not self._scheduled:
                self._scheduled = True
                self._pool.submit(self._write)
        return len(batch)

    def save_face(self, face: LearnedFace) -> None:
        self.save_faces([face])

    def _write(self) -> None:
        with self._lock:
            batch, self._pending, self._scheduled = list(self._pending.values()), {}, False
        try:
            self._store.save_faces(batch)
        except Exception as exc:  # the frame loop carries on; the next save of these faces may succeed
            self._failed(exc)
            _LOG.error("face store: saving faces %s failed: %s", [f.face_id for f in batch][:20],
                       str(exc)[:_MAX_ERROR_CHARS])
        else:
            self.last_write_ok = True

    def _failed(self, exc: Exception) -> None:
        self.write_failures += 1
        self.last_error = reason_of(exc)[:_MAX_ERROR_CHARS]
        self.last_write_ok = False

    def forget_later(self, face_ids: Iterable[int]) -> None:
        """Hand faces to delete to the worker and return at once (the face cap's evictions: nobody waits for
        the answer); deleted after the saves handed over before, a failure counted like a failed save."""
        self._pool.submit(self._forget, list(face_ids))

    def _forget(self, face_ids: list[int]) -> None:
        try:
            self._store.forget_faces(face_ids)
        except Exception as exc:
            self._failed(exc)
            _LOG.error("face store: forgetting faces %s failed: %s", face_ids[:20], str(exc)[:_MAX_ERROR_CHARS])
        else:
            self.last_write_ok = True

    def flush(self) -> None:
        """Wait until every face handed over so far is written (or its failure counted)."""
        self._pool.submit(lambda: None).result()

    def close(self) -> None:
        """Write what is pending, close the store and stop the worker (idempotent)."""
        if self._pool is None:
            return
        try:
            self._pool.submit(self._store.close).result()
        finally:
            self._pool.shutdown(wait=True)
            self._pool = None  # type: ignore[assignment]

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._store, name)
        if not callable(attr):
            return attr

        def on_worker(*args: Any, **kwargs: Any) -> Any:
            if self._pool is None:
                raise ValueError("the face store is closed")
            return self._pool.submit(attr, *args, **kwargs).result()

        return on_worker
