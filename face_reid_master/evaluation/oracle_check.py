"""How far apart an oracle-evidence scenario's people are, against the distances the likelihood in use decides at.

A scenario made with ``face-reid-sim --oracle-evidence`` (:mod:`face_reid_master.sim.oracle`) is meant to make
no two people confusable; this checks it in the space the master compares (the scenario's embeddings cut to the
evaluated space and scaled by the likelihood's component weights): the smallest distance between two people's
mean embeddings and between two of their observations, against the likelihood's decision distance (N_p = N_n,
pooled and per face-size bucket) and the naming distance; and the same for the bodies (per person and day) in
the body metric in use, against its decision distance (docs/evaluation.md, "Oracle evidence").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.embedding_spaces import extract_space
from face_reid_master.body.metric_file import BodyFeatureMetric
from face_reid_master.evaluation.body_rank import ScenarioBodies
from face_reid_master.identity.size_likelihood import FaceLikelihood
from face_reid_master.records import CameraFrameRecord
from face_reid_master.sim.oracle import closest_pair

__all__ = ["MAX_ROWS_PER_PERSON", "body_separation", "face_rows_by_person", "oracle_check", "separation"]

MAX_ROWS_PER_PERSON = 400  # observations per person compared pairwise (evenly spaced; the noise is i.i.d.)


def face_rows_by_person(frames: Sequence[CameraFrameRecord], frame_gt_ids: Sequence[NDArray[np.integer]],
                        have: str, want: str) -> dict[int, NDArray[np.float32]]:
    """True person -> (n, dim) the face embeddings of their detections in space ``want`` (``have``: the
    scenario's); false positives left out."""
    rows: dict[int, list[NDArray[np.float32]]] = {}
    for frame, gts in zip(frames, frame_gt_ids, strict=True):
        for person, gt in zip(frame.people, np.asarray(gts).tolist(), strict=True):
            if person.embedding is not None and gt >= 0:
                rows.setdefault(int(gt), []).append(np.asarray(person.embedding, dtype=np.float32))
    out = {}
    for gt, vals in rows.items():
        cut = extract_space(np.stack(vals), have, want)
        if cut is None:
            raise ValueError(f"the scenario's space {have!r} does not hold {want!r}")
        out[gt] = cut
    return out


def separation(rows: Mapping[int, NDArray[np.floating]], max_rows: int = MAX_ROWS_PER_PERSON) -> dict[str, Any]:
    """The smallest distance between two people's mean rows and between two rows of different people (up to
    ``max_rows`` evenly spaced rows each), and the median distance of a row to its person's mean."""
    means = {gt: r.astype(np.float64).mean(axis=0) for gt, r in rows.items() if len(r)}
    spread = [np.linalg.norm(r - means[gt], axis=1) for gt, r in rows.items() if len(r)]
    pair = closest_pair(means)
    sub = {gt: r[np.linspace(0, len(r) - 1, min(len(r), max_rows)).round().astype(int)].astype(np.float64)
           for gt, r in rows.items() if len(r)}
    best, best_pair = np.inf, None
    keys = sorted(sub)
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            d2 = (sub[a] ** 2).sum(axis=1)[:, None] + (sub[b] ** 2).sum(axis=1)[None, :] - 2.0 * sub[a] @ sub[b].T
            d = float(np.sqrt(max(float(d2.min()), 0.0)))
            if d < best:
                best, best_pair = d, [a, b]
    return {
        "people": len(means),
        "min_between_person_distance": None if pair is None else round(pair[0], 4),
        "closest_people": None if pair is None else [pair[1], pair[2]],
        "min_between_observations_distance": None if best_pair is None else round(best, 4),
        "closest_observations_people": best_pair,
        "median_within_person_distance": round(float(np.median(np.concatenate(spread))), 4) if spread else None,
    }


def body_separation(bodies: ScenarioBodies, feature: BodyFeatureMetric) -> dict[str, Any] | None:
    """:func:`separation` of a scenario's (thinned) bodies per person and day in the body metric ``feature``
    (its embedding: Euclidean distances are the metric's), against its decision distance; None without bodies."""
    if not bodies.labels.size:
        return None
    embedded = feature.embed(bodies.wire)
    rows = {int(k): embedded[bodies.labels == k] for k in np.unique(bodies.labels)}
    sep = separation(rows)
    closest = sep["min_between_observations_distance"]
    return {"metric": feature.name, "bodies": int(bodies.labels.size), "people_days": sep.pop("people"), **sep,
            "decision_distance": round(feature.decision_distance, 4),
            "separated": None if closest is None else bool(closest > feature.decision_distance)}


def oracle_check(document: Mapping[str, Any], frames: Sequence[CameraFrameRecord],
                 frame_gt_ids: Sequence[NDArray[np.integer]], likelihood: FaceLikelihood,
                 name_distance: float | None, bodies: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The ``oracle`` block of face-reid-eval's JSON for an oracle-evidence scenario (None for real evidence);
    ``bodies``: the :func:`body_separation` of the run's bodies (None: bodies not used)."""
    if not document.get("oracle"):
        return None
    have = str(document.get("embedding_space", "dlib_resnet_v1"))
    rows = face_rows_by_person(frames, frame_gt_ids, have, likelihood.space)
    scaled = {gt: likelihood.scale(r) for gt, r in rows.items()}
    sep = separation(scaled)
    decision = likelihood.decision_distance
    by_size = [round(m.decision_distance, 4) for m in likelihood.by_size] if likelihood.conditioned else []
    largest = max([decision, *(m.decision_distance for m in likelihood.by_size)])
    closest = sep["min_between_observations_distance"]
    return {
        "oracle": True,
        "noise_std": (document.get("oracle_evidence") or {}).get("noise_std"),
        "space": likelihood.space,
        **sep,
        "decision_distance": round(decision, 4),
        "decision_distance_by_size": by_size,
        "name_distance": None if name_distance is None else round(float(name_distance), 4),
        "separated": None if closest is None else bool(closest > largest
                                                       and (name_distance is None or closest > name_distance)),
        "bodies": bodies,
    }
