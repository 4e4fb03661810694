"""The learned faces of the identity manager, and face_list: those no live track carries (the paper's III-D).

face_list is kept in the order of the classification method's columns (Bayes: the table's columns 1..M) with
the faces' feature-bank slots beside it, so that eq. 4 for all of a step's observations is one product over
the bank; above ``exact_search_max_features`` stored features only the ``shortlist_faces`` faces with the
nearest centroids are compared exactly. Faces come and go from face_list through :meth:`FaceList.make_available`
/ :meth:`FaceList.make_unavailable`, which tell the classification method (``on_available`` /
``on_unavailable``). Face ids are never given twice.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int
from face_reid_master.identity.entries import FaceEntry
from face_reid_master.identity.feature_bank import FeatureBank
from face_reid_master.identity.records import IdentityStats, LearnedFace

__all__ = ["FaceList"]

F32Array = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]


class FaceList:
    """Every learned face by id (:attr:`entries`) and face_list in column order (:attr:`available`, with the
    faces' bank :attr:`slots`); see the module doc."""

    def __init__(self, bank: FeatureBank, stats: IdentityStats, exact_search_max_features: int,
                 shortlist_faces: int, on_available: Callable[[int], None],
                 on_unavailable: Callable[[list[int]], None]) -> None:
        self.bank = bank
        self.embedding_dim = bank.dim
        self.stats = stats
        self.exact_search_max_features = exact_search_max_features
        self.shortlist_faces = shortlist_faces
        self._on_available = on_available
        self._on_unavailable = on_unavailable
        self.entries: dict[int, FaceEntry] = {}
        self.available: list[int] = []  # face_list in column order
        self.slots = np.zeros(0, dtype=np.intp)  # their bank slots
        self.next_id = 1

    def get(self, face_id: int) -> FaceEntry:
        face = self.entries.get(face_id)
        if face is None:
            raise KeyError(f"unknown face id {face_id}")
        return face

    def available_ids(self) -> list[int]:
        """face_list: the learned faces no live track carries, in column order."""
        return list(self.available)

    def features(self, face_id: int) -> F32Array:
        """Copy of a learned face's stored features (k, embedding_dim)."""
        return self.bank.features(self.get(face_id).slot).copy()

    def name(self, face_id: int) -> str | None:
        return self.get(face_id).name

    def set_name(self, face_id: int, name: str | None) -> None:
        """Attach a (predefined-person) name to a learned face, or clear it with None."""
        if name is not None and not isinstance(name, str):
            raise ValueError(f"name must be a str or None, got {name!r}")
        self.get(face_id).name = name

    def export_all(self) -> list[LearnedFace]:
        """Snapshot of all learned faces (copies), for the persistent memory."""
        return [self.export(fid) for fid in sorted(self.entries)]

    def slot(self, face_id: int | None) -> int | None:
        """The bank slot of a learned face (None for None: an unidentified track's)."""
        return None if face_id is None else self.entries[face_id].slot

    def new_id(self) -> int:
        fid = self.next_id
        self.next_id += 1
        return fid

    def reserve_ids(self, highest_used_id: int) -> None:
        """Never give ids <= ``highest_used_id`` (ids of forgotten faces stay retired)."""
        self.next_id = max(self.next_id, check_int("highest_used_id", highest_used_id, 0) + 1)

    def make_available(self, face_id: int) -> None:
        """The face joins face_list (the last column)."""
        self.entries[face_id].track_id = None
        self.available.append(face_id)
        self.slots = np.append(self.slots, self.entries[face_id].slot).astype(np.intp)
        self._on_available(face_id)

    def make_unavailable(self, face_ids: list[int]) -> None:
        """The faces leave face_list."""
        idx = [self.available.index(f) for f in face_ids]
        keep = np.ones(len(self.available), dtype=bool)
        keep[idx] = False
        self._on_unavailable(idx)
        self.available = [f for f, k in zip(self.available, keep, strict=True) if k]
        self.slots = self.slots[keep]

    def distances(self, obs: F32Array) -> FloatArray:
        """Eq. 4 distances (Q, M) from observations to every face in face_list (column order)."""
        slots = self.slots
        if len(slots) == 0:
            return np.zeros((obs.shape[0], 0))
        n_feats = int(self.bank.count[slots].sum())
        if n_feats > self.exact_search_max_features and len(slots) > self.shortlist_faces:
            self.stats.shortlist_searches += 1
            return self.bank.shortlist_min_distances(obs, slots, self.shortlist_faces)
        return self.bank.exact_min_distances(obs, slots)

    def min_distances(self, face_id: int, others: list[int]) -> FloatArray:
        """The smallest distance between the stored features of learned face ``face_id`` and of each of
        ``others``, in one batched computation (NaN where either face is unknown)."""
        out = np.full(len(others), np.nan)
        top = self.entries.get(face_id)
        known = [k for k, f in enumerate(others) if f in self.entries]
        if top is None or not known:
            return out
        slots = np.array([self.entries[others[k]].slot for k in known], dtype=np.intp)
        d = self.bank.exact_min_distances(self.bank.features(top.slot), slots)
        if d.size:
            out[known] = d.min(axis=0)
        return out

    def alike(self, face_id: int, others: list[int], limit: float | None) -> list[bool]:
        """Which of ``others`` have features closer than ``limit`` to face ``face_id``'s (None: none; an unknown
        face: not alike)."""
        if limit is None:
            return [False] * len(others)
        return (self.min_distances(face_id, others) < limit).tolist()

    def forget(self, face_id: int) -> None:
        """Delete a learned face: out of face_list, its bank slot freed (its id is never given again)."""
        face = self.entries.pop(face_id)
        if face.track_id is None:
            self.make_unavailable([face_id])
        self.bank.free_slot(face.slot)

    def eviction_order(self, exclude: Iterable[int]) -> list[int]:
        """The unnamed faces of face_list not in ``exclude``, least recently seen first."""
        skip = set(exclude)
        faces = [self.entries[fid] for fid in self.available if fid not in skip and not self.entries[fid].name]
        return [f.face_id for f in sorted(faces, key=lambda f: (f.last_seen_s, f.face_id))]

    def export(self, face_id: int) -> LearnedFace:
        """Snapshot (copy) of one learned face; KeyError if unknown."""
        f = self.get(face_id)
        return LearnedFace(f.face_id, self.bank.features(f.slot).copy(), f.name, f.created_s, f.last_seen_s,
                           f.n_observations)

    def import_faces(self, faces: Iterable[LearnedFace]) -> None:
        """Add exported faces to face_list; ValueError on an id clash or another dimension (nothing added)."""
        embedding_dim = self.embedding_dim
        batch = list(faces)
        seen: set[int] = set()
        for f in batch:
            if not isinstance(f, LearnedFace):
                raise ValueError(f"import_faces expects LearnedFace records, got {type(f).__name__}")
            if f.features.shape[1] != embedding_dim:
                raise ValueError(
                    f"face {f.face_id}: features have dim {f.features.shape[1]}, "
                    f"expected {embedding_dim}"
                )
            if f.face_id in self.entries or f.face_id in seen:
                raise ValueError(f"face id {f.face_id} already exists")
            seen.add(f.face_id)
        for f in batch:
            slot = self.bank.new_slot(f.features)
            self.entries[f.face_id] = FaceEntry(
                f.face_id, slot, f.name, f.created_s, f.last_seen_s, f.n_observations, track_id=None
            )
            self.next_id = max(self.next_id, f.face_id + 1)
            self.make_available(f.face_id)
