"""Predefined people: link online-learned faces to named gallery people (Koide et al. 2017, Sec. III-F).

The gallery maps a name to embeddings of that person's photos (embedded by the caller).  A learned face
and a person are compared by the paper's rule: the minimum L2 distance over all pairs of (gallery
feature, learned feature).  ``k_smallest > 1`` generalises it to the mean of the k smallest per-feature
nearest-neighbour distances (OpenPTrack uses 5), which is less sensitive to one lucky pair.  A face is
named when that distance is below ``name_threshold``; names and faces are matched one-to-one, greedily
by increasing distance.  Faces with fewer than ``min_face_features`` stored features are not named yet.
Distances are cached per face and recomputed only for faces whose features changed, so re-evaluating
the links as faces keep learning is cheap.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import shown

__all__ = [
    "MAX_NAME_CHARS",
    "NameMatch",
    "PredefinedPeople",
    "assign_one_to_one",
    "check_person_name",
    "face_to_person_distance",
    "with_kept_people",
]

FloatArray = npt.NDArray[np.float64]


MAX_NAME_CHARS = 64


def check_person_name(name: object) -> str:
    """``name`` if it is a usable person name: a string of 1..MAX_NAME_CHARS printable characters (no control
    characters, newlines or terminal escapes: names are shown in logs, lists and on robots) without leading or
    trailing spaces; ValueError saying what is wrong otherwise."""
    if not isinstance(name, str):
        raise ValueError(f"person name must be a string, got {type(name).__name__}")
    quoted = shown(name, 40)
    if not name.strip():
        raise ValueError("person name must not be empty")
    if len(name) > MAX_NAME_CHARS:
        raise ValueError(f"person name {quoted} has {len(name)} characters, more than {MAX_NAME_CHARS}")
    if not name.isprintable():
        raise ValueError(f"person name {quoted} holds control characters (newlines, escapes, ...)")
    if name != name.strip():
        raise ValueError(f"person name {quoted} starts or ends with a space")
    return name


def with_kept_people(folder: Mapping[str, npt.ArrayLike], kept: Mapping[str, npt.ArrayLike]
                     ) -> tuple[dict[str, npt.ArrayLike], list[str]]:
    """The predefined people of a master: the gallery folder's and those named at run time (kept in the face store),
    and the names both hold. A person named at run time wins over the gallery folder's of the same name (the
    operator's newer word: ``add`` replaces a person at run time, and so it stays after a restart) until
    ``forget --name`` removes them; then the folder's person is back at the next start."""
    people: dict[str, npt.ArrayLike] = dict(folder)
    people.update(kept)
    return people, sorted(set(folder) & set(kept))


def _as_features(features: npt.ArrayLike, dim: int, what: str) -> npt.NDArray[np.float32]:
    arr = np.asarray(features)
    if arr.ndim != 2 or arr.shape[1] != dim or arr.shape[0] < 1:
        raise ValueError(f"{what} must have shape (k >= 1, {dim}), got {arr.shape}")
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise ValueError(f"{what} must be a real numeric array, got dtype {arr.dtype}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} contain NaN or Inf")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _nn_distances(learned: npt.NDArray[np.float32], gallery: npt.NDArray[np.float32]) -> FloatArray:
    """For every learned feature, the L2 distance to its nearest gallery feature (float64)."""
    a = learned.astype(np.float64)
    b = gallery.astype(np.float64)
    d2 = np.einsum("ij,ij->i", a, a)[:, None] + np.einsum("ij,ij->i", b, b)[None, :] - 2.0 * (a @ b.T)
    return np.sqrt(np.maximum(d2.min(axis=1), 0.0))


def face_to_person_distance(
    face_features: npt.ArrayLike, person_features: npt.ArrayLike, k_smallest: int = 1
) -> float:
    """Paper's III-F distance: min over all (learned, gallery) pairs; k_smallest > 1: mean of the k
    smallest nearest-neighbour distances of the learned features (fewer if the face has fewer)."""
    f = np.asarray(face_features, dtype=np.float32)
    g = np.asarray(person_features, dtype=np.float32)
    if f.ndim != 2 or g.ndim != 2 or f.shape[1] != g.shape[1] or not len(f) or not len(g):
        raise ValueError(f"need (k, dim) feature arrays of equal dim, got {f.shape} and {g.shape}")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(g))):
        raise ValueError("features contain NaN or Inf")
    if k_smallest < 1:
        raise ValueError(f"k_smallest must be >= 1, got {k_smallest}")
    nn = np.sort(_nn_distances(f, g))
    return float(nn[: min(k_smallest, len(nn))].mean())


def assign_one_to_one(distances: npt.ArrayLike, threshold: float) -> list[tuple[int, int, float]]:
    """Greedy one-to-one matching of rows and columns by increasing distance, only below threshold.

    Returns (row, column, distance) triples.  NaN / +inf entries mean "not eligible".
    """
    d = np.array(distances, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"distances must be 2-D, got shape {d.shape}")
    d[~np.isfinite(d)] = np.inf
    d[d >= threshold] = np.inf
    out = []
    if d.size == 0:
        return out
    order = np.argsort(d, axis=None, kind="stable")
    used_r: set[int] = set()
    used_c: set[int] = set()
    for flat in order:
        r, c = divmod(int(flat), d.shape[1])
        if not math.isfinite(d[r, c]):
            break
        if r in used_r or c in used_c:
            continue
        used_r.add(r)
        used_c.add(c)
        out.append((r, c, float(d[r, c])))
    return out


@dataclass(frozen=True)
class NameMatch:
    """A learned face linked to a predefined person."""

    face_id: int
    name: str
    distance: float


class PredefinedPeople:
    """Gallery of named people and the cache of their distances to learned faces.

    ``name_threshold``: a face is named only if its distance to the person is below it (L2, same units
    as the embedder).  Default 0.45 for the dlib ResNet with the min rule (3 gallery photos vs 2-12
    learned features: CelebA 99 people, same person found 93%, wrong person below it 0.12% of pairs;
    fixture LFW/deepface people 100% / 0%); the minimum over more pairs drifts lower, hence below 0.6.
    ``min_face_features``: faces with fewer stored features are not named yet (OpenPTrack: 10).
    ``k_smallest``: 1 = the paper's min rule; > 1 = mean of the k smallest NN distances.
    """

    def __init__(
        self,
        people: Mapping[str, npt.ArrayLike] | None = None,
        *,
        name_threshold: float = 0.45,
        min_face_features: int = 5,
        k_smallest: int = 1,
        embedding_dim: int = 128,
    ) -> None:
        if isinstance(name_threshold, bool) or not isinstance(name_threshold, (int, float)):
            raise ValueError(f"name_threshold must be a number, got {name_threshold!r}")
        if not (math.isfinite(name_threshold) and name_threshold > 0.0):
            raise ValueError(f"name_threshold must be finite and > 0, got {name_threshold}")
        for pname, value in (
            ("min_face_features", min_face_features),
            ("k_smallest", k_smallest),
            ("embedding_dim", embedding_dim),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{pname} must be an int >= 1, got {value!r}")
        self.name_threshold = float(name_threshold)
        self.min_face_features = min_face_features
        self.k_smallest = k_smallest
        self.embedding_dim = embedding_dim
        self._people: dict[str, npt.NDArray[np.float32]] = {}
        self._faces: dict[int, npt.NDArray[np.float32]] = {}
        self._rows: dict[int, dict[str, float]] = {}  # face id -> name -> distance (eligible faces)
        for name, feats in (people or {}).items():
            self.set_person(name, feats)

    # ------------------------------------------------------------------------------ gallery
    def set_person(self, name: str, features: npt.ArrayLike) -> None:
        """Add or replace a named person's gallery embeddings (k, embedding_dim)."""
        check_person_name(name)
        self._people[name] = _as_features(features, self.embedding_dim, f"features of {name!r}")
        for fid, row in self._rows.items():
            row[name] = self._distance(self._faces[fid], self._people[name])

    def remove_person(self, name: str) -> None:
        if name not in self._people:
            raise KeyError(f"unknown person {name!r}")
        del self._people[name]
        for row in self._rows.values():
            row.pop(name, None)

    def names(self) -> list[str]:
        return sorted(self._people)

    def n_embeddings(self, name: str) -> int:
        """How many gallery embeddings the person has (0: no such person)."""
        feats = self._people.get(name)
        return 0 if feats is None else int(feats.shape[0])

    # ------------------------------------------------------------------------------ learned faces
    def update_face(self, face_id: int, features: npt.ArrayLike) -> None:
        """(Re)compute a learned face's distances to every person; call when its features changed."""
        if isinstance(face_id, bool) or not isinstance(face_id, (int, np.integer)):
            raise ValueError(f"face_id must be an int, got {face_id!r}")
        fid = int(face_id)
        feats = _as_features(features, self.embedding_dim, f"features of face {fid}")
        self._faces[fid] = feats
        if len(feats) < self.min_face_features:
            self._rows.pop(fid, None)
            return
        self._rows[fid] = {name: self._distance(feats, g) for name, g in self._people.items()}

    def remove_face(self, face_id: int) -> None:
        self._faces.pop(face_id, None)
        self._rows.pop(face_id, None)

    def distance(self, face_id: int, name: str) -> float | None:
        """Cached distance, or None if the face is not eligible yet / unknown."""
        row = self._rows.get(face_id)
        return None if row is None else row.get(name)

    def assignments(self) -> dict[int, NameMatch]:
        """Face id -> NameMatch for every linked face (one name per face, one face per name)."""
        names = self.names()
        fids = sorted(self._rows)
        if not names or not fids:
            return {}
        mat = np.array([[self._rows[f][n] for n in names] for f in fids])
        return {
            fids[r]: NameMatch(fids[r], names[c], dist)
            for r, c, dist in assign_one_to_one(mat, self.name_threshold)
        }

    def _distance(self, face: npt.NDArray[np.float32], person: npt.NDArray[np.float32]) -> float:
        nn = _nn_distances(face, person)
        if self.k_smallest == 1:
            return float(nn.min())
        k = min(self.k_smallest, len(nn))
        return float(np.partition(nn, k - 1)[:k].mean())
