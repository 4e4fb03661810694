"""The master's pure core: camera frames in, named tracks out (no rclpy).

One :class:`MasterCore` owns the tracker, the face-identity manager (Algorithm 1, Bayesian or threshold), the
predefined-people matcher and the face memory. The node, the evaluation and the benchmarks all drive it the
same way:

    core.process_frame(CameraFrameRecord(...), now_s=...)   # per camera message
    core.tick(now_s)                                          # when no frames arrive (timeouts)
    core.tracks()                                             # -> list[NamedTrackRecord]

A frame goes through five steps (:meth:`MasterCore.process_frame`): admit (:mod:`.admission`), read its
people (:mod:`.detections`), track, observe (face and body evidence) and decide (one identity step, deferred
to :meth:`MasterCore.finish_frames` when a caller batches frames); :meth:`MasterCore.tracks` publishes. Bad
input never raises: it is rejected, counted in :class:`~.records.MasterStats` and reported in the
:class:`~.records.FrameOutcome`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.embedding_spaces import space_dim
from face_reid_master.body.metric_file import BodyMetricModel, default_body_metric
from face_reid_master.core.admission import FrameAdmission
from face_reid_master.core.config import MasterConfig
from face_reid_master.core.detections import DetectionReader, Detections, degenerate_rows
from face_reid_master.core.face_memory import FaceMemory
from face_reid_master.core.records import FrameOutcome, MasterStats, PublicId
from face_reid_master.core.static_clutter import StaticClutter
from face_reid_master.identity.algorithm1 import IdentityManagerBase
from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.confidence_map import ConfidenceMap, default_confidence_map
from face_reid_master.identity.evidence import EvidenceSource
from face_reid_master.identity.likelihood import LikelihoodModel
from face_reid_master.identity.methods import make_identity_manager
from face_reid_master.identity.predefined_people import PredefinedPeople
from face_reid_master.identity.records import IdentityEvent, IdentityEventKind
from face_reid_master.identity.size_likelihood import FaceLikelihood, default_face_likelihood
from face_reid_master.records import CameraFrameRecord, NamedTrackRecord
from face_reid_master.tracking.interface import MultiCameraTracker, TrackerId
from face_reid_master.tracking.records import FrameStatus, TrackState
from face_reid_master.tracking.tracker import Tracker

__all__ = ["MasterCore"]

def _derived(name: str, configured: float, derived: float | None) -> float:
    """A configured distance, or (0) the value derived for the embedder space; ValueError if there is none."""
    if configured > 0:
        return configured
    if derived is None:
        raise ValueError(f"{name} is 0 (= derived for the embedder space) but the likelihood file derives none: "
                         f"set {name} explicitly or refit with face-reid-fit-likelihood")
    return derived


def _face_likelihood(likelihood: LikelihoodModel | FaceLikelihood | None, space: str) -> FaceLikelihood:
    """The face likelihood of the master's embedder space (the shipped one when none is given)."""
    model = likelihood or default_face_likelihood(space)
    if isinstance(model, LikelihoodModel):
        model = FaceLikelihood(model, space)
    if model.space != space:
        raise ValueError(f"the likelihood model is fitted for embedder space {model.space!r} but "
                         f"embedding_space is {space!r}")
    return model


class MasterCore:
    """Tracking + face identities + names + persistence, frame by frame (see the module doc)."""

    def __init__(
        self,
        config: MasterConfig | None = None,
        likelihood: LikelihoodModel | FaceLikelihood | None = None,
        store: Any | None = None,
        gallery: Mapping[str, NDArray[np.floating]] | None = None,
        body_metric: BodyMetricModel | None = None,
        confidence_map: ConfidenceMap | None = None,
        tracker: MultiCameraTracker | None = None,
        evidence_sources: Sequence[EvidenceSource] = (),
    ) -> None:
        cfg = config or MasterConfig()
        if tracker is not None:  # an injected tracker's own configuration is the one read (admission, timeouts)
            cfg = dataclasses.replace(cfg, tracker=tracker.config)
        self.config = cfg
        # what a decision's raw posterior is worth, measured on development scenarios (the published confidence)
        self.confidence_map = confidence_map if confidence_map is not None else default_confidence_map()
        self.stats = MasterStats()
        self._notices: list[str] = []  # things the node should log once, handed out with the next FrameOutcome
        # judges every stamp once, against the tracker's clock (the project's tracker is given the gate's)
        self.admission = FrameAdmission(cfg, self.stats, tracker.clock if tracker is not None else None)
        self.tracker: MultiCameraTracker = (tracker if tracker is not None
                                            else Tracker(cfg.tracker, clock=self.admission.tracker_clock))
        if body_metric is None and cfg.body_appearance_tracking:
            body_metric = default_body_metric()
        self.body_metric = body_metric if cfg.body_appearance_tracking else None
        self.likelihood = model = _face_likelihood(likelihood, cfg.embedding_space)  # also the space's weights
        self.threshold_distance = _derived("threshold_distance", cfg.threshold_distance, model.threshold_distance) \
            if cfg.method == "threshold" else cfg.threshold_distance or model.threshold_distance
        # naming needs a threshold only once there are predefined people (add_person checks it too)
        self.name_threshold = _derived("name_threshold", cfg.name_threshold, model.name_threshold) \
            if gallery else cfg.name_threshold or model.name_threshold
        self.identity = self._identity_manager(model, evidence_sources)
        dim = space_dim(cfg.embedding_space)
        self.people = PredefinedPeople(
            {name: model.scale(np.asarray(rows, dtype=np.float32)) for name, rows in (gallery or {}).items()},
            name_threshold=self.name_threshold or 1.0, min_face_features=cfg.min_face_features_for_name,
            embedding_dim=dim,
        )
        self.reader = DetectionReader(cfg, self.stats, model, self.body_metric, self._notices)
        self.memory = FaceMemory(cfg, self.stats, self.identity, self.people, store, self._notices)
        self.clutter = StaticClutter(cfg.static_clutter_after_s, cfg.static_clutter_radius_m)
        self.static_clutter_tracks = 0  # tracks held back as static clutter at the last tracks() call
        # what the next identity step decides on beyond the identity layer's own queue: the newest stamp applied
        # since the last step (None: nothing waits) and the tracks given a face observation meanwhile
        self._undecided_stamp: float | None = None
        self._touched: set[int] = set()
        self._last_stamp = -math.inf

    def _identity_manager(self, model: FaceLikelihood, sources: Sequence[EvidenceSource]) -> IdentityManagerBase:
        """Algorithm 1 with the configured method (bayes: with body evidence where bodies are used) and the
        given further cues."""
        cfg = self.config
        dim = space_dim(cfg.embedding_space)
        if cfg.method == "threshold":
            return make_identity_manager(
                "threshold", distance_threshold=self.threshold_distance, n_votes=cfg.threshold_votes,
                max_features_per_face=cfg.max_features_per_face, embedding_dim=dim,
                feature_gate_distance=self.threshold_distance if cfg.learn_only_consistent_features else None,
                release_after_inconsistent=cfg.release_after_inconsistent, evidence_sources=sources,
            )
        body_evidence = None
        if self.body_metric is not None and cfg.body_identity:
            body_evidence = BodyEvidence(
                self.body_metric.features["fused"].likelihood, window_s=cfg.body_window_s,
                posterior_threshold=cfg.body_posterior_threshold, min_observations=cfg.body_min_observations,
                max_log_ratio=cfg.body_max_log_ratio,
                funnel_alpha=cfg.body_funnel_alpha, height_same_std_m=cfg.body_height_same_std_m,
                height_other_std_m=cfg.body_height_other_std_m)
        if cfg.new_person_scale_c != model.new_person_scale_c:
            model = model.with_new_person_scale(cfg.new_person_scale_c)
        return make_identity_manager(
            "bayes", likelihood=model, posterior_threshold=cfg.posterior_threshold,
            prior_probability=cfg.prior_probability, min_observations=cfg.min_observations,
            max_features_per_face=cfg.max_features_per_face, embedding_dim=dim,
            feature_gate_distance=model.decision_distance if cfg.learn_only_consistent_features else None,
            release_after_inconsistent=cfg.release_after_inconsistent, body_evidence=body_evidence,
            lend_lost_faces=cfg.lend_lost_faces, alike_face_distance=cfg.alike_face_distance or None,
            learn_confidence=cfg.learn_confidence, evidence_sources=sources,
        )

    @property
    def body_fused(self) -> Any:
        """The fused body metric bodies are embedded with (None: bodies are not used)."""
        return self.reader.body_fused

    # ------------------------------------------------------------------------------ the frame path
    def process_frame(self, frame: CameraFrameRecord, now_s: float | None = None, *,
                      defer_identity: bool = False) -> FrameOutcome:
        """Admit one camera frame, read its people, track them, observe their faces and bodies, and decide.

        ``now_s``: the caller's clock (live; None offline: stamps are the clock). ``defer_identity``: leave the
        identity step (and face saving) to :meth:`finish_frames`, which runs it once for every frame deferred:
        a node that applies several frames per cycle pays for one identity update, not one per frame."""
        admission = self.admission.admit(frame, now_s)
        if not admission.admitted:
            return FrameOutcome(False, admission.reason, admission.code)
        if admission.clock_went_back:
            assert now_s is not None
            self._restart_tracking(now_s)
        stamp = admission.stamp_s
        detections = self.reader.read(frame)
        update = self.tracker.update_frame(detections, stamp, frame.camera_id, admitted=admission.tracker)
        if update.status in (FrameStatus.REJECTED_LATE, FrameStatus.REJECTED_FUTURE):
            self.stats.frames_rejected_tracker_late += 1
            return FrameOutcome(False, f"tracker rejected the frame ({update.status.value})", "tracker_late")
        self.stats.frames_applied += 1
        self.stats.detections_rejected_position += len(update.rejected_detections)
        self.clutter.follow(update.associations, detections.positions, stamp)
        self._last_stamp = max(self._last_stamp, stamp)
        for a, b, p in update.swaps:
            self.identity.crossings.crossed(a, b, p, stamp)
        for a, p in update.strays:
            self.identity.crossings.strayed(a, p)
        self._observe(update.associations, detections, stamp, frame)
        self._track_events(update.deleted, stamp, update.lost, update.recovered)
        self._undecided_stamp = stamp if self._undecided_stamp is None else max(self._undecided_stamp, stamp)
        events = () if defer_identity else tuple(self.finish_frames())
        notices, self._notices[:] = tuple(self._notices), []
        return FrameOutcome(True, track_of_person={detections.person_index[det]: tid
                                                   for tid, det in update.associations},
                            tracks_created=tuple(update.created), tracks_deleted=tuple(update.deleted),
                            identity_events=events, notices=notices)

    def _restart_tracking(self, now_s: float) -> None:
        """The caller's clock went back: what is pending is decided, then the tracker starts afresh."""
        self.finish_frames()
        self._identity_step(self.tracker.reset(), now_s, (), ())
        self._last_stamp = -math.inf

    def _observe(self, associations: list[tuple[int, int]], detections: Detections, stamp: float,
                 frame: CameraFrameRecord) -> None:
        """The associated detections' faces, then each further cue's observations (the body, ...), as identity
        evidence (the tracks a face was added to are remembered for face saving after the identity step)."""
        camera_id = frame.camera_id
        for track_id, det in associations:
            face = detections.faces.get(det)
            if face is None:
                continue
            emb, eye_px = face
            if self.identity.add_validated_observations(track_id, emb[None, :], stamp, eye_px, camera_id):
                self.identity.tracks.entries[track_id].face_observations += 1
                self._touched.add(track_id)
                self.stats.embeddings_used += 1
        for source in self.identity.sources:
            for track_id, det in associations:
                values = source.read(frame.people[detections.person_index[det]], det, detections)
                if values is not None:
                    self.identity.add_cue_observations(source.kind, track_id, values, stamp, camera_id,
                                                       detections.heights[det: det + 1])

    def finish_frames(self) -> list[IdentityEvent]:
        """The identity step on what the frames applied since the last step queued (their track events were told
        as each frame was applied; one step at the newest stamp), then face saving; returns the identity events.
        A no-op when nothing waits (process_frame without ``defer_identity`` calls it itself)."""
        if self._undecided_stamp is None:
            return []
        stamp, touched = self._undecided_stamp, self._touched
        self._undecided_stamp, self._touched = None, set()
        events = self._identity_step((), stamp)
        for track_id in touched:
            fid = self.identity.face_id_of(track_id)
            if fid is not None:
                self.memory.learned(fid, stamp)
        self.memory.maintain(stamp)
        return events

    @property
    def identity_pending(self) -> bool:
        """True while frames applied with ``defer_identity`` wait for :meth:`finish_frames`."""
        return self._undecided_stamp is not None

    @property
    def time_s(self) -> float:
        """The tracker's time: the newest frame stamp applied (at most the caller's clock) or time advanced to by
        :meth:`tick`; -inf before either."""
        return self._last_stamp

    def tick(self, now_s: float) -> None:
        """Advance time without a frame (tracks time out, released faces are saved). ``now_s`` behind the
        caller's last clock (frame or tick) by more than max_detection_delay_s: the clock stepped back (e.g. a
        forward step corrected), tracking starts afresh instead of waiting for the old future."""
        self.finish_frames()
        if not math.isfinite(now_s):
            return
        if self.admission.clock_went_back(now_s):
            self._restart_tracking(now_s)
        if now_s <= self._last_stamp:
            return
        result = self.tracker.advance(now_s)
        self._last_stamp = now_s
        self._identity_step(result.deleted, now_s, result.lost, result.recovered)
        self.memory.maintain(now_s)

    # ------------------------------------------------------------------------------ decide
    def _track_events(self, deleted: Iterable[int], stamp: float, lost: Iterable[int] = (),
                      recovered: Iterable[int] = ()) -> None:
        """The tracker's lost / recovered / deleted tracks of one update, told to the identity layer (a deleted
        track's record goes at the next identity step, after its last evidence)."""
        for track_id in lost:
            self.identity.track_lost(track_id)
        for track_id in recovered:
            self.identity.track_recovered(track_id)
        for track_id in deleted:
            self.identity.track_deleted(track_id, stamp)
            self.clutter.forget(track_id)

    def _identity_step(self, deleted: Iterable[int], stamp: float, lost: Iterable[int] = (),
                       recovered: Iterable[int] = ()) -> list[IdentityEvent]:
        """One identity update after the given track events; returns its events with published track ids."""
        self._track_events(deleted, stamp, lost, recovered)
        kept = []
        for ev in self.identity.step(stamp):
            if ev.kind == IdentityEventKind.NEW_FACE and not self.memory.room_for(ev.face_id):
                continue  # not learned (its id not durable, or max_faces): the track stays unidentified
            public = self.public_id(ev.track_id)
            kept.append(ev if public == ev.track_id else dataclasses.replace(ev, track_id=public))
            if ev.kind == IdentityEventKind.NEW_FACE:
                self.stats.faces_created += 1
            elif ev.kind == IdentityEventKind.ASSIGNED_KNOWN:
                self.stats.faces_reidentified += 1
            elif ev.kind in (IdentityEventKind.RELEASED, IdentityEventKind.SWAPPED):
                self.stats.faces_released += 1
            self.memory.changed(ev.face_id)
            if ev.kind == IdentityEventKind.SWAPPED:
                self.stats.faces_released_swapped += 1
                self._split_track(ev.track_id, stamp)
        self.identity.tracks.retired.clear()  # the records of the tracks deleted at this step are read: they go
        return kept

    def _split_track(self, track_id: int, stamp: float) -> None:
        """A swapped track is someone else from now on: it is published under a new id, so that no consumer
        carries the person it was over to the one it has become (its old id ends here)."""
        track = self.identity.tracks.record(track_id)
        assert track is not None, "a SWAPPED event names a track of this step"
        track.public_id, track.public_since_s = self.tracker.reserve_id(), stamp
        track.face_observations = 0

    def public_id(self, track_id: TrackerId) -> PublicId:
        """The id a tracker track is published under: its own until a swap split it, then a new one per swap."""
        track = self.identity.tracks.record(track_id)
        return PublicId(track_id if track is None else track.public_id)

    def published_face_id(self, track_id: TrackerId) -> int:
        """The face id a track is published with: its face, or 0 while undecided or while a crossing makes its
        identity more likely wrong than right."""
        fid = self.identity.face_id_of(track_id)
        return 0 if fid is None or self.identity.crossings.withholds(track_id) else fid

    def published_confidence(self, track_id: int) -> float:
        """``identity_confidence`` of a track: a decided track's decision posterior through the confidence map
        (how often such decisions were right), times the chance that no crossing since swapped its person; 0 for an
        undecided track (it claims no face: its candidates' raw posteriors are the overconfident numbers the map
        exists to correct) and for one whose identity is withheld."""
        evidence = self.identity.evidence_of(track_id)
        doubt = self.identity.crossings.doubt_of(track_id)
        if not evidence or self.identity.crossings.withheld_at(doubt):
            return 0.0
        raw = float(self.identity.confidence_of(track_id))
        return float(self.confidence_map(evidence, raw, self.identity.decided_new(track_id))) * (1.0 - doubt)

    # ------------------------------------------------------------------------------ people and faces
    def add_person(self, name: str, embeddings: NDArray[np.floating]) -> None:
        """Add or replace a predefined person (gallery embeddings (k, dim) of the master's space) at run time."""
        _derived("name_threshold", self.config.name_threshold, self.likelihood.name_threshold)
        rows = np.asarray(embeddings, dtype=np.float32)
        if rows.ndim == 2 and rows.shape[0]:
            bad = np.flatnonzero(degenerate_rows(rows))
            if bad.size:
                raise ValueError(f"embedding(s) {bad[:10].tolist()} are degenerate (NaN / Inf, zero norm or all "
                                 "values equal): no face gives one; refused")
        self.people.set_person(name, self.likelihood.scale(rows))
        self.memory.refresh_names()

    def forget_person(self, name: str) -> bool:
        """Remove a predefined person (gallery) at run time; the faces named after them lose the name.
        True if there was one."""
        if name not in self.people.names():
            return False
        self.people.remove_person(name)
        self.memory.refresh_names()
        return True

    def forget_face(self, face_id: int) -> bool:
        """Delete a learned face everywhere (memory, names, store). True if it existed; ValueError for an id out
        of range."""
        return self.memory.forget_face(face_id)

    def face_name(self, face_id: int) -> str:
        """The name linked to a face (predefined match, else a stored name), or ''."""
        return self.memory.face_name(face_id)

    def flush(self) -> None:
        """Decide what is pending and write every face with unsaved features to the store (call at shutdown)."""
        self.finish_frames()
        self.memory.flush()

    # ------------------------------------------------------------------------------ publish
    def tracks(self, at_s: float | None = None) -> list[NamedTrackRecord]:
        """Current tracks with identities (confirmed and lost; tentative if configured), static clutter left
        out (:class:`~.static_clutter.StaticClutter`)."""
        out = []
        snaps = [s for s in self.tracker.snapshots(at_s, include_tentative=self.config.publish_tentative)
                 if s.state != TrackState.DELETED]
        records = self.identity.tracks.entries
        clutter = self.clutter.among(snaps, records)
        self.static_clutter_tracks = len(clutter)
        for snap in snaps:
            if snap.track_id in clutter:
                continue
            fid = self.published_face_id(snap.track_id)
            track = records.get(snap.track_id)
            since = None if track is None else track.public_since_s
            out.append(
                NamedTrackRecord(
                    track_id=self.public_id(snap.track_id),
                    face_id=fid,
                    name=self.face_name(fid) if fid else "",
                    identity_confidence=self.published_confidence(snap.track_id),
                    identity_evidence=self.identity.evidence_of(snap.track_id) if fid else "",
                    face_observations=0 if track is None else track.face_observations,
                    position_xy=snap.position_xy,
                    velocity_xy=snap.velocity_xy,
                    covariance=snap.covariance,
                    height_m=float(snap.height_m),
                    state=int(snap.state),
                    first_seen_s=float(snap.created_s if since is None else since),
                    last_seen_s=float(snap.last_seen_s),
                    cameras=tuple(sorted(snap.cameras)),
                )
            )
        return out
