"""Oracle evidence (``face-reid-sim --oracle-evidence``): every observation of a person shows one fixed real
embedding (and body descriptor) plus a little Gaussian noise, so that no two people's faces can be confused
(two people's clothes may still look alike: their fixed descriptors are real ones).

It measures the identity logic apart from the evidence: whatever a scenario with oracle evidence still gets
wrong, no better embedder can mend (docs/evaluation.md, "Oracle evidence").

- Faces: a person's fixed embedding is, per component space of the scenario's space (the dlib and SFace parts of
  the joint space each on their own), the medoid of that identity's photo embeddings (each photo as is);
  every face observation of the person becomes it plus N(0, ``noise_std``) per value.
- Bodies: a person's fixed descriptor for a day (the clothes worn that day) is the medoid of the person's
  described body descriptors of that day in the scenario; every described body row of theirs becomes it plus
  the same noise. Undescribed rows (zeros) stay as they are.
- Observations of no person (false positives, gt id -1) are left as they are.

Pure: arrays in, arrays out; the simulator applies :func:`oracle_table` once, to the assembled frame table.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.embedding_spaces import parse_space
from face_reid_master.sim.frame_table import FrameTable

__all__ = ["ORACLE_NOISE_STD", "S_ORACLE", "OracleSummary", "closest_pair", "medoid_index", "oracle_rows",
           "oracle_table", "space_medoid"]

ORACLE_NOISE_STD = 0.01  # per value: ~0.11 between an observation and its person's vector in 128 values
S_ORACLE = 20  # its random stream (face_reid_master.sim.streams numbers the others below 13, and 99)
_CHUNK = 1024  # rows per block of the pairwise distances of a medoid


def medoid_index(rows: NDArray[np.floating]) -> int:
    """Index of the row with the smallest sum of L2 distances to all rows (ties: the first)."""
    x = np.asarray(rows, dtype=np.float64)
    if x.ndim != 2 or not x.shape[0]:
        raise ValueError(f"medoid of an empty or non 2-D array (shape {x.shape})")
    sq = np.einsum("ij,ij->i", x, x)
    totals = np.empty(x.shape[0])
    for lo in range(0, x.shape[0], _CHUNK):
        block = x[lo:lo + _CHUNK]
        d2 = sq[lo:lo + _CHUNK, None] + sq[None, :] - 2.0 * block @ x.T
        totals[lo:lo + _CHUNK] = np.sqrt(np.maximum(d2, 0.0)).sum(axis=1)
    return int(np.argmin(totals))


def space_medoid(rows: NDArray[np.floating], space: str) -> tuple[NDArray[np.float32], list[int]]:
    """The medoid of ``rows`` (n, dim of ``space``) taken per component space, concatenated; and the chosen row
    per component (a joint space's parts may come from different rows: each is a real embedding of its network)."""
    x = np.asarray(rows, dtype=np.float32)
    parts, chosen, start = [], [], 0
    for comp in parse_space(space):
        block = x[:, start:start + comp.dim]
        k = medoid_index(block)
        parts.append(block[k])
        chosen.append(k)
        start += comp.dim
    if start != x.shape[1]:
        raise ValueError(f"rows have {x.shape[1]} values, space {space!r} has {start}")
    return np.concatenate(parts).astype(np.float32), chosen


def oracle_rows(values: NDArray[np.floating], keys: NDArray[np.integer], centres: Mapping[int, NDArray[np.floating]],
                noise_std: float, rng: np.random.Generator) -> NDArray[np.float32]:
    """``values`` with every row whose key has a centre replaced by that centre plus N(0, noise_std) per value
    (rows of other keys unchanged). One draw per replaced row, in row order."""
    out = np.array(values, dtype=np.float32, copy=True)
    keys = np.asarray(keys)
    todo = np.flatnonzero(np.isin(keys, np.fromiter(centres, dtype=np.int64, count=len(centres))))
    if todo.size:
        table = {k: np.asarray(v, dtype=np.float32) for k, v in centres.items()}
        base = np.stack([table[int(k)] for k in keys[todo]])
        out[todo] = base + (noise_std * rng.standard_normal(base.shape)).astype(np.float32)
    return out


def closest_pair(centres: Mapping[int, NDArray[np.floating]]) -> tuple[float, int, int] | None:
    """(distance, key a, key b) of the two closest centres (L2), None with fewer than two."""
    keys = sorted(centres)
    if len(keys) < 2:
        return None
    x = np.stack([np.asarray(centres[k], dtype=np.float64) for k in keys])
    d = np.sqrt(np.maximum(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2), 0.0))
    d[np.diag_indices(len(keys))] = np.inf
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    a, b = sorted((keys[i], keys[j]))
    return float(d[i, j]), a, b


@dataclass(frozen=True)
class OracleSummary:
    """What :func:`oracle_table` did (for scenario.json): the noise, rows replaced, the medoids chosen and the
    closest two people's fixed vectors."""

    noise_std: float
    face_rows: int
    body_rows: int
    face_medoid_photos: dict[int, list[int]]  # gt id -> per component space, the photo index of the medoid
    face_closest: tuple[float, int, int] | None  # (L2 distance, gt a, gt b) between fixed face embeddings
    body_closest: tuple[float, int, int] | None  # (L2 distance, key a, key b), key = gt id * 100 + day

    def as_json(self) -> dict[str, Any]:
        def pair(p: tuple[float, int, int] | None, what: str) -> dict[str, Any] | None:
            return None if p is None else {"distance": round(p[0], 4), what: [p[1], p[2]]}

        return {"noise_std": self.noise_std, "face_rows": self.face_rows, "body_rows": self.body_rows,
                "face_medoid_photos": {str(k): v for k, v in sorted(self.face_medoid_photos.items())},
                "face_closest_people": pair(self.face_closest, "gt_ids"),
                "body_closest_people": pair(self.body_closest, "gt_id_x100_plus_day")}


def oracle_table(table: FrameTable, photo_embeddings: Sequence[NDArray[np.floating]],
                 photo_offsets: Sequence[int], space: str, day_starts_s: Sequence[float], noise_std: float,
                 rng_faces: np.random.Generator, rng_bodies: np.random.Generator) -> tuple[FrameTable, OracleSummary]:
    """The frame table with oracle evidence (module docstring).

    ``photo_embeddings[gt]``: (photos, dim) the identity's photo embeddings in ``space`` (its photos' scenario
    indices start at ``photo_offsets[gt]``); ``day_starts_s``: the days' start stamps in order (day 1 first).
    """
    if not (np.isfinite(noise_std) and noise_std >= 0):
        raise ValueError(f"noise_std must be a finite number >= 0, got {noise_std!r}")
    det_gt = np.asarray(table.det["gt_id"], dtype=np.int64)
    face_of_det = np.asarray(table.det["face"])
    face_gt = np.full(table.face["embedding"].shape[0], -1, dtype=np.int64)
    has_face = face_of_det >= 0
    face_gt[face_of_det[has_face]] = det_gt[has_face]
    centres: dict[int, NDArray[np.float32]] = {}
    medoid_photos: dict[int, list[int]] = {}
    for gt in sorted({int(g) for g in face_gt if g >= 0}):
        centres[gt], rows = space_medoid(photo_embeddings[gt], space)
        medoid_photos[gt] = [int(photo_offsets[gt]) + r for r in rows]
    face = dict(table.face)
    face["embedding"] = oracle_rows(table.face["embedding"], face_gt, centres, noise_std, rng_faces)
    n_face = int(np.count_nonzero(face_gt >= 0))

    body, body_centres, n_body = table.body, {}, 0
    if body is not None and "body" in table.det:
        body_of_det = np.asarray(table.det["body"])
        det_frame = np.repeat(np.arange(table.stamp_s.size), np.diff(table.offsets))
        det_day = np.searchsorted(np.asarray(day_starts_s, dtype=np.float64), table.stamp_s[det_frame] + 1e-9)
        key = np.full(body.described.size, -1, dtype=np.int64)
        with_body = body_of_det >= 0
        key[body_of_det[with_body]] = np.where(det_gt[with_body] >= 0,
                                               det_gt[with_body] * 100 + det_day[with_body], -1)
        key[~body.described] = -1  # undescribed rows stay zeros
        for k in sorted({int(v) for v in key if v >= 0}):
            rows = body.descriptor[key == k]
            body_centres[k] = rows[medoid_index(rows)].astype(np.float32)
        body = dataclasses.replace(body, descriptor=oracle_rows(body.descriptor, key, body_centres, noise_std,
                                                                rng_bodies))
        n_body = int(np.count_nonzero(key >= 0))
    out = FrameTable(table.camera, table.stamp_s, table.offsets, table.det, face, body)
    return out, OracleSummary(float(noise_std), n_face, n_body, medoid_photos, closest_pair(centres),
                              closest_pair(body_centres))
