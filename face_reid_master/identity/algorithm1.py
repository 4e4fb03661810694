"""Algorithm 1 of Koide et al. 2017 (III-D): face-ID assignment of people tracks, method-independent.

face_list = learned faces not carried by a live track (assignable); track_list = live tracks. An unassigned
track accumulates evidence from its observations; once classified it gets a known face (which leaves face_list
and absorbs the track's features) or a new face id. While assigned, further observations are added to its
face. When the track dies the face returns to face_list.

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
from collections.abc import Iterable, Sequence

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real, check_stamp
from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.body_identification import BodyIdentification
from face_reid_master.identity.co_sightings import CoSightings
from face_reid_master.identity.crossings import Crossings
from face_reid_master.identity.entries import (
    Chunk,
    FaceEntry,
    TrackRecord,
    checked_observations,
    eye_rows,
    rows_of,
)
from face_reid_master.identity.evidence import CueChunk, Cues, Evidence, EvidenceSource
from face_reid_master.identity.face_list import FaceList
from face_reid_master.identity.feature_bank import FeatureBank
from face_reid_master.identity.lent_faces import LentFaces
from face_reid_master.identity.records import IdentityEvent, IdentityEventKind, IdentityStats
from face_reid_master.identity.swap_guard import SwapGuard
from face_reid_master.identity.track_list import TrackList

__all__ = ["IdentityManagerBase"]

FloatArray = npt.NDArray[np.float64]
F32Array = npt.NDArray[np.float32]


class IdentityManagerBase:
    """Algorithm 1 of the paper, shared by the Bayesian method and the threshold baseline.

    ``embedding_dim``: length of the face descriptors.  ``max_features_per_face``: bound of every face's (and
    unidentified track's) feature set, kept diverse (:func:`~.feature_bank.select_diverse_subset`).  Eq. 4 is
    exact while face_list holds at most ``exact_search_max_features`` features; beyond, only the ``shortlist_faces``
    faces with the nearest centroids are compared.  Track ids must not be reused after :meth:`track_deleted`.

    Our extensions, off by default (the paper): ``feature_gate_distance`` / ``release_after_inconsistent``
    (:mod:`~.swap_guard`), ``body_evidence`` (:mod:`~.body_identification`), ``lend_lost_faces`` (:mod:`~.lent_faces`),
    ``alike_face_distance`` (:mod:`~.alike_group`; None: half the gate); always on: crossing doubt (:mod:`~.crossings`).

    Subclasses (the classification methods) implement ``_ingest_unassigned``, ``_decide`` and ``_current_confidence``
    and may override the ``_on_*`` notifications; they read :attr:`tracks`, :attr:`faces` and the bank ``_bank``.
    """

    learn_confidence: float = 0.0  # a method's: a face decision below it identifies its track, teaches its face nothing

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
        alike_face_distance: float | None = None,
        evidence_sources: Sequence[EvidenceSource] = (),
    ) -> None:
        self.embedding_dim = check_int("embedding_dim", embedding_dim, 1)
        self.body_evidence = body_evidence
        # the cues besides the face, in the order they decide (the body first)
        body: list[EvidenceSource] = [] if body_evidence is None else [BodyIdentification(body_evidence)]
        self.sources = Cues(body + list(evidence_sources))  # the cues besides the face, the body first
        self.lend_lost_faces = bool(lend_lost_faces)
        if feature_gate_distance is not None:
            feature_gate_distance = check_real("feature_gate_distance", feature_gate_distance, 0.0, math.inf,
                                               low_open=True, high_open=True)
        self.feature_gate_distance = feature_gate_distance
        half_gate = None if feature_gate_distance is None else 0.5 * feature_gate_distance
        self.alike_face_distance = half_gate if alike_face_distance is None else check_real(
            "alike_face_distance", alike_face_distance, 0.0, math.inf, low_open=True)
        self.release_after_inconsistent = check_int("release_after_inconsistent", release_after_inconsistent, 0)
        self.max_features_per_face = check_int("max_features_per_face", max_features_per_face, 1)
        self.exact_search_max_features = check_int("exact_search_max_features", exact_search_max_features, 0)
        self.shortlist_faces = check_int("shortlist_faces", shortlist_faces, 1)
        self._bank = FeatureBank(self.embedding_dim, self.max_features_per_face)
        self.stats = IdentityStats()
        self._swaps = SwapGuard(feature_gate_distance, self.release_after_inconsistent, self._bank, self.stats)
        self.faces = FaceList(self._bank, self.stats, self.exact_search_max_features, self.shortlist_faces,
                              self._on_face_available, self._on_faces_unavailable)
        self.tracks = TrackList()  # track_list: the live tracks, their queued observations and deaths
        self.crossings = Crossings(self.tracks)  # the doubt a possible tracker swap leaves on identities
        self.co_sightings = CoSightings(self.tracks, self.stats)  # two tracks seen at the same time are two people
        self._lent = LentFaces(self.faces, self.lend_lost_faces)
        self._side_events: list[IdentityEvent] = []  # lent faces taken from their LOST tracks this step

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
        checked = checked_observations(tid, embeddings, eye_px, source, self.embedding_dim)
        return checked is None or self.add_validated_observations(tid, checked[0], stamp, checked[1], source)

    def add_validated_observations(self, tid: int, emb: F32Array, stamp: float,
                                   eye_px: FloatArray | None = None, source: str = "") -> bool:
        """:meth:`add_observations` for input already validated (MasterCore checks each frame once):
        ``emb`` a finite C-contiguous float32 (K >= 1, embedding_dim) array, ``stamp`` finite seconds,
        ``eye_px`` None or (K,) float64, ``source`` a str."""
        if self.tracks.gone(tid):
            self.stats.observations_ignored_dead_track += emb.shape[0]
            return False
        self.tracks.queue(tid, Chunk(emb, eye_px, stamp, source))
        self.stats.observations_received += emb.shape[0]
        return True

    def add_body_observations(self, track_id: int, embeddings: F32Array, stamp_s: float, source: str = "",
                              heights: FloatArray | None = None) -> None:
        """Queue a track's body-appearance embeddings (k, r) (finite, validated by the caller) and head
        ``heights`` (k, m; None = unknown) seen by camera ``source`` for the next :meth:`step`; ignored
        without body evidence or for a deleted track."""
        self.add_cue_observations(Evidence.BODY, track_id, embeddings, stamp_s, source, heights)

    def add_cue_observations(self, kind: str, track_id: int, values: F32Array, stamp_s: float, source: str = "",
                             heights: FloatArray | None = None) -> None:
        """Queue observations (k, r) of cue ``kind`` (an evidence source's, validated by the caller) on a track,
        with head ``heights`` (k,; None = unknown) seen by camera ``source``, for the next :meth:`step`; ignored
        without that source or for a deleted track."""
        if kind not in self.sources.kinds or self.tracks.gone(track_id):
            return
        self.tracks.queue_cue(kind, track_id, CueChunk(values, stamp_s, source, heights))
        if kind == Evidence.BODY:
            self.stats.body_observations += values.shape[0]

    def track_deleted(self, track_id: int, stamp_s: float) -> None:
        """The tracker dropped this track; handled at the next :meth:`step` (after its last evidence)."""
        self.tracks.died(check_int("track_id", track_id, -(2**63)), check_stamp(stamp_s))

    def track_lost(self, track_id: int) -> None:
        """The tracker lost the track (no detection for a while): its face is lent to face_list
        (:mod:`~face_reid_master.identity.lent_faces`)."""
        self._lent.lend(self.tracks.entries.get(track_id))

    def track_recovered(self, track_id: int) -> None:
        """The LOST track was detected again: it takes its face back from face_list if nobody took it."""
        self._lent.give_back(self.tracks.entries.get(track_id))

    def _take_lent(self, fid: int, stamp: float) -> None:
        """Face ``fid`` goes to another track: a LOST track that lent it is no longer identified."""
        track = self._lent.take_holder(fid, self.tracks.entries)
        if track is None:
            return
        self._side_events.append(IdentityEvent(IdentityEventKind.RELEASED, track.track_id, fid, stamp,
                                               track.confidence))
        track.unassign()
        self.stats.lent_faces_taken += 1

    def step(self, stamp_s: float) -> list[IdentityEvent]:
        """Run one update of Algorithm 1: release the tracks a crossing made more likely someone else (their faces
        are free for whoever shows them), learn the queued observations, classify the unassigned tracks (by face,
        then by body), then handle deaths."""
        stamp = check_stamp(stamp_s)
        self.stats.steps += 1
        self.tracks.retired.clear()
        events = [self._release_swapped(track, stamp, stamp) for track in self.crossings.withheld()]
        for track in self.crossings.take_mixed():  # a stray more likely than not: its evidence was someone else's
            self._forget_evidence(track)
            self.stats.tracks_restarted += 1
        self._learn(stamp, events)
        self.co_sightings.note()
        for tid, face_or_new, confidence in self.co_sightings.allowed(self._decide()):
            events.append(self._apply_decision(tid, face_or_new, confidence, stamp))
        for source in self.sources:
            events.extend(self._cue_step(source, stamp))
        events.extend(self._side_events)
        self._side_events = []
        deaths, self.tracks.deaths = self.tracks.deaths, {}
        return events + [ev for tid, died in deaths.items() if (ev := self._remove_track(tid, died)) is not None]

    def _learn(self, stamp: float, events: list[IdentityEvent]) -> None:
        """The queued observations: an identified track's join its face (those its face accepts; a swap releases
        the track, :class:`SwapGuard`); an unassigned track's join its buffer and go to the classification."""
        pending = self.tracks.take_pending()
        unassigned: list[tuple[int, F32Array, FloatArray]] = []  # (track, its rows, their eye distances)
        singles: list[tuple[int, F32Array]] = []  # one new feature into a full feature set: batched
        rows = {tid: rows_of(chunks) for tid, chunks in pending.items()}
        near = self._swaps.consistent(rows, lambda tid: self.faces.slot(self.tracks.entries[tid].face_id))
        bank = self._bank
        for tid, chunks in pending.items():
            track = self.tracks.entries[tid]
            track.n_observations += rows[tid].shape[0]
            slot: int | None = None
            obs: F32Array | None = rows[tid]
            if track.face_id is not None:
                slot, chunks, obs = self._learn_identified(track, chunks, rows[tid], near.get(tid), stamp, events)
            if obs is None:
                continue
            if track.face_id is None:
                slot = track.slot
                if slot is None:
                    track.slot = bank.new_slot(obs)
                unassigned.append((tid, obs, eye_rows(chunks)))
            if slot is not None:
                if obs.shape[0] == 1 and bank.count[slot] == bank.kmax >= 2:
                    singles.append((slot, obs))
                else:
                    bank.add_features(slot, obs)
        if singles:
            bank.add_one_each(np.array([s for s, _ in singles], dtype=np.intp), np.concatenate([o for _, o in singles]))
        if unassigned:
            tids, observations, eyes = zip(*unassigned, strict=True)
            self._ingest_unassigned(list(tids), list(observations), list(eyes))

    def _learn_identified(self, track: TrackRecord, chunks: list[Chunk], obs: F32Array,
                          keep: npt.NDArray[np.bool_] | None, stamp: float, events: list[IdentityEvent]
                          ) -> tuple[int | None, list[Chunk], F32Array | None]:
        """An identified track's observations (``keep``: which its face accepts; None: all): its face's slot and
        the rows it learns (None: none), or, when they show a swap, the released track's chunks and rows."""
        assert track.face_id is not None
        face = self.faces.entries[track.face_id]
        face.n_observations += obs.shape[0]
        face.last_seen_s = max(face.last_seen_s, stamp)
        if keep is not None:
            swapped = self._swaps.swapped(track, chunks, keep)
            obs = obs if keep.all() else obs[keep]
            if swapped is not None:  # the face keeps what was its person's, then lets the track go
                if obs.shape[0] and track.teaches(self.learn_confidence):
                    self._bank.add_features(face.slot, obs)
                events.append(self._release_swapped(track, stamp, swapped[0].stamp_s))
                obs = rows_of(swapped)
                track.n_observations = obs.shape[0]
                return None, swapped, obs
            if obs.shape[0] == 0:
                return face.slot, chunks, None
        if not track.teaches(self.learn_confidence):
            self.stats.observations_not_learned_uncertain += obs.shape[0]
            return face.slot, chunks, None
        if track.evidence not in (Evidence.FACE, Evidence.BOTH) and obs.shape[0]:
            track.evidence = Evidence.BOTH  # its own face agrees with another cue's decision
        return face.slot, chunks, obs

    def _cue_step(self, source: EvidenceSource, stamp: float) -> list[IdentityEvent]:
        """One cue's observations: an identified track's describe its face's person (if its decision teaches); a
        faceless track is given one of face_list when its evidence against every learned face is strong enough."""
        queued, withheld = self.tracks.take_cue(source.kind, self.learn_confidence)
        self.stats.cue_observations_not_learned_uncertain += withheld
        source.observe(queued, list(self.faces.entries))
        events = []
        for tid, fid, p in self.co_sightings.allowed(source.decide(self.faces.available, stamp, self._faces_alike)):
            track = self.tracks.entries.get(tid)
            if track is not None and track.face_id is None and track.slot is None and fid in self.faces.available:
                events.append(self._apply_cue_decision(track, fid, p, stamp, source.kind))
        return events

    def _apply_cue_decision(self, track: TrackRecord, fid: int, confidence: float, stamp: float,
                            evidence: str) -> IdentityEvent:
        """A faceless track is face ``fid``'s person by another cue: it carries the face (no features to add)."""
        self._give_face(track, fid, confidence, stamp, evidence, new=False)
        if evidence == Evidence.BODY:
            self.stats.assigned_by_body += 1
        return IdentityEvent(IdentityEventKind.ASSIGNED_KNOWN, track.track_id, fid, stamp, float(confidence),
                             evidence=evidence)

    def _faces_alike(self, face: int, others: list[int]) -> list[bool]:
        """Which of ``others`` are learned ``face``'s person: closer than ``alike_face_distance``."""
        return self.faces.alike(face, others, self.alike_face_distance)

    # ------------------------------------------------------------------------------ queries
    def evidence_of(self, track_id: int) -> str:
        """What identified a live track (:class:`~.evidence.Evidence`: the face, a cue, both a cue and then its
        face), or "" (unidentified / unknown track)."""
        track = self.tracks.entries.get(track_id)
        return "" if track is None or track.face_id is None else str(track.evidence)  # plain str: published

    def decided_new(self, track_id: int) -> bool:
        """Whether a live identified track's decision created its face (False otherwise)."""
        track = self.tracks.entries.get(track_id)
        return track is not None and track.face_id is not None and track.new_face

    def face_id_of(self, track_id: int) -> int | None:
        """Face id assigned to a live track, or None while unidentified / unknown track."""
        track = self.tracks.entries.get(track_id)
        return None if track is None else track.face_id

    def confidence_of(self, track_id: int) -> float:
        """Current max posterior (Bayes) / leading vote fraction of an unassigned track; the decision
        confidence once assigned; 0.0 for an unknown track."""
        track = self.tracks.entries.get(track_id)
        if track is None or track.face_id is not None:
            return 0.0 if track is None else track.confidence
        return self._current_confidence(track)

    def posterior_of(self, track_id: int) -> dict[int, float]:
        """Hypotheses of an unassigned track: {0: new person, face_id: probability}; {} if none."""
        return {}

    def assigned_tracks(self) -> dict[int, int]:
        """Live track id -> face id for all identified tracks."""
        return {t.track_id: t.face_id for t in self.tracks.entries.values() if t.face_id is not None}

    def face_ids(self) -> list[int]:
        """All learned face ids (assigned or in face_list)."""
        return sorted(self.faces.entries)

    def forget_face(self, face_id: int) -> bool:
        """Remove a learned face entirely (privacy: "delete this person"); False if the id is unknown. It leaves
        face_list and the bank; a live track carrying it becomes unidentified (its queued observations, meant for it,
        are dropped) and is classified afresh, normally as a *new* face id. Face ids are never reused here."""
        fid = check_int("face_id", face_id, -(2**63))
        face = self.faces.entries.get(fid)
        if face is None:
            return False
        lender = self._lent.take_holder(fid, self.tracks.entries)
        if lender is not None:
            lender.face_id, lender.confidence = None, 0.0  # a LOST track lent it: it holds nothing now
        track = None if face.track_id is None else self.tracks.entries.get(face.track_id)
        if track is not None and track.face_id == fid:
            track.unassign()
            track.inconsistent.clear()
            self.tracks.drop_faces(track)
        self.faces.forget(fid)
        self.sources.forget_face(fid)
        self.stats.faces_forgotten += 1
        return True

    def eviction_order(self, exclude: Iterable[int] = ()) -> list[int]:
        """Unnamed faces of face_list no live or lost track holds, not in ``exclude``, least recently seen first."""
        return self.faces.eviction_order(set(exclude) | set(self._lent.lender))

    # ------------------------------------------------------------------------------ internals
    def _apply_decision(self, tid: int, face_or_new: int, confidence: float, stamp: float) -> IdentityEvent:
        """The classification decided an unassigned track: a new face from its buffered features (0) or a known
        face, which absorbs them."""
        track = self.tracks.entries[tid]
        assert track.slot is not None, "a track is only classified after observations"
        new = face_or_new == 0
        fid = self.faces.new_id() if new else face_or_new
        if new:  # the track's buffer becomes the new face's feature set
            self.faces.entries[fid] = FaceEntry(fid, track.slot, None, stamp, stamp, track.n_observations)
            self.stats.new_faces += 1
        self._give_face(track, fid, confidence, stamp, Evidence.FACE, new=new)
        if not new:  # the known face absorbs the buffer (add result.face_images) if the decision teaches it
            face = self.faces.entries[fid]
            if track.teaches(self.learn_confidence):
                self._bank.add_features(face.slot, self._bank.features(track.slot))
            else:
                self.stats.observations_not_learned_uncertain += int(self._bank.count[track.slot])
            self._bank.free_slot(track.slot)
            face.n_observations += track.n_observations
            self.stats.assigned_known += 1
        kind = IdentityEventKind.NEW_FACE if new else IdentityEventKind.ASSIGNED_KNOWN
        track.slot = None
        track.votes.clear()
        return IdentityEvent(kind, tid, fid, stamp, float(confidence))

    def _give_face(self, track: TrackRecord, fid: int, confidence: float, stamp: float, evidence: str,
                   new: bool) -> None:
        """The track carries face ``fid`` from now on (a known face leaves face_list, taken from a LOST track that
        lent it); the bodies it gathered join the face's gallery if the decision teaches, else they go."""
        face = self.faces.entries[fid]
        if not new:
            self._take_lent(fid, stamp)
            self.faces.make_unavailable([fid])
        face.track_id = track.track_id
        face.last_seen_s = max(face.last_seen_s, stamp)
        self._on_track_identified(track)
        track.give(fid, confidence, evidence, new)
        self.crossings.forget_all(track)  # decided on what it showed since
        self.sources.track_identified(track.track_id, fid, track.teaches(self.learn_confidence))

    def _release_swapped(self, track: TrackRecord, stamp: float, since: float) -> IdentityEvent:
        """Not its face's person any more: its face returns to face_list (a lent one is there), it is unassigned."""
        assert track.face_id is not None
        fid, confidence = track.face_id, track.confidence
        if self._lent.take(fid) is None:
            self.faces.make_available(fid)
        track.unassign()
        self.crossings.forget_strays(track)
        self.stats.swaps_released += 1
        return IdentityEvent(IdentityEventKind.SWAPPED, track.track_id, fid, stamp, confidence, since)

    def _forget_evidence(self, track: TrackRecord) -> None:
        """An unidentified track's evidence goes (its face buffer, classification row and cues' evidence)."""
        if track.slot is not None:
            self._bank.free_slot(track.slot)
            track.slot = None
        self._on_track_forgotten(track)
        self.sources.forget_track(track.track_id)
        track.unassign()

    def _remove_track(self, tid: int, stamp: float) -> IdentityEvent | None:
        self.sources.forget_track(tid)
        track = self.tracks.remove(tid, stamp)
        if track is None:
            return None
        track.crossed.clear()  # its partners keep their doubt: its end does not say whether they were swapped
        if track.face_id is None:
            self._forget_evidence(track)
            return None
        if not self._lent.returned(track.face_id, tid):  # a lent face is in face_list already
            self.faces.make_available(track.face_id)
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

    def _current_confidence(self, track: TrackRecord) -> float:
        """Confidence of an unassigned track's leading hypothesis, in [0, 1]."""
        raise NotImplementedError

    def _on_face_available(self, face_id: int) -> None:
        """A face joined face_list (appended as the last column)."""

    def _on_faces_unavailable(self, column_indices: list[int]) -> None:
        """Faces at these 0-based positions of face_list are leaving it."""

    def _on_track_identified(self, track: TrackRecord) -> None:
        """An unassigned track got a face id (its table row goes away)."""

    def _on_track_forgotten(self, track: TrackRecord) -> None:
        """An unassigned track died."""

