"""What the master remembers of faces beyond the identity layer: the store, the face cap, retention and names.

Faces are written to the store (any object with ``save_faces`` / ``load_faces`` / ``forget`` /
``prune_unnamed`` / ``max_face_id`` / ``reserve_face_ids``, e.g.
:class:`~face_reid_master.storage.face_store.FaceStore`) when an identity decision changes them and, for features
learned since, at most every ``save_interval_s``. A new face's id is reserved durably in the store before it is
published (``id_block`` ids at a time): when the store cannot write, the new face is not learned (its track stays
undecided, counted in ``faces_refused_no_id``, the reason in :attr:`FaceMemory.id_error`), so no id a restart
could give again is ever published. At most
``max_faces`` are kept (the least recently seen unnamed face not on a track goes first); unnamed faces older
than the store's retention are pruned; each face's predefined name is re-evaluated every
``name_update_interval_s``. Store failures are counted, never raised: identities keep working in memory.
"""

from __future__ import annotations

import contextlib
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.core.config import MasterConfig
from face_reid_master.core.records import MasterStats
from face_reid_master.identity.algorithm1 import IdentityManagerBase
from face_reid_master.identity.predefined_people import PredefinedPeople
from face_reid_master.identity.records import MAX_FACE_ID, LearnedFace, check_face_id

__all__ = ["ID_BLOCK", "FaceMemory"]

ID_BLOCK = 16  # new face ids reserved in the store at once: one durable write per 16 new faces, not per face
_MAX_ERROR_CHARS = 300


def _power_of_ten(n: int) -> bool:
    """1, 10, 100, ...: when a counter is worth a log line (floods stay quiet)."""
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1


class FaceMemory:
    """The faces' store, cap, retention and names (see the module doc); counts into ``stats``, appends notices
    for the node to ``notices``."""

    def __init__(self, config: MasterConfig, stats: MasterStats, identity: IdentityManagerBase,
                 people: PredefinedPeople, store: Any | None, notices: list[str]) -> None:
        self.config = config
        self.stats = stats
        self.identity = identity
        self.people = people
        self.store = store
        self.notices = notices
        self._dirty_faces: dict[int, float] = {}  # face id -> first unsaved change (s)
        self._write_failures_seen = 0  # background save failures already counted in stats.store_errors
        self._name_checked: dict[int, float] = {}  # face id -> last name evaluation (s)
        self._names: dict[int, str] = {}  # face id -> name from the predefined people
        self._last_prune_s = -math.inf
        self.id_block = ID_BLOCK
        self._ids_durable_upto = 0  # new face ids up to this one are reserved in the store (every restart skips them)
        self.id_error = ""  # why the last id reservation failed ("" = the last one succeeded, or none was needed)
        self._last_id_retry_s = -math.inf
        if store is not None:
            faces = self._cap_loaded(store.load_faces())
            identity.faces.import_faces(faces)
            self._ids_durable_upto = int(store.max_face_id())
            identity.faces.reserve_ids(self._ids_durable_upto)
            for face in faces:
                self.refresh_name(face.face_id, face.features)

    # ------------------------------------------------------------------------------ decisions
    def changed(self, face_id: int) -> None:
        """An identity decision concerned the face: it is written now and its name re-evaluated soon."""
        self.save([face_id])
        self._name_checked.pop(face_id, None)

    def learned(self, face_id: int, stamp: float) -> None:
        """The face learned features at ``stamp``: it is written within save_interval_s."""
        self._dirty_faces.setdefault(face_id, stamp)

    def room_for(self, new_face: int) -> bool:
        """Whether a new face may be learned (else it is forgotten at once, counted, and its track stays
        undecided): its id must be durable in the store (:meth:`_id_durable`), and within max_faces it evicts the
        least recently seen unnamed face not on a track (False when there is none)."""
        if not self._id_durable(new_face):
            self.identity.forget_face(new_face)
            return False
        excess = len(self.identity.face_ids()) - self.config.max_faces
        if excess <= 0:
            return True
        victims = self.identity.eviction_order(exclude=(new_face,))[:excess]
        if len(victims) == excess:
            self._evict(victims)
            return True
        self.identity.forget_face(new_face)
        self.stats.faces_refused_cap += 1
        if _power_of_ten(self.stats.faces_refused_cap):
            self.notices.append(f"max_faces ({self.config.max_faces}) reached and every face is named or on a "
                                f"track: a new face was not learned ({self.stats.faces_refused_cap} so far, "
                                "faces_refused_cap)")
        return False

    def _id_durable(self, face_id: int) -> bool:
        """Whether new face ``face_id`` is reserved in the store (reserving the next ``id_block`` ids when it is
        not yet); False, said and counted, when the store cannot write them (disk full, read-only)."""
        if self.store is None or face_id <= self._ids_durable_upto or self._reserve(face_id):
            return True
        self.stats.faces_refused_no_id += 1
        if _power_of_ten(self.stats.faces_refused_no_id):
            self.notices.append(f"a new face was not learned: its id cannot be reserved in the face store "
                                f"({self.id_error}); new people stay undecided until the store can write "
                                f"({self.stats.faces_refused_no_id} so far, faces_refused_no_id)")
        return False

    def _reserve(self, first: int) -> bool:
        """Reserve ids ``first`` .. ``first + id_block - 1`` in the store; False (the reason in :attr:`id_error`)
        when it cannot write them."""
        upto = min(first + self.id_block - 1, MAX_FACE_ID)
        try:
            self.store.reserve_face_ids(upto)
        except Exception as exc:  # new faces wait; identities keep working in memory
            self.id_error = f"{type(exc).__name__}: {str(exc)[:_MAX_ERROR_CHARS]}"
            return False
        self._ids_durable_upto = upto
        self.id_error = ""
        return True

    def _evict(self, face_ids: list[int]) -> None:
        """Forget unnamed faces for the cap (memory, names, store), counted; logged at 1, 10, 100, ... evictions."""
        for fid in face_ids:
            self._drop(fid)
        self._forget_stored(face_ids)
        before = self.stats.faces_evicted
        self.stats.faces_evicted += len(face_ids)
        if any(_power_of_ten(n) for n in range(before + 1, self.stats.faces_evicted + 1)):
            self.notices.append(f"max_faces ({self.config.max_faces}) reached: evicted the least recently seen "
                                 f"unnamed face(s) {face_ids[:10]} ({self.stats.faces_evicted} so far, faces_evicted)")

    def _drop(self, face_id: int) -> bool:
        """Forget a face in memory (identity, names, pending saves); True if the identity layer had it."""
        found = bool(self.identity.forget_face(face_id))
        self.people.remove_face(face_id)
        self._names.pop(face_id, None)
        self._dirty_faces.pop(face_id, None)
        self._name_checked.pop(face_id, None)
        return found

    def _forget_stored(self, face_ids: list[int]) -> None:
        """Delete faces from the store: handed to its worker without waiting when it has one (forget_later)."""
        if self.store is None or not face_ids:
            return
        try:
            later = getattr(self.store, "forget_later", None)
            if later is not None:
                later(face_ids)
            else:
                for fid in face_ids:
                    self.store.forget(fid)
        except Exception:  # the store logs; the faces are gone from memory
            self.stats.store_errors += 1

    def _cap_loaded(self, faces: list[LearnedFace]) -> list[LearnedFace]:
        """The stored faces within max_faces: the most recently seen unnamed ones and every named one (the others
        are evicted from the store, counted, said)."""
        excess = len(faces) - self.config.max_faces
        if excess <= 0:
            return faces
        unnamed = sorted((f for f in faces if not f.name), key=lambda f: (f.last_seen_s, f.face_id))
        gone = {f.face_id for f in unnamed[:excess]}
        if gone:
            self._forget_stored(sorted(gone))
            self.stats.faces_evicted += len(gone)
            self.notices.append(f"the face store held {len(faces)} faces, more than max_faces "
                                 f"({self.config.max_faces}): evicted the {len(gone)} least recently seen unnamed")
        return [f for f in faces if f.face_id not in gone]

    def maintain(self, stamp: float) -> None:
        """What is due at ``stamp``: retention, saving the faces that learned, re-evaluating live faces' names,
        retrying a failed id reservation."""
        cfg = self.config
        if self.store is not None and stamp - self._last_prune_s >= cfg.prune_interval_s:
            self._last_prune_s = stamp
            self._prune_unnamed(stamp)
        due = [fid for fid, since in self._dirty_faces.items() if stamp - since >= cfg.save_interval_s]
        if due:
            self.save(due)
        if self.id_error and stamp - self._last_id_retry_s >= cfg.save_interval_s:
            self._last_id_retry_s = stamp  # the store may write again: the error clears without waiting for a face
            self._reserve(max(self.identity.faces.next_id, self._ids_durable_upto + 1))
        for fid in set(self.identity.assigned_tracks().values()):
            if stamp - self._name_checked.get(fid, -math.inf) >= cfg.name_update_interval_s:
                self._name_checked[fid] = stamp
                self.refresh_name(fid, self.identity.faces.features(fid))

    def refresh_name(self, face_id: int, features: NDArray[np.floating]) -> None:
        if not self.people.names():
            return
        self.people.update_face(face_id, features)
        matches = self.people.assignments()
        self._names = {fid: m.name for fid, m in matches.items()}
        for fid, name in self._names.items():
            if self.identity.faces.name(fid) != name:
                self.identity.faces.set_name(fid, name)
                self.save([fid])

    def save(self, face_ids: list[int]) -> None:
        """Write faces to the store in one transaction (one fsync however many)."""
        faces = []
        for fid in face_ids:
            self._dirty_faces.pop(fid, None)
            with contextlib.suppress(KeyError):
                faces.append(self.identity.faces.export(fid))
        if self.store is None or not faces:
            return
        try:
            self.store.save_faces(faces)
        except Exception:  # the store logs; identity keeps working in memory
            self.stats.store_errors += 1
        # a store that writes in the background (storage.write_behind) counts its failures itself
        self.stats.store_errors += getattr(self.store, "write_failures", 0) - self._write_failures_seen
        self._write_failures_seen = getattr(self.store, "write_failures", 0)

    def _prune_unnamed(self, stamp: float) -> None:
        """Retention: forget unnamed faces the store says are too old (never those on live tracks)."""
        try:
            pruned = self.store.prune_unnamed(stamp, keep=tuple(self.identity.assigned_tracks().values()))
        except Exception:
            self.stats.store_errors += 1
            return
        for fid in pruned:
            self.identity.forget_face(fid)
            self.people.remove_face(fid)
            self._names.pop(fid, None)
            self._dirty_faces.pop(fid, None)
            self.stats.faces_pruned += 1

    def flush(self) -> None:
        """Write every face with unsaved features to the store (call at shutdown)."""
        for fid in list(self._dirty_faces):
            self.save([fid])

    def refresh_names(self) -> None:
        """Re-evaluate every face's predefined name (the predefined people changed)."""
        for fid in self.identity.face_ids():
            self.refresh_name(fid, self.identity.faces.features(fid))

    def forget_face(self, face_id: int) -> bool:
        """Delete a learned face everywhere (memory, names, store). True if it existed; ValueError for an id out
        of range."""
        face_id = check_face_id(face_id)
        found = self._drop(face_id)
        if self.store is not None:
            found = bool(self.store.forget(face_id)) or found
        return found

    def face_name(self, face_id: int) -> str:
        """The name linked to a face (predefined match, else a stored name), or ''."""
        return self._names.get(face_id) or self.identity.faces.name(face_id) or ""
