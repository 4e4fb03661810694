"""Algorithm 1 of Koide et al. 2017 (III-D): face-ID assignment of people tracks, method-independent.

Pure core of the master node (no ROS).  The node feeds face embeddings per track
(:meth:`IdentityManagerBase.add_observations`), track deaths (:meth:`~IdentityManagerBase.track_deleted`)
and calls :meth:`~IdentityManagerBase.step` once per update; it gets back identity events.  How an
unassigned track is classified (known face or new person) is left to a subclass: the Bayesian posterior
table (:mod:`~face_reid_master.identity.bayes_table`) or the threshold baseline
(:mod:`~face_reid_master.identity.threshold`).

Scaling: eq. 4 for all unassigned observations is one GEMM over the :class:`FeatureBank`; above
``exact_search_max_features`` stored features only the ``shortlist_faces`` faces with the nearest
centroids are compared exactly and the others get the weakest evidence.  Observations of identified
tracks never need distances to other faces.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass, field
from itertools import accumulate
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real, check_stamp
from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.feature_bank import FeatureBank
from face_reid_master.identity.records import IdentityEvent, IdentityEventKind, IdentityStats, LearnedFace

__all__ = ["Chunk", "IdentityManagerBase", "TrackEntry", "Vote"]

FloatArray = npt.NDArray[np.float64]
F32Array = npt.NDArray[np.float32]


@dataclass
class _Face:
    """A learned face: its bank slot, metadata, and the live track carrying it (None = in face_list)."""

    face_id: int
    slot: int
    name: str | None
    created_s: float
    last_seen_s: float
    n_observations: int
    track_id: int | None = None


@dataclass(frozen=True, slots=True)
class Vote:
    """One observation's vote of the threshold baseline: a face id (0 = new person) and its distance."""

    face_id: int
    distance: float


class Chunk(NamedTuple):
    """Observations of one track queued by one :meth:`IdentityManagerBase.add_observations` call: the
    embeddings (K, dim), their eye distances (px; None = unknown), the stamp (s) and the camera."""

    embeddings: F32Array
    eye_px: FloatArray | None
    stamp_s: float
    source: str


@dataclass
class TrackEntry:
    """A live track of track_list, as seen by the identity layer (read by the classification methods)."""

    track_id: int
    slot: int | None = None  # bank slot buffering observed features while unassigned (track.face_images)
    n_observations: int = 0
    first_seen_s: float = 0.0
    last_seen_s: float = 0.0
    face_id: int | None = None
    confidence: float = 0.0
    votes: list[Vote] = field(default_factory=list)  # threshold baseline only
    inconsistent: list[Chunk] = field(default_factory=list)  # identified: the current run of faces not its face's
    evidence: str = ""  # identified: "face", "body" (no face seen yet) or "both" (body, then its face agreed)
    new_face: bool = False  # identified: its decision created the face (a person not known before)


def _rows(chunks: list[Chunk]) -> F32Array:
    """The embeddings of a track's queued chunks, stacked."""
    return chunks[0].embeddings if len(chunks) == 1 else np.concatenate([c.embeddings for c in chunks])


def _eye_rows(chunks: list[Chunk]) -> FloatArray:
    """Eye distance (px) of every row of a track's queued chunks (0 = unknown)."""
    return np.concatenate([c.eye_px if c.eye_px is not None else np.zeros(c.embeddings.shape[0]) for c in chunks])


class IdentityManagerBase:
    """Algorithm 1 of the paper, shared by the Bayesian method and the threshold baseline.

    face_list = learned faces not carried by a live track (assignable); track_list = live tracks.  An
    unassigned track accumulates evidence from its observations; once classified it gets a known face
    (which leaves face_list and absorbs the track's features) or a new face id.  While assigned, further
    observations are added to its face.  When the track dies the face returns to face_list.

    ``embedding_dim``: length of the face descriptors.  ``max_features_per_face``: bound of every face's
    (and unidentified track's) feature set, kept diverse
    (:func:`~face_reid_master.identity.feature_bank.select_diverse_subset`).  Eq. 4 is exact
    while face_list holds at most ``exact_search_max_features`` features; beyond, only the
    ``shortlist_faces`` faces with the nearest centroids are compared per observation.  Track ids must not
    be reused after :meth:`track_deleted` (late observations of a deleted id are ignored).

    ``feature_gate_distance`` (None = the paper: every observation of an identified track joins its face):
    an observation farther than this from every feature of the track's face is not learned (counted in
    ``stats.observations_not_learned_inconsistent``).  When the tracker swaps two people, the face then
    does not absorb the other person's features, which would make that person's later tracks look like
    this face.  ``release_after_inconsistent`` (0 = never, the paper; needs the gate): an identified track
    whose last this many observations were all beyond the gate has been swapped onto someone else: its
    face goes back to face_list (a SWAPPED event) and the track is classified afresh from those
    observations on, so the other person does not carry this face's name.

    ``lend_lost_faces`` (False = the paper): the face of a track the tracker lost goes back to face_list
    while the track is LOST (:meth:`track_lost`), so that the person's new track can take it.

    Subclasses (the classification methods) implement ``_ingest_unassigned``, ``_decide`` and
    ``_current_confidence`` and may override the ``_on_*`` notifications; the single-underscore state
    (``_tracks``, ``_available``, ``_available_slots``, ``_bank``) is shared with them only.
    """

    _DEAD_TRACK_MEMORY = 4096  # ids of deleted tracks remembered to ignore late observations

    def __init__(
        self,
        *,
        embedding_dim: int = 128,
        max_features_per_face: int = 50,
        exact_search_max_features: int = 5_000,
        shortlist_faces: int = 32,
        feature_gate_distance: float | None = None,
        release_after_inconsistent: int = 0,
        body_evidence: BodyEvidence | None = None,
        lend_lost_faces: bool = False,
    ) -> None:
        self.embedding_dim = check_int("embedding_dim", embedding_dim, 1)
        if body_evidence is not None and not isinstance(body_evidence, BodyEvidence):
            raise ValueError(f"body_evidence must be a BodyEvidence or None, got {type(body_evidence).__name__}")
        self.body_evidence = body_evidence
        self.lend_lost_faces = bool(lend_lost_faces)
        self._pending_bodies: dict[int, list[tuple[F32Array, float, str, FloatArray | None]]] = {}
        if feature_gate_distance is not None:
            feature_gate_distance = check_real(
                "feature_gate_distance", feature_gate_distance, 0.0, math.inf, low_open=True, high_open=True
            )
        self.feature_gate_distance = feature_gate_distance
        self.release_after_inconsistent = check_int("release_after_inconsistent", release_after_inconsistent, 0)
        if self.release_after_inconsistent and feature_gate_distance is None:
            raise ValueError("release_after_inconsistent needs feature_gate_distance (it counts the observations "
                             "beyond it); 0 = never release")
        self.max_features_per_face = check_int("max_features_per_face", max_features_per_face, 1)
        self.exact_search_max_features = check_int("exact_search_max_features", exact_search_max_features, 0)
        self.shortlist_faces = check_int("shortlist_faces", shortlist_faces, 1)
        self._bank = FeatureBank(self.embedding_dim, self.max_features_per_face)
        self._faces: dict[int, _Face] = {}
        self._tracks: dict[int, TrackEntry] = {}
        self._available: list[int] = []  # face_list in column order (Bayes: table columns 1..M)
        self._available_slots = np.zeros(0, dtype=np.intp)
        self._pending_obs: dict[int, list[Chunk]] = {}
        self._pending_deleted: dict[int, float] = {}
        self._lent: dict[int, int] = {}  # face id -> the LOST track holding it while it is in face_list
        self._side_events: list[IdentityEvent] = []  # lent faces taken from their LOST tracks this step
        self._dead: OrderedDict[int, float] = OrderedDict()
        self._next_face_id = 1
        self.stats = IdentityStats()

    # ------------------------------------------------------------------------------ public inputs
    def add_observations(self, track_id: int, embeddings: npt.ArrayLike, stamp_s: float,
                         eye_px: npt.ArrayLike | None = None, source: str = "") -> bool:
        """Queue face embeddings (K, embedding_dim) observed on a track; used at the next :meth:`step`.

        ``eye_px``: the face size (eye distance, px) of each row, for size-conditioned likelihoods (None or
        0: unknown). ``source``: the camera that saw them. Returns False (and counts it) when
        the track was already deleted (a late message). Raises ValueError on a wrong shape/dtype, NaN or Inf.
        """
        tid = check_int("track_id", track_id, -(2**63))
        stamp = check_stamp(stamp_s)
        emb = np.asarray(embeddings)
        if emb.ndim != 2 or emb.shape[1] != self.embedding_dim:
            raise ValueError(
                f"embeddings must have shape (K, {self.embedding_dim}), got {emb.shape} for track {tid}"
            )
        if not (np.issubdtype(emb.dtype, np.floating) or np.issubdtype(emb.dtype, np.integer)) or (
            emb.dtype == np.bool_
        ):
            raise ValueError(f"embeddings must be a real numeric array, got dtype {emb.dtype}")
        if not np.all(np.isfinite(emb)):
            raise ValueError(f"embeddings of track {tid} contain NaN or Inf")
        if emb.shape[0] == 0:
            return True
        eye = None
        if eye_px is not None:
            eye = np.asarray(eye_px, dtype=np.float64).reshape(-1)
            if eye.shape != (emb.shape[0],):
                raise ValueError(f"eye_px must have one value per embedding ({emb.shape[0]}), got {eye.shape}")
        if not isinstance(source, str):
            raise ValueError(f"source must be a str, got {type(source).__name__}")
        return self.add_validated_observations(tid, np.ascontiguousarray(emb, dtype=np.float32), stamp, eye,
                                               source)

    def add_validated_observations(self, tid: int, emb: F32Array, stamp: float,
                                   eye_px: FloatArray | None = None, source: str = "") -> bool:
        """:meth:`add_observations` for input already validated (MasterCore checks each frame once):
        ``emb`` a finite C-contiguous float32 (K >= 1, embedding_dim) array, ``stamp`` finite seconds,
        ``eye_px`` None or (K,) float64, ``source`` a str."""
        if tid in self._dead or tid in self._pending_deleted:
            self.stats.observations_ignored_dead_track += emb.shape[0]
            return False
        self._pending_obs.setdefault(tid, []).append(Chunk(emb, eye_px, stamp, source))
        self.stats.observations_received += emb.shape[0]
        track = self._tracks.get(tid)
        if track is not None:
            track.last_seen_s = max(track.last_seen_s, stamp)
        else:
            self._tracks[tid] = TrackEntry(tid, first_seen_s=stamp, last_seen_s=stamp)
        return True

    def add_body_observations(self, track_id: int, embeddings: F32Array, stamp_s: float, source: str = "",
                              heights: FloatArray | None = None) -> None:
        """Queue a track's body-appearance embeddings (k, r) (finite, validated by the caller) and head
        ``heights`` (k, m; None = unknown) seen by camera ``source`` for the next :meth:`step`; ignored
        without body evidence or for a deleted track."""
        if self.body_evidence is None or track_id in self._dead or track_id in self._pending_deleted:
            return
        self._pending_bodies.setdefault(track_id, []).append((embeddings, stamp_s, source, heights))
        self.stats.body_observations += embeddings.shape[0]
        if track_id not in self._tracks:
            self._tracks[track_id] = TrackEntry(track_id, first_seen_s=stamp_s, last_seen_s=stamp_s)

    def track_deleted(self, track_id: int, stamp_s: float) -> None:
        """The tracker dropped this track; handled at the next :meth:`step` (after its last evidence)."""
        tid = check_int("track_id", track_id, -(2**63))
        stamp = check_stamp(stamp_s)
        if tid in self._dead:
            return
        self._pending_deleted[tid] = stamp

    def track_lost(self, track_id: int) -> None:
        """The tracker lost the track (no detection for a while): its face goes back to face_list, lent, so
        that the person's new track can be identified with it; the LOST track keeps it unless another takes
        it (the person came back as a new track) before it is found again."""
        track = self._tracks.get(track_id)
        fid = None if track is None else track.face_id
        if not self.lend_lost_faces or fid is None or fid in self._lent or fid in self._available:
            return
        self._make_available(fid)
        self._lent[fid] = track_id

    def track_recovered(self, track_id: int) -> None:
        """The LOST track was detected again: it takes its face back from face_list if nobody took it."""
        track = self._tracks.get(track_id)
        fid = None if track is None else track.face_id
        if fid is not None and self._lent.get(fid) == track_id:
            del self._lent[fid]
            self._make_unavailable([fid])
            self._faces[fid].track_id = track_id

    def _take_lent(self, fid: int, stamp: float) -> None:
        """Face ``fid`` goes to another track: a LOST track that lent it is no longer identified."""
        lender = self._lent.pop(fid, None)
        track = None if lender is None else self._tracks.get(lender)
        if track is None or track.face_id != fid:
            return
        confidence = track.confidence
        track.face_id, track.confidence, track.evidence = None, 0.0, ""
        track.votes.clear()
        track.n_observations = 0
        self.stats.lent_faces_taken += 1
        self._side_events.append(IdentityEvent(IdentityEventKind.RELEASED, track.track_id, fid, stamp, confidence))

    def sync_alive_tracks(self, alive_track_ids: Iterable[int], stamp_s: float) -> None:
        """Mark every known track not in ``alive_track_ids`` as deleted (OpenPTrack's garbage collection)."""
        alive = {check_int("track_id", t, -(2**63)) for t in alive_track_ids}
        for tid in list(self._tracks):
            if tid not in alive:
                self.track_deleted(tid, stamp_s)

    def step(self, stamp_s: float) -> list[IdentityEvent]:
        """Run one update of Algorithm 1: ingest queued observations, classify, then handle deaths."""
        stamp = check_stamp(stamp_s)
        self.stats.steps += 1
        events: list[IdentityEvent] = []
        pending = self._pending_obs
        self._pending_obs = {}
        unassigned_ids: list[int] = []
        unassigned_obs: list[F32Array] = []
        unassigned_eye: list[FloatArray] = []
        bank = self._bank
        single_slots: list[int] = []  # one new feature into a full feature set: batched below
        single_obs: list[F32Array] = []
        rows = {tid: _rows(chunks) for tid, chunks in pending.items()}
        near = self._near_own_face(rows)
        for tid, chunks in pending.items():
            obs = rows[tid]
            track = self._tracks[tid]
            track.n_observations += obs.shape[0]
            if track.face_id is not None:
                face = self._faces[track.face_id]
                slot: int | None = face.slot
                face.n_observations += obs.shape[0]
                face.last_seen_s = max(face.last_seen_s, stamp)
                if tid in near:
                    keep = near[tid]
                    swapped = self._swapped_rows(track, chunks, keep)
                    obs = obs if keep.all() else obs[keep]
                    if swapped is not None:  # the face keeps what was its person's, then lets the track go
                        if obs.shape[0]:
                            bank.add_features(face.slot, obs)
                        events.append(self._release_swapped(track, stamp, swapped[0].stamp_s))
                        chunks = swapped
                        obs = _rows(chunks)
                        track.n_observations = obs.shape[0]
                    elif obs.shape[0] == 0:
                        continue
                if track.evidence == "body" and track.face_id is not None and obs.shape[0]:
                    track.evidence = "both"  # its own face agrees with the body decision
            if track.face_id is None:
                slot = track.slot
                if slot is None:
                    track.slot = bank.new_slot(obs)
                unassigned_ids.append(tid)
                unassigned_obs.append(obs)
                unassigned_eye.append(_eye_rows(chunks))
            if slot is not None:
                if obs.shape[0] == 1 and bank.count[slot] == bank.kmax >= 2:
                    single_slots.append(slot)
                    single_obs.append(obs)
                else:
                    bank.add_features(slot, obs)
        if single_slots:
            bank.add_one_each(np.array(single_slots, dtype=np.intp), np.concatenate(single_obs))
        if unassigned_ids:
            self._ingest_unassigned(unassigned_ids, unassigned_obs, unassigned_eye)
        for tid, face_or_new, confidence in self._decide():
            events.append(self._apply_decision(tid, face_or_new, confidence, stamp))
        if self.body_evidence is not None:
            events.extend(self._body_step(stamp))
        events.extend(self._side_events)
        self._side_events = []
        for tid in list(self._pending_deleted):
            ev = self._remove_track(tid, self._pending_deleted[tid])
            if ev is not None:
                events.append(ev)
        self._pending_deleted.clear()
        return events

    def _body_step(self, stamp: float) -> list[IdentityEvent]:
        """Bodies of identified tracks join their face's gallery; faceless tracks gather body evidence against
        every learned face and are given one of face_list when that evidence is strong enough (their own face,
        once seen, overrules it)."""
        body = self.body_evidence
        assert body is not None
        pending, self._pending_bodies = self._pending_bodies, {}
        for tid, parts in pending.items():
            track = self._tracks.get(tid)
            if track is None:
                continue
            for emb, t, source, heights in parts:
                if track.face_id is not None:
                    body.add_face_bodies(track.face_id, emb, t, heights)
                else:  # faceless tracks are compared; the others only keep their bodies for their face
                    body.observe(tid, emb, t, list(self._faces) if track.slot is None else [], source, heights)
        events = []
        for tid, fid, p in body.decide(self._available, stamp, self._faces_alike):
            track = self._tracks.get(tid)
            if track is not None and track.face_id is None and track.slot is None and fid in self._available:
                events.append(self._apply_body_decision(track, fid, p, stamp))
        return events

    def _apply_body_decision(self, track: TrackEntry, fid: int, confidence: float, stamp: float) -> IdentityEvent:
        """A faceless track is face ``fid``'s person by their body: it carries the face (no features to add)."""
        face = self._faces[fid]
        self._take_lent(fid, stamp)
        self._make_unavailable([fid])
        face.track_id = track.track_id
        face.last_seen_s = max(face.last_seen_s, stamp)
        self._on_track_identified(track.track_id)
        track.face_id = fid
        track.confidence = float(confidence)
        track.evidence = "body"
        track.new_face = False
        self._move_track_bodies(track.track_id, fid)
        self.stats.assigned_by_body += 1
        return IdentityEvent(IdentityEventKind.ASSIGNED_KNOWN, track.track_id, fid, stamp, float(confidence),
                             evidence="body")

    def _move_track_bodies(self, tid: int, fid: int) -> None:
        """The bodies a track gathered before its decision join its face's gallery."""
        body = self.body_evidence
        if body is None:
            return
        emb, newest, heights = body.track_bodies(tid)
        if emb.shape[0]:
            body.add_face_bodies(fid, emb, newest, heights=heights)
        body.forget_track(tid)

    def _face_distances(self, face: int, others: list[int]) -> FloatArray:
        """The smallest distance between the stored features of learned ``face`` and of each of ``others``, in one
        batched computation (NaN where either face is unknown)."""
        out = np.full(len(others), np.nan)
        top = self._faces.get(face)
        known = [k for k, f in enumerate(others) if f in self._faces]
        if top is None or not known:
            return out
        slots = np.array([self._faces[others[k]].slot for k in known], dtype=np.intp)
        d = self._bank.exact_min_distances(self._bank.features(top.slot), slots)
        if d.size:
            out[known] = d.min(axis=0)
        return out

    def _faces_alike(self, face: int, others: list[int]) -> list[bool]:
        """Which of ``others`` are the same person as learned ``face``: features closer than the body evidence's
        ``alike_face_distance`` (default: half the decision distance); NaN (unknown face): not alike."""
        assert self.body_evidence is not None
        limit = self.body_evidence.alike_face_distance
        if limit is None and self.feature_gate_distance is not None:
            limit = 0.5 * self.feature_gate_distance
        if limit is None:
            return [False] * len(others)
        return (self._face_distances(face, others) < limit).tolist()

    def _near_own_face(self, rows: dict[int, F32Array]) -> dict[int, npt.NDArray[np.bool_]]:
        """For each identified track's new observations: which lie within ``feature_gate_distance`` of a stored
        feature of its face (all tracks in one batched product; {} when the gate is off)."""
        gate = self.feature_gate_distance
        ident = [tid for tid in rows if self._tracks[tid].face_id is not None] if gate is not None else []
        if not ident:
            return {}
        obs = np.concatenate([rows[tid] for tid in ident])
        counts = [rows[tid].shape[0] for tid in ident]
        slots = np.repeat(np.array([self._faces[self._tracks[tid].face_id].slot for tid in ident], np.intp), counts)
        keep = self._bank.own_min_distances(obs, slots) <= gate
        self.stats.observations_not_learned_inconsistent += int(keep.size - np.count_nonzero(keep))
        ends = list(accumulate(counts))
        return {tid: keep[end - n:end] for tid, n, end in zip(ident, counts, ends, strict=True)}

    def _swapped_rows(self, track: TrackEntry, chunks: list[Chunk], keep: npt.NDArray[np.bool_]
                      ) -> list[Chunk] | None:
        """Follow the identified track's run of inconsistent observations; once it is
        ``release_after_inconsistent`` long, the chunks from the run's start on (None: no swap)."""
        k = self.release_after_inconsistent
        if not k:
            return None
        if keep.size and keep.all():  # every observation consistent: any run is over
            track.inconsistent.clear()
            return None
        start = 0
        for c in chunks:
            n = c.embeddings.shape[0]
            ok = keep[start:start + n]
            start += n
            if ok.all():
                track.inconsistent.clear()
                continue
            last_ok = int(np.flatnonzero(ok)[-1]) if ok.any() else -1
            if last_ok >= 0:
                track.inconsistent.clear()
            rows = slice(last_ok + 1, None)
            track.inconsistent.append(Chunk(c.embeddings[rows], None if c.eye_px is None else c.eye_px[rows],
                                            c.stamp_s, c.source))
        run = track.inconsistent
        if sum(c.embeddings.shape[0] for c in run) < k:
            return None
        track.inconsistent = []
        return run

    # ------------------------------------------------------------------------------ queries
    def evidence_of(self, track_id: int) -> str:
        """What identified a live track: "face", "body", "both" (a body decision its face then confirmed), or
        "" (unidentified / unknown track)."""
        track = self._tracks.get(track_id)
        return "" if track is None or track.face_id is None else track.evidence

    def decided_new(self, track_id: int) -> bool:
        """Whether a live identified track's decision created its face (False otherwise)."""
        track = self._tracks.get(track_id)
        return track is not None and track.face_id is not None and track.new_face

    def face_id_of(self, track_id: int) -> int | None:
        """Face id assigned to a live track, or None while unidentified / unknown track."""
        track = self._tracks.get(track_id)
        return None if track is None else track.face_id

    def confidence_of(self, track_id: int) -> float:
        """Current max posterior (Bayes) / leading vote fraction of an unassigned track; the decision
        confidence once assigned; 0.0 for an unknown track."""
        track = self._tracks.get(track_id)
        if track is None:
            return 0.0
        if track.face_id is not None:
            return track.confidence
        return self._current_confidence(track)

    def posterior_of(self, track_id: int) -> dict[int, float]:
        """Hypotheses of an unassigned track: {0: new person, face_id: probability}; {} if none."""
        return {}

    def assigned_tracks(self) -> dict[int, int]:
        """Live track id -> face id for all identified tracks."""
        return {t.track_id: t.face_id for t in self._tracks.values() if t.face_id is not None}

    def live_track_ids(self) -> list[int]:
        """Tracks that have reported observations and are not deleted."""
        return list(self._tracks)

    def face_ids(self) -> list[int]:
        """All learned face ids (assigned or in face_list)."""
        return sorted(self._faces)

    def available_face_ids(self) -> list[int]:
        """face_list: learned faces not carried by a live track, in table-column order."""
        return list(self._available)

    def face_features(self, face_id: int) -> F32Array:
        """Copy of a learned face's stored features (k, embedding_dim)."""
        return self._bank.features(self._face(face_id).slot).copy()

    def face_name(self, face_id: int) -> str | None:
        return self._face(face_id).name

    def set_face_name(self, face_id: int, name: str | None) -> None:
        """Attach a (predefined-person) name to a learned face, or clear it with None."""
        if name is not None and not isinstance(name, str):
            raise ValueError(f"name must be a str or None, got {name!r}")
        self._face(face_id).name = name

    def forget_face(self, face_id: int) -> bool:
        """Remove a learned face entirely (privacy: "delete this person"); False if the id is unknown.

        The face leaves face_list (its table column / threshold votes go) and its bank slot is zeroed.
        If a live track carries it, that track becomes unidentified again: its assignment, confidence
        and queued observations are dropped (they were merged into / meant for the forgotten face), so
        while the person stays in view new observations are classified afresh and normally create a
        *new* face id after ``min_observations``.  Face ids are never reused within this manager.
        """
        fid = check_int("face_id", face_id, -(2**63))
        face = self._faces.get(fid)
        if face is None:
            return False
        lender = self._lent.pop(fid, None)
        if lender is not None and lender in self._tracks and self._tracks[lender].face_id == fid:
            self._tracks[lender].face_id = None  # a LOST track lent it: it holds nothing now
            self._tracks[lender].confidence = 0.0
        if face.track_id is None:
            self._make_unavailable([fid])
        else:
            track = self._tracks.get(face.track_id)
            if track is not None and track.face_id == fid:
                track.face_id = None
                track.confidence = 0.0
                track.n_observations = 0
                track.votes.clear()
                track.inconsistent.clear()
                self._pending_obs.pop(track.track_id, None)
        self._bank.free_slot(face.slot)
        del self._faces[fid]
        if self.body_evidence is not None:
            self.body_evidence.forget_face(fid)
        self.stats.faces_forgotten += 1
        return True

    def eviction_order(self, exclude: Iterable[int] = ()) -> list[int]:
        """The unnamed faces of face_list (no live or lost track holds them) not in ``exclude``, least recently
        seen first: what the face cap may evict (named faces never)."""
        skip = set(exclude) | set(self._lent)
        faces = [self._faces[fid] for fid in self._available if fid not in skip and not self._faces[fid].name]
        return [f.face_id for f in sorted(faces, key=lambda f: (f.last_seen_s, f.face_id))]

    def export_face(self, face_id: int) -> LearnedFace:
        """Snapshot (copy) of one learned face, e.g. to save it when its track is released; KeyError if unknown."""
        f = self._face(face_id)
        return LearnedFace(
            f.face_id, self._bank.features(f.slot).copy(), f.name, f.created_s, f.last_seen_s, f.n_observations
        )

    def export_faces(self) -> list[LearnedFace]:
        """Snapshot of all learned faces (copies), for the persistent memory."""
        return [self.export_face(fid) for fid in sorted(self._faces)]

    def reserve_face_ids(self, highest_used_id: int) -> None:
        """Never hand out face ids <= ``highest_used_id`` (ids of forgotten faces stay retired)."""
        self._next_face_id = max(self._next_face_id, check_int("highest_used_id", highest_used_id, 0) + 1)

    def import_faces(self, faces: Iterable[LearnedFace]) -> None:
        """Add previously exported faces to face_list; ValueError on an id clash or wrong dimension."""
        batch = list(faces)
        seen: set[int] = set()
        for f in batch:
            if not isinstance(f, LearnedFace):
                raise ValueError(f"import_faces expects LearnedFace records, got {type(f).__name__}")
            if f.features.shape[1] != self.embedding_dim:
                raise ValueError(
                    f"face {f.face_id}: features have dim {f.features.shape[1]}, "
                    f"expected {self.embedding_dim}"
                )
            if f.face_id in self._faces or f.face_id in seen:
                raise ValueError(f"face id {f.face_id} already exists")
            seen.add(f.face_id)
        for f in batch:
            slot = self._bank.new_slot(f.features)
            self._faces[f.face_id] = _Face(
                f.face_id, slot, f.name, f.created_s, f.last_seen_s, f.n_observations, track_id=None
            )
            self._next_face_id = max(self._next_face_id, f.face_id + 1)
            self._make_available(f.face_id)

    # ------------------------------------------------------------------------------ internals
    def _face(self, face_id: int) -> _Face:
        face = self._faces.get(face_id)
        if face is None:
            raise KeyError(f"unknown face id {face_id}")
        return face

    def _available_distances(self, obs: F32Array) -> FloatArray:
        """Eq. 4 distances (Q, M) from observations to every face in face_list (column order)."""
        slots = self._available_slots
        if len(slots) == 0:
            return np.zeros((obs.shape[0], 0))
        n_feats = int(self._bank.count[slots].sum())
        if n_feats > self.exact_search_max_features and len(slots) > self.shortlist_faces:
            self.stats.shortlist_searches += 1
            return self._bank.shortlist_min_distances(obs, slots, self.shortlist_faces)
        return self._bank.exact_min_distances(obs, slots)

    def _make_available(self, face_id: int) -> None:
        self._faces[face_id].track_id = None
        self._available.append(face_id)
        self._available_slots = np.append(self._available_slots, self._faces[face_id].slot).astype(np.intp)
        self._on_face_available(face_id)

    def _make_unavailable(self, face_ids: list[int]) -> None:
        idx = [self._available.index(f) for f in face_ids]
        keep = np.ones(len(self._available), dtype=bool)
        keep[idx] = False
        self._on_faces_unavailable(idx)
        self._available = [f for f, k in zip(self._available, keep, strict=True) if k]
        self._available_slots = self._available_slots[keep]

    def _apply_decision(self, tid: int, face_or_new: int, confidence: float, stamp: float) -> IdentityEvent:
        track = self._tracks[tid]
        assert track.slot is not None, "a track is only classified after observations"
        if face_or_new == 0:
            fid = self._next_face_id
            self._next_face_id += 1
            slot = track.slot  # the track's buffer becomes the new face's feature set
            self._faces[fid] = _Face(fid, slot, None, stamp, stamp, track.n_observations, track_id=tid)
            kind = IdentityEventKind.NEW_FACE
            self.stats.new_faces += 1
        else:
            fid = face_or_new
            face = self._faces[fid]
            self._take_lent(fid, stamp)
            self._make_unavailable([fid])
            self._bank.add_features(face.slot, self._bank.features(track.slot))  # add result.face_images
            self._bank.free_slot(track.slot)
            face.track_id = tid
            face.n_observations += track.n_observations
            face.last_seen_s = max(face.last_seen_s, stamp)
            kind = IdentityEventKind.ASSIGNED_KNOWN
            self.stats.assigned_known += 1
        self._on_track_identified(tid)
        self._faces[fid].track_id = tid
        track.face_id = fid
        track.confidence = float(confidence)
        track.slot = None
        track.votes.clear()
        track.evidence = "face"
        track.new_face = kind == IdentityEventKind.NEW_FACE
        self._move_track_bodies(tid, fid)
        return IdentityEvent(kind, tid, fid, stamp, float(confidence))

    def _release_swapped(self, track: TrackEntry, stamp: float, since: float) -> IdentityEvent:
        """The track is not its face's person any more: the face returns to face_list, the track is unassigned."""
        assert track.face_id is not None
        fid, confidence = track.face_id, track.confidence
        self._make_available(fid)
        track.face_id = None
        track.confidence = 0.0
        track.votes.clear()
        track.n_observations = 0
        self.stats.swaps_released += 1
        return IdentityEvent(IdentityEventKind.SWAPPED, track.track_id, fid, stamp, confidence, since)

    def _remove_track(self, tid: int, stamp: float) -> IdentityEvent | None:
        self._dead[tid] = stamp
        while len(self._dead) > self._DEAD_TRACK_MEMORY:
            self._dead.popitem(last=False)
        self._pending_obs.pop(tid, None)
        self._pending_bodies.pop(tid, None)
        if self.body_evidence is not None:
            self.body_evidence.forget_track(tid)
        track = self._tracks.pop(tid, None)
        if track is None:
            return None
        if track.face_id is None:
            if track.slot is not None:
                self._bank.free_slot(track.slot)
            self._on_track_forgotten(tid)
            return None
        if self._lent.get(track.face_id) == tid:  # already in face_list
            del self._lent[track.face_id]
        else:
            self._make_available(track.face_id)
        self.stats.released += 1
        return IdentityEvent(IdentityEventKind.RELEASED, tid, track.face_id, stamp, track.confidence)

    # hooks for the classification method
    def _ingest_unassigned(self, track_ids: list[int], observations: list[F32Array],
                           eye_px: list[FloatArray]) -> None:
        """Accumulate the evidence of this step's observations of unassigned tracks (one array per track;
        ``eye_px``: the eye distance of each row, px, 0 = unknown)."""
        raise NotImplementedError

    def _decide(self) -> list[tuple[int, int, float]]:
        """(track id, face id or 0 = new person, confidence) for every unassigned track decided now."""
        raise NotImplementedError

    def _current_confidence(self, track: TrackEntry) -> float:
        """Confidence of an unassigned track's leading hypothesis, in [0, 1]."""
        raise NotImplementedError

    def _on_face_available(self, face_id: int) -> None:
        """A face joined face_list (appended as the last column)."""

    def _on_faces_unavailable(self, column_indices: list[int]) -> None:
        """Faces at these 0-based positions of face_list are leaving it."""

    def _on_track_identified(self, track_id: int) -> None:
        """An unassigned track got a face id (its table row goes away)."""

    def _on_track_forgotten(self, track_id: int) -> None:
        """An unassigned track died."""

