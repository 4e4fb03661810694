"""Body evidence for identities: what each learned face's person wore lately, and who a faceless track is.

Faces identify people only while they show them. Every learned face therefore also keeps the body
appearance of its person's recent tracks (embeddings of the body metric, :meth:`~face_reid_master.body.
metric_file.BodyFeatureMetric.embed`), each with its stamp: clothes change, so an embedding older than
``window_s`` no longer counts (faces never expire). A live track that has shown no face accumulates, per
face in face_list with recent bodies, the log-likelihood ratio of its body observations (N_p / N_n of the
body distance, fitted with the metric); a face is decided when its posterior, against every other such face
and "someone else" (a person without recent bodies here: new, or in other clothes), passes a strict
threshold after enough observations. Body evidence never creates a face: only a face does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.identity.alike_group import Alike, alike_group
from face_reid_master.identity.body_gallery import FaceBodyPool
from face_reid_master.identity.feature_funnel import funnel_survivors, gaussian_log_ratio
from face_reid_master.identity.likelihood import LikelihoodModel

__all__ = ["BodyEvidence"]

F32 = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]


@dataclass
class _TrackBodies:
    """A faceless track's body observations so far (bounded) and its evidence per face id."""

    rows: list[F32] = field(default_factory=list)
    stamps: list[float] = field(default_factory=list)
    heights: list[float] = field(default_factory=list)
    log_ratio: dict[int, float] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)
    last_used: dict[str, float] = field(default_factory=dict)  # camera -> stamp of its last observation used


class BodyEvidence:
    """Body galleries of learned faces and body evidence of faceless tracks (see the module doc).

    ``likelihood``: N_p / N_n of the body distance (the body metric's fused feature). ``window_s``: bodies
    older than this do not count. ``gallery_size``: embeddings kept per face. ``posterior_threshold`` and
    ``min_observations``: a faceless track is decided when one face's posterior exceeds the threshold after at
    least that many observations compared with it. ``max_log_ratio``: bound of one observation's evidence
    (frames of one glance are far from independent). ``other_log_odds``: log prior odds of "someone else".
    ``min_interval_s``: one camera's observations of a track count as evidence at most this often (the
    frames in between show nearly the same view; they are still kept for the face's gallery).
    A faceless track's body appearance and head height are combined by the feature funnel (see
    :mod:`~face_reid_master.identity.feature_funnel`): appearance first; a face whose recent bodies are farther
    than ``funnel_alpha`` x the nearest face's is abandoned for that observation, the others are also judged
    by height. ``height_same_std_m`` /
    ``height_other_std_m``: spread of the difference between a person's head height and their face's recent
    median, for the same person / another person (m). Learned faces of one person (the caller's ``alike``) count
    as one: their posteriors are added up (:mod:`~face_reid_master.identity.alike_group`).
    """

    def __init__(self, likelihood: LikelihoodModel, *, window_s: float = 3600.0, gallery_size: int = 64,
                 posterior_threshold: float = 0.99, min_observations: int = 10, max_log_ratio: float = 0.3,
                 other_log_odds: float = 0.0, track_buffer: int = 64, min_interval_s: float = 0.5,
                 funnel_alpha: float = 1.5, height_same_std_m: float = 0.05,
                 height_other_std_m: float = 0.12) -> None:
        if not isinstance(likelihood, LikelihoodModel):
            raise ValueError(f"likelihood must be a LikelihoodModel, got {type(likelihood).__name__}")
        self.likelihood = likelihood
        self.window_s = check_real("window_s", window_s, 0.0, math.inf, low_open=True)
        self.gallery_size = check_int("gallery_size", gallery_size, 1)
        self.posterior_threshold = check_real("posterior_threshold", posterior_threshold, 0.5, 1.0,
                                              low_open=True, high_open=True)
        self.min_observations = check_int("min_observations", min_observations, 1)
        self.max_log_ratio = check_real("max_log_ratio", max_log_ratio, 0.0, math.inf, low_open=True)
        self.other_log_odds = check_real("other_log_odds", other_log_odds)
        self.track_buffer = check_int("track_buffer", track_buffer, 1)
        self.min_interval_s = check_real("min_interval_s", min_interval_s, 0.0)
        self.funnel_alpha = check_real("funnel_alpha", funnel_alpha, 1.0, math.inf, low_open=True)
        self.height_same_std_m = check_real("height_same_std_m", height_same_std_m, 0.0, math.inf, low_open=True)
        self.height_other_std_m = check_real("height_other_std_m", height_other_std_m, self.height_same_std_m,
                                             math.inf, low_open=True)
        self._faces = FaceBodyPool(self.gallery_size)
        self._tracks: dict[int, _TrackBodies] = {}

    # ------------------------------------------------------------------ faces
    def add_face_bodies(self, face_id: int, embeddings: F32, stamp_s: float,
                        heights: npt.ArrayLike | None = None) -> None:
        """What the person of ``face_id`` wears now (rows of the body metric's embedding) and their head
        ``heights`` (m per row, None = unknown)."""
        if embeddings.shape[0] == 0:
            return
        self._faces.add(face_id, embeddings, stamp_s, _heights(heights, embeddings.shape[0]))

    def forget_face(self, face_id: int) -> None:
        """Drop a face's bodies (the face was forgotten)."""
        self._faces.release(face_id)
        for track in self._tracks.values():
            track.log_ratio.pop(face_id, None)
            track.counts.pop(face_id, None)

    def face_bodies(self, face_id: int, now_s: float) -> F32:
        """A face's recent body embeddings (k, r)."""
        return self._faces.face_rows(face_id, now_s - self.window_s)

    # ------------------------------------------------------------------ tracks
    def observe(self, track_id: int, embeddings: F32, stamp_s: float, candidates: list[int],
                source: str = "", heights: npt.ArrayLike | None = None) -> None:
        """Body observations of a track seen by camera ``source`` (with head ``heights``, m, None = unknown):
        kept (for its face, once it has one) and, at most every ``min_interval_s`` per camera, compared with
        the recent bodies of the ``candidates``."""
        track = self._tracks.setdefault(track_id, _TrackBodies())
        h = _heights(heights, embeddings.shape[0])
        track.rows.extend(embeddings)
        track.stamps.extend([stamp_s] * embeddings.shape[0])
        track.heights.extend(h.tolist())
        if len(track.rows) > self.track_buffer:  # keep an even spread of the track's history
            keep = np.linspace(0, len(track.rows) - 1, self.track_buffer).round().astype(int)
            track.rows = [track.rows[i] for i in keep]
            track.stamps = [track.stamps[i] for i in keep]
            track.heights = [track.heights[i] for i in keep]
        if not candidates or stamp_s < track.last_used.get(source, -math.inf) + self.min_interval_s:
            return
        track.last_used[source] = stamp_s
        pool = self._faces
        if embeddings.shape[1] != pool.dim:
            return
        slots = np.array([pool.slot_of[f] for f in candidates if f in pool.slot_of], dtype=np.intp)
        if not slots.size:
            return
        recent = pool.stamps >= stamp_s - self.window_s
        best, _ = pool.nearest(embeddings, recent)  # every face at once: (observations, slots)
        best = best[:, slots]
        seen = np.isfinite(best).all(axis=0)
        if not seen.any():
            return
        slots = slots[seen]
        faces = pool.face[slots].tolist()
        d = np.sqrt(best[:, seen])
        face_heights = pool.slot_heights(recent)[slots]
        lr = self._log_ratios(d, np.abs(h[:, None] - face_heights[None, :])).sum(axis=0)
        for face_id, value in zip(faces, lr.tolist(), strict=True):
            track.log_ratio[face_id] = track.log_ratio.get(face_id, 0.0) + value
            track.counts[face_id] = track.counts.get(face_id, 0) + embeddings.shape[0]

    def _log_ratios(self, appearance: FloatArray, height_difference: FloatArray) -> FloatArray:
        """Per observation and face, the log-likelihood ratio of "same person" from the appearance distances
        and head-height differences (NaN: not measured, no evidence), fused by the feature funnel."""
        cap = self.max_log_ratio
        lr = np.clip(self.likelihood.log_likelihood_ratio(appearance), -cap, cap)
        geo = np.clip(gaussian_log_ratio(height_difference, self.height_same_std_m, self.height_other_std_m),
                      -cap, cap)
        lr = lr + np.where(np.isfinite(geo), geo, 0.0)
        keep = funnel_survivors([appearance, height_difference], [self.funnel_alpha])  # appearance prunes
        return np.where(keep, lr, -cap)  # the faces abandoned get the bound against them

    def track_bodies(self, track_id: int) -> tuple[F32, float, FloatArray]:
        """The track's kept body embeddings (k, r), the stamp of its newest and their head heights (for its
        face's gallery)."""
        track = self._tracks.get(track_id)
        if track is None or not track.rows:
            return np.zeros((0, 0), np.float32), -math.inf, np.zeros(0)
        return np.stack(track.rows), max(track.stamps), np.array(track.heights)

    def forget_track(self, track_id: int) -> None:
        """Drop a track's bodies and evidence (it was deleted, or its bodies joined its face's gallery)."""
        self._tracks.pop(track_id, None)

    def posterior(self, track_id: int, candidates: list[int], now_s: float) -> dict[int, float]:
        """{face_id: posterior} over the candidates with recent bodies, plus 0 = someone else."""
        recent = set(candidates) & set(self._faces.recent_faces(now_s - self.window_s).tolist())
        return self._posterior(self._tracks.get(track_id), recent)

    def _posterior(self, track: _TrackBodies | None, recent: set[int]) -> dict[int, float]:
        faces = [f for f in track.log_ratio if f in recent] if track is not None else []
        logs = np.array([self.other_log_odds] + [track.log_ratio[f] for f in faces]) if track else np.zeros(1)
        p = np.exp(logs - logs.max())
        p /= p.sum()
        return dict(zip([0, *faces], p.tolist(), strict=True))

    def decide(self, available: list[int], now_s: float,
               alike: Alike | None = None) -> list[tuple[int, int, float]]:
        """(track id, face id, posterior) of the faceless tracks decided now: one face per track and one track
        per face (the most confident first). The posterior is over every face with recent bodies (those held
        by live tracks too: a track that looks most like someone already tracked is not decided), and only an
        ``available`` face (in face_list) can be given. ``alike(a, others)``: which of ``others`` are face a's person
        (their posteriors are added up; the most likely available one of them is given)."""
        compared = [(tid, t) for tid, t in self._tracks.items() if t.log_ratio]  # faceless tracks with evidence
        if not compared:
            return []
        recent = set(self._faces.recent_faces(now_s - self.window_s).tolist())
        free = set(available)
        wanted = []
        for track_id, track in compared:
            post = self._posterior(track, recent)
            face, p = max(post.items(), key=lambda kv: kv[1])
            if face == 0:
                continue
            if face not in free or p <= self.posterior_threshold:
                face, p = alike_group(post, face, free, alike, self.posterior_threshold)
            if face in free and p > self.posterior_threshold and track.counts.get(face, 0) >= self.min_observations:
                wanted.append((p, track_id, face))
        out, taken = [], set()
        for p, track_id, face in sorted(wanted, reverse=True):
            if face not in taken:
                taken.add(face)
                out.append((track_id, face, p))
        return out


def _heights(heights: npt.ArrayLike | None, n: int) -> FloatArray:
    """``n`` head heights (m) from the caller's (None: unknown = NaN)."""
    if heights is None:
        return np.full(n, math.nan)
    h = np.asarray(heights, dtype=np.float64).reshape(-1)
    if h.size != n:
        raise ValueError(f"heights must hold one value per embedding row ({n}), got {h.size}")
    return h
