"""The master's pure core: camera frames in, named tracks out (no rclpy).

One :class:`MasterCore` owns the tracker, the face-identity manager (Algorithm 1, Bayesian or
threshold), the predefined-people matcher and (optionally) the persistent face store. The node,
the evaluation and the benchmarks all drive it the same way:

    core.process_frame(CameraFrameRecord(...), now_s=...)   # per camera message
    core.tick(now_s)                                          # when no frames arrive (timeouts)
    core.tracks()                                             # -> list[NamedTrackRecord]

Bad input never raises: malformed frames and detections are rejected, counted in
:class:`MasterStats` and reported in the returned :class:`FrameOutcome`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import check_real, is_finite_number, shown
from face_reid_camera.common.embedding_spaces import (
    DLIB_SPACE,
    EMBEDDER_CHOICES,
    SFACE_SPACE,
    embedder_space,
    extract_space,
    plausible_norms,
    space_dim,
)
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.body.metric_file import BodyMetricModel, default_body_metric
from face_reid_master.identity.algorithm1 import IdentityManagerBase
from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.confidence_map import ConfidenceMap, default_confidence_map
from face_reid_master.identity.likelihood import LikelihoodModel
from face_reid_master.identity.methods import make_identity_manager
from face_reid_master.identity.predefined_people import PredefinedPeople
from face_reid_master.identity.records import IdentityEventKind, LearnedFace, check_face_id
from face_reid_master.identity.size_likelihood import FaceLikelihood, default_face_likelihood
from face_reid_master.records import CameraFrameRecord, NamedTrackRecord
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import FrameStatus, TrackState
from face_reid_master.tracking.tracker import Tracker

_SPACE_CHOICES = tuple(embedder_space(choice) for choice in EMBEDDER_CHOICES)


def _derived(name: str, configured: float, derived: float | None) -> float:
    """A configured distance, or (0) the value derived for the embedder space; ValueError if there is none."""
    if configured > 0:
        return configured
    if derived is None:
        raise ValueError(f"{name} is 0 (= derived for the embedder space) but the likelihood file derives none: "
                         f"set {name} explicitly or refit with face-reid-fit-likelihood")
    return derived


def _constant_rows(rows: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Finite rows (k, dim) whose values are all equal (all zero included): no embedder produces them."""
    return np.ptp(rows, axis=1) <= 1e-6 * np.abs(rows).max(axis=1)


def degenerate_rows(rows: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Rows (k, dim) no embedder produces: a NaN / Inf, or all values equal (zero norm, a constant vector): such a
    vector is as near to every face as to any other, so it would match, or teach, anyone."""
    rows = np.asarray(rows)
    if not rows.shape[1]:
        return np.ones(len(rows), dtype=bool)
    finite = np.isfinite(rows).all(axis=1)
    return ~finite | _constant_rows(np.where(finite[:, None], rows, 0.0))


def _power_of_ten(n: int) -> bool:
    """1, 10, 100, ...: when a counter is worth a log line (floods stay quiet)."""
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1


@dataclass(frozen=True)
class MasterConfig:
    """Parameters of the master core (units in the names).

    ``known_camera_ids``: accepted camera ids (empty = any). ``max_stamp_age_s`` /
    ``max_stamp_future_s``: frames older / newer than this relative to ``now_s`` (when the caller
    passes one) are rejected as stale / from the future. ``min_face_quality``: embeddings of lower
    quality are not used for identity. ``save_interval_s``: how often faces that learned new
    features are written to the store (new faces and re-identifications are written at once).
    ``name_update_interval_s``: how often a live face's predefined-name match is re-evaluated.
    ``learn_only_consistent_features``: an identified track's embedding joins its face only within the
    decision distance (bayes: where N_p = N_n; threshold: ``threshold_distance``), so a track the tracker
    swapped onto another person does not teach the face that person (our extension; False = the paper).
    """

    method: str = param("bayes", "Face classification: 'bayes' (the paper's table) or 'threshold' (baseline).",
                        choices=("bayes", "threshold"))
    embedding_space: str = param(
        DLIB_SPACE + "+" + SFACE_SPACE, "Embedder space compared for identity: dlib_resnet_v1, sface_2021dec or "
        "dlib_resnet_v1+sface_2021dec (cameras must send it, or a joint space containing it; other "
        "embeddings are not used, logged once per camera).", choices=_SPACE_CHOICES, read_only=True)
    known_camera_ids: tuple[str, ...] = ()
    max_stamp_age_s: float = param(10.0, "Frames older than this vs the master clock are rejected (s).",
                                   low=0.0, high=86400.0)
    max_stamp_future_s: float = param(2.0, "Frames newer than this vs the clock are rejected (s).",
                                      low=0.0, high=86400.0)
    max_people_per_frame: int = param(
        200, "Frames with more people are rejected whole (count; a camera sees a few dozen at most).", low=1,
        high=100000)
    max_camera_rate_hz: float = param(
        100.0, "Frames of one camera beyond this many in one second are rejected (Hz; cameras send <= 30-60).",
        low=1.0, high=100000.0)
    min_face_quality: float = param(0.0, "Embeddings with lower face quality are ignored (0..1).", low=0.0, high=1.0)
    publish_tentative: bool = param(False, "Also publish tracks not confirmed yet (bool).")
    static_clutter_after_s: float = param(
        60.0, "A track that has not moved more than static_clutter_radius_m from where it appeared and never "
        "showed a face is static clutter (a coat stand, a pillar) after this long: not published (s; 0 = off).",
        low=0.0, high=86400.0)
    static_clutter_radius_m: float = param(
        0.4, "How far a track must move from where it appeared to count as a person who moved (m).",
        low=0.01, high=10.0)
    save_interval_s: float = param(1.0, "Faces with new embeddings are saved at least this often (s; a kill -9 "
                                   "loses at most this much learning).",
                                   low=0.0, high=86400.0)
    name_update_interval_s: float = 0.5
    prune_interval_s: float = 60.0
    # identity (Bayesian)
    posterior_threshold: float = param(0.95, "Assign a face when its posterior exceeds this (0.5..1).",
                                       low=0.5, high=0.999, high_open=True)
    prior_probability: float = param(0.1, "Prior of a new cell of the face table (0..1).",
                                     low=0.0, high=1.0, low_open=True, high_open=True)
    min_observations: int = param(3, "Face observations needed before a decision (count).", low=1, high=1000)
    new_person_scale_c: float = param(1.0, "The paper's c: larger = readier to call a face new.",
                                      low=0.0, high=1e6, low_open=True)
    max_features_per_face: int = param(50, "Embeddings kept per face, a diverse subset (count).", low=1, high=10000)
    max_faces: int = param(
        3000, "Learned faces kept at most: a new face beyond it evicts the least recently seen unnamed face not on a "
        "track (named faces never; when none can go, the new face is not learned, counted in faces_refused_cap). "
        "Bounds memory, disk and start-up time (~0.1 MB of memory per face of 50 features; count).",
        low=1, high=1_000_000)
    learn_only_consistent_features: bool = param(
        True, "An identified track's embedding joins its face only if within the decision distance (guards "
        "faces against tracker swaps; false = the paper).")
    release_after_inconsistent: int = param(
        3, "An identified track whose last this many face embeddings were all beyond the decision distance "
        "was swapped onto someone else: it loses its face and goes on under a new track id, undecided (count; "
        "0 = never, the paper; needs learn_only_consistent_features).", low=0, high=1000)
    lend_lost_faces: bool = param(
        True, "The face of a track the tracker lost (tracker.lost_after_s) may be given to another track before "
        "the lost one is deleted: the person came back as a new track (false = the paper: held until deleted).")
    # identity (threshold baseline)
    threshold_distance: float = param(
        0.0, "Threshold method: same face below this L2 distance (0 = the value derived for embedding_space, "
        "in its likelihood file).", low=0.0, high=4.0)
    threshold_votes: int = param(5, "Threshold method: observations per majority vote (count).", low=1, high=1000)
    # predefined people
    name_threshold: float = param(
        0.0, "A face gets a predefined name below this L2 distance (0 = the value derived for embedding_space, "
        "in its likelihood file).", low=0.0, high=4.0)
    min_face_features_for_name: int = param(5, "Embeddings a face needs before naming.", low=1, high=10000)
    # bodies
    body_appearance_tracking: bool = param(
        True, "Associate detections to tracks by body appearance too (the body metric's space; cameras without "
        "bodies are tracked by position alone, as before).")
    body_identity: bool = param(
        True, "A track that shows no face may be identified by its body: matched to the recent bodies of the "
        "learned faces (needs body_appearance_tracking; bayes method only).")
    body_window_s: float = param(
        3600.0, "A face's body evidence expires after this (s): clothes change, faces do not.", low=0.0,
        high=1e7, low_open=True)
    body_posterior_threshold: float = param(
        0.999, "A faceless track gets a face when its body posterior exceeds this (0.5..1).", low=0.5, high=1.0,
        low_open=True, high_open=True)
    body_max_log_ratio: float = param(
        0.25, "Bound of one body observation's evidence, in log odds (frames of one glance are far from "
        "independent).", low=0.0, high=10.0, low_open=True)
    body_min_observations: int = param(
        6, "Body observations compared with a face before a body decision (count).", low=1, high=100000)
    body_alike_face_distance: float = param(
        0.0, "Two learned faces whose features are closer than this face-embedding distance count as one person "
        "in a body decision (a second face learned while another track held the first); 0 = half the face "
        "decision distance.", low=0.0, high=4.0)
    body_funnel_alpha: float = param(
        1.5, "Funnel: a face whose recent bodies are farther than this times the nearest face's is abandoned "
        "for that observation (> 1).", low=1.0, high=100.0, low_open=True)
    body_height_same_std_m: float = param(
        0.05, "Spread of one person's head height around their face's recent median (m).", low=0.0, high=1.0,
        low_open=True)
    body_height_other_std_m: float = param(
        0.12, "Spread of another person's head height around a face's recent median (m; > the same-person "
        "spread).", low=0.0, high=2.0, low_open=True)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self) -> None:
        validate_fields(self)
        if self.release_after_inconsistent and not self.learn_only_consistent_features:
            raise ValueError("release_after_inconsistent needs learn_only_consistent_features (it counts the "
                             "embeddings beyond the decision distance): set it to 0 for the paper's behaviour")
        for name in ("name_update_interval_s", "prune_interval_s"):
            check_real(name, getattr(self, name), 0.0)


@dataclass
class MasterStats:
    """Counters of everything the core accepted, rejected or decided (logged by the node)."""

    frames_received: int = 0
    frames_applied: int = 0
    frames_rejected_unknown_camera: int = 0
    frames_rejected_stale: int = 0
    frames_rejected_future: int = 0
    frames_rejected_bad_stamp: int = 0
    frames_rejected_tracker_late: int = 0
    frames_rejected_too_many_people: int = 0
    frames_rejected_camera_rate: int = 0
    frames_future_clamped: int = 0  # stamped ahead of the master's clock (within max_stamp_future_s): applied at it
    clock_jumps_back: int = 0  # the master's own clock went back: the tracker started afresh
    detections_received: int = 0
    detections_rejected_position: int = 0
    embeddings_used: int = 0
    embeddings_rejected_length: int = 0
    embeddings_rejected_space: int = 0
    embeddings_rejected_nonfinite: int = 0
    embeddings_rejected_norm: int = 0  # lengths no embedder of the space produces
    embeddings_skipped_quality: int = 0
    bodies_received: int = 0  # detections with well-formed body fields
    bodies_rejected_malformed: int = 0  # body fields with NaN / Inf appearance or out-of-range visibility
    bodies_rejected_space: int = 0  # descriptors of another projection than the body metric's
    faces_created: int = 0
    faces_reidentified: int = 0
    faces_released: int = 0
    faces_released_swapped: int = 0  # of which: the track was swapped onto someone else (published under a new id)
    faces_pruned: int = 0
    faces_evicted: int = 0  # unnamed faces forgotten to keep max_faces (least recently seen first)
    faces_refused_cap: int = 0  # new faces not learned: max_faces reached and every face named or on a track
    embeddings_rejected_degenerate: int = 0  # constant rows (all zero, ...): no embedder produces them
    store_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class FrameOutcome:
    """What :meth:`MasterCore.process_frame` did with one frame (``reason`` and its short ``code``, e.g.
    ``stale_stamp``, when rejected: the node counts rejections by code)."""

    accepted: bool
    reason: str = ""
    code: str = ""
    track_of_person: dict[int, int] = field(default_factory=dict)  # index in frame.people -> tracker id (public_id)
    tracks_created: tuple[int, ...] = ()
    tracks_deleted: tuple[int, ...] = ()
    identity_events: tuple[Any, ...] = ()
    notices: tuple[str, ...] = ()  # things the node should log once (e.g. a camera of another embedder space)


class FaceStoreLike:
    """The persistence interface the core needs (satisfied by face_store.FaceStore)."""

    def save_face(self, face: LearnedFace) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def load_faces(self) -> list[LearnedFace]:  # pragma: no cover - interface
        raise NotImplementedError

    def forget(self, face_id: int) -> bool:  # pragma: no cover - interface
        raise NotImplementedError


_MAX_NOTICED_CAMERAS = 1024  # cameras whose unusable spaces are remembered (hostile ids cannot grow it)


def _first_notice(seen: dict[str, str], camera_id: str, space: str) -> bool:
    """True the first time ``camera_id`` sends ``space`` (cut to 64 characters); remembers at most
    _MAX_NOTICED_CAMERAS cameras, the least recently noticed forgotten first."""
    camera_id, space = camera_id[:256], space[:64]
    if seen.get(camera_id) == space:
        return False
    seen.pop(camera_id, None)
    seen[camera_id] = space
    while len(seen) > _MAX_NOTICED_CAMERAS:
        del seen[next(iter(seen))]
    return True


class MasterCore:
    """Tracking + face identities + names + persistence, frame by frame."""

    def __init__(
        self,
        config: MasterConfig | None = None,
        likelihood: LikelihoodModel | FaceLikelihood | None = None,
        store: Any | None = None,
        gallery: Mapping[str, NDArray[np.floating]] | None = None,
        body_metric: BodyMetricModel | None = None,
        confidence_map: ConfidenceMap | None = None,
    ) -> None:
        self.config = config or MasterConfig()
        # what a decision's raw posterior is worth, measured on development scenarios (the published confidence)
        self.confidence_map = confidence_map if confidence_map is not None else default_confidence_map()
        cfg = self.config
        self.tracker = Tracker(cfg.tracker)
        if body_metric is None and cfg.body_appearance_tracking:
            body_metric = default_body_metric()
        self.body_metric = body_metric if cfg.body_appearance_tracking else None
        # the fused metric bodies are embedded with
        self.body_fused = None if self.body_metric is None else self.body_metric.features["fused"]
        self._body_space_noticed: dict[str, str] = {}  # camera id -> the unusable body space it was logged for
        model = likelihood or default_face_likelihood(cfg.embedding_space)
        if isinstance(model, LikelihoodModel):
            model = FaceLikelihood(model, cfg.embedding_space)
        if model.space != cfg.embedding_space:
            raise ValueError(f"the likelihood model is fitted for embedder space {model.space!r} but "
                             f"embedding_space is {cfg.embedding_space!r}")
        self._dim = dim = space_dim(cfg.embedding_space)
        self.likelihood = model  # also gives the joint-space weights and the space's derived thresholds
        self.threshold_distance = _derived("threshold_distance", cfg.threshold_distance, model.threshold_distance) \
            if cfg.method == "threshold" else cfg.threshold_distance or model.threshold_distance
        # naming needs a threshold only once there are predefined people (add_person checks it too)
        self.name_threshold = _derived("name_threshold", cfg.name_threshold, model.name_threshold) \
            if gallery else cfg.name_threshold or model.name_threshold
        body_evidence = None
        if self.body_metric is not None and cfg.body_identity and cfg.method == "bayes":
            body_evidence = BodyEvidence(
                self.body_metric.features["fused"].likelihood, window_s=cfg.body_window_s,
                posterior_threshold=cfg.body_posterior_threshold, min_observations=cfg.body_min_observations,
                max_log_ratio=cfg.body_max_log_ratio,
                funnel_alpha=cfg.body_funnel_alpha, height_same_std_m=cfg.body_height_same_std_m,
                height_other_std_m=cfg.body_height_other_std_m,
                alike_face_distance=cfg.body_alike_face_distance or None)
        if cfg.method == "bayes":
            if cfg.new_person_scale_c != model.new_person_scale_c:
                model = model.with_new_person_scale(cfg.new_person_scale_c)
            self.identity: IdentityManagerBase = make_identity_manager(
                "bayes", likelihood=model, posterior_threshold=cfg.posterior_threshold,
                prior_probability=cfg.prior_probability, min_observations=cfg.min_observations,
                max_features_per_face=cfg.max_features_per_face, embedding_dim=dim,
                feature_gate_distance=model.decision_distance if cfg.learn_only_consistent_features else None,
                release_after_inconsistent=cfg.release_after_inconsistent, body_evidence=body_evidence,
                lend_lost_faces=cfg.lend_lost_faces,
            )
        else:
            self.identity = make_identity_manager(
                "threshold", distance_threshold=self.threshold_distance, n_votes=cfg.threshold_votes,
                max_features_per_face=cfg.max_features_per_face, embedding_dim=dim,
                feature_gate_distance=self.threshold_distance if cfg.learn_only_consistent_features else None,
                release_after_inconsistent=cfg.release_after_inconsistent,
            )
        self.people = PredefinedPeople(
            {name: model.scale(np.asarray(rows, dtype=np.float32)) for name, rows in (gallery or {}).items()},
            name_threshold=self.name_threshold or 1.0, min_face_features=cfg.min_face_features_for_name,
            embedding_dim=dim,
        )
        self.store = store
        self.stats = MasterStats()
        self._space_noticed: dict[str, str] = {}  # camera id -> the unusable space it was last logged for
        self._notices: list[str] = []
        self._face_obs: dict[int, int] = {}  # track id -> face embeddings observed (since its last split)
        self._split: dict[int, tuple[int, float]] = {}  # tracker id -> (published id, since s) after a swap
        self._gone: list[int] = []  # tracks deleted since the last identity step (their split ids go after it)
        self._birth: dict[int, tuple[float, float, float]] = {}  # track id -> (x, y, created s) until it moves
        self._moved: set[int] = set()  # tracks that moved away from where they appeared
        self.static_clutter_tracks = 0  # tracks held back as static clutter at the last tracks() call
        self._dirty_faces: dict[int, float] = {}  # face id -> first unsaved change (s)
        self._write_failures_seen = 0  # background save failures already counted in stats.store_errors
        # frames applied with defer_identity: (deleted, stamp, lost, recovered, tracks given a face observation)
        self._deferred: list[tuple[tuple[int, ...], float, tuple[int, ...], tuple[int, ...], set[int]]] = []
        self._name_checked: dict[int, float] = {}  # face id -> last name evaluation (s)
        self._names: dict[int, str] = {}  # face id -> name from the predefined people
        self._last_stamp = -math.inf
        self._last_now_s = -math.inf  # the caller's clock at the last frame (live)
        self._camera_frames: dict[str, deque[float]] = {}  # camera -> its frames' times in the last second
        self._last_prune_s = -math.inf
        if store is not None:
            faces = self._cap_loaded(store.load_faces())
            self.identity.import_faces(faces)
            self.identity.reserve_face_ids(int(store.max_face_id()))
            for face in faces:
                self._refresh_name(face.face_id, face.features)

    # ------------------------------------------------------------------------------ input
    def process_frame(self, frame: CameraFrameRecord, now_s: float | None = None, *,
                      defer_identity: bool = False) -> FrameOutcome:
        """Validate one camera frame, track its people and update face identities.

        ``defer_identity``: queue the frame's face evidence and track events and leave the identity update
        (and face saving) to :meth:`finish_frames`, which runs it once for every frame deferred: a node that
        applies several frames per cycle pays for one identity update, not one per frame."""
        cfg, st = self.config, self.stats
        st.frames_received += 1
        stamp = float(frame.stamp_s) if isinstance(frame.stamp_s, int | float) else math.nan
        if not math.isfinite(stamp):
            st.frames_rejected_bad_stamp += 1
            return FrameOutcome(False, "stamp is not a finite number", "bad_stamp")
        if cfg.known_camera_ids and frame.camera_id not in cfg.known_camera_ids:
            st.frames_rejected_unknown_camera += 1
            return FrameOutcome(False, f"unknown camera id {shown(frame.camera_id, 64)}", "unknown_camera")
        if not isinstance(frame.camera_id, str) or not frame.camera_id:
            st.frames_rejected_unknown_camera += 1
            return FrameOutcome(False, "empty camera id" if frame.camera_id == "" else "camera id is not a str",
                                "unknown_camera")
        if len(frame.people) > cfg.max_people_per_frame:
            st.frames_rejected_too_many_people += 1
            return FrameOutcome(False, f"{len(frame.people)} people in one frame (> max_people_per_frame)",
                                "too_many_people")
        if not self._camera_rate_ok(frame.camera_id, stamp if now_s is None else now_s):
            st.frames_rejected_camera_rate += 1
            return FrameOutcome(False, f"camera sends more than {cfg.max_camera_rate_hz:g} frames/s", "camera_rate")
        if now_s is not None:
            if stamp < now_s - cfg.max_stamp_age_s:
                st.frames_rejected_stale += 1
                return FrameOutcome(False, f"stamp {now_s - stamp:.2f} s in the past (> max_stamp_age_s)",
                                    "stale_stamp")
            if stamp > now_s + cfg.max_stamp_future_s:
                st.frames_rejected_future += 1
                return FrameOutcome(False, f"stamp {stamp - now_s:.2f} s in the future (> max_stamp_future_s)",
                                    "future_stamp")
            if now_s < self._last_now_s - self.config.tracker.max_detection_delay_s:  # our own clock went back
                st.clock_jumps_back += 1
                self.finish_frames()
                self._identity_step(self.tracker.reset(), now_s, (), ())
                self._last_stamp = -math.inf
            self._last_now_s = now_s
            if stamp > now_s:  # no camera moves the tracker clock past the master's: others' frames stay on time
                st.frames_future_clamped += 1
                stamp = now_s

        positions, stds, heights, appearance, embeddings, person_index = self._detections(frame)
        result = self.tracker.update_arrays(positions, stds, heights, stamp, frame.camera_id, appearance,
                                            resync_backward=now_s is None)
        if result.status in (FrameStatus.REJECTED_LATE, FrameStatus.REJECTED_FUTURE):
            st.frames_rejected_tracker_late += 1
            return FrameOutcome(False, f"tracker rejected the frame ({result.status.value})", "tracker_late")
        st.frames_applied += 1
        st.detections_rejected_position += len(result.rejected_detections)
        if self.config.static_clutter_after_s:
            self._follow_births(result.associations, positions, stamp)
        self._last_stamp = max(self._last_stamp, stamp)

        touched_tracks: set[int] = set()
        for track_id, det_index in result.associations:
            face = embeddings.get(det_index)
            if face is None:
                continue
            emb, eye_px = face
            if self.identity.add_validated_observations(track_id, emb[None, :], stamp, eye_px,  # validated above
                                                        frame.camera_id):
                self._face_obs[track_id] = self._face_obs.get(track_id, 0) + 1
                touched_tracks.add(track_id)
                st.embeddings_used += 1
        if appearance is not None and self.identity.body_evidence is not None:
            for track_id, det_index in result.associations:
                row = appearance[det_index]
                if np.isfinite(row[0]):  # a described body of the metric's space (NaN rows: none)
                    self.identity.add_body_observations(track_id, row[None, :], stamp, frame.camera_id,
                                                        heights[det_index: det_index + 1])
        self._deferred.append((result.deleted, stamp, result.lost, result.recovered, touched_tracks))
        events = () if defer_identity else tuple(self.finish_frames())
        track_of_person = {person_index[det]: tid for tid, det in result.associations}
        notices, self._notices = tuple(self._notices), []
        return FrameOutcome(True, track_of_person=track_of_person, tracks_created=tuple(result.created),
                            tracks_deleted=tuple(result.deleted), identity_events=events, notices=notices)

    def finish_frames(self) -> list[Any]:
        """The identity update of the frames applied since the last call (one step at the newest stamp, after
        their track events in order), then face saving; returns the identity events. A no-op when nothing
        waits (process_frame without ``defer_identity`` calls it itself)."""
        if not self._deferred:
            return []
        deferred, self._deferred = self._deferred, []
        for deleted, stamp, lost, recovered, _ in deferred[:-1]:
            self._track_events(deleted, stamp, lost, recovered)
        deleted, _, lost, recovered, _ = deferred[-1]
        stamp = max(d[1] for d in deferred)
        events = self._identity_step(deleted, stamp, lost, recovered)
        for *_, touched_tracks in deferred:
            for track_id in touched_tracks:
                fid = self.identity.face_id_of(track_id)
                if fid is not None:
                    self._dirty_faces.setdefault(fid, stamp)
        self._maintain_faces(stamp)
        return events

    def _camera_rate_ok(self, camera_id: str, now_s: float) -> bool:
        """Whether the camera sent fewer than ``max_camera_rate_hz`` frames in the second before ``now_s``
        (then this one is counted); at most 1024 cameras are remembered (the least recent go first)."""
        times = self._camera_frames.get(camera_id)
        if times is None:
            if len(self._camera_frames) >= 1024:
                oldest = min(self._camera_frames, key=lambda c: self._camera_frames[c][-1])  # never empty
                del self._camera_frames[oldest]
            times = self._camera_frames[camera_id] = deque()
        while times and (times[0] <= now_s - 1.0 or times[0] > now_s + 1.0):
            times.popleft()
        if len(times) >= self.config.max_camera_rate_hz:
            return False
        times.append(now_s)
        return True

    @property
    def time_s(self) -> float:
        """The tracker's time: the newest frame stamp applied (at most the caller's clock) or time advanced to by
        :meth:`tick`; -inf before either."""
        return self._last_stamp

    def tick(self, now_s: float) -> None:
        """Advance time without a frame (tracks time out, released faces are saved)."""
        self.finish_frames()
        if not math.isfinite(now_s) or now_s <= self._last_stamp:
            return
        result = self.tracker.advance(now_s)
        self._last_stamp = now_s
        self._identity_step(result.deleted, now_s, result.lost, result.recovered)
        self._maintain_faces(now_s)

    def _detections(
        self, frame: CameraFrameRecord
    ) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float32] | None,
        dict[int, tuple[NDArray[np.float32], NDArray[np.float64]]], list[int]
    ]:
        """The frame's valid detections as tracker input (positions (N, 2), stds (N,), heights (N,), body
        appearance embeddings (N, r) with NaN rows for undescribed bodies, or None), their usable face
        embeddings (with the face's eye distance, px; 0 = unknown) by detection index, and detection ->
        person index.

        This is the one place a frame's people are validated (the tracker and the face table are handed
        checked values), in one vectorised pass: it runs for every person of every camera frame.
        """
        cfg, st = self.config, self.stats
        people = frame.people
        n = len(people)
        st.detections_received += n
        if n == 0:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0), None, {}, []
        xy = np.full((n, 2), np.nan)
        std = np.full(n, np.nan)
        for i, person in enumerate(people):
            pos = np.asarray(person.position_world, dtype=np.float64).reshape(-1)
            if pos.size >= 2:
                xy[i] = pos[:2]
            std[i] = person.position_std_m
        valid = np.isfinite(xy).all(axis=1) & np.isfinite(std) & (std > 0)
        st.detections_rejected_position += int(n - np.count_nonzero(valid))
        person_index = np.flatnonzero(valid).tolist()
        tracker_input = (
            xy[valid],
            std[valid],
            np.array([float(people[i].height_m) for i in person_index], dtype=np.float64),
            self._appearance([people[i].body for i in person_index], frame.camera_id),
        )
        with_face = [
            (k, i) for k, i in enumerate(person_index)
            if people[i].embedding is not None and np.size(people[i].embedding) > 0
        ]
        embeddings: dict[int, tuple[NDArray[np.float32], NDArray[np.float64]]] = {}
        if not with_face:
            return *tracker_input, embeddings, person_index
        vectors = [(k, i, self._in_space(people[i], frame.camera_id)) for k, i in with_face]
        in_space = [(k, i, v) for k, i, v in vectors if v is not None]
        st.embeddings_rejected_space += len(vectors) - len(in_space)
        good_len = [(k, i, v) for k, i, v in in_space if v.size == self._dim]
        st.embeddings_rejected_length += len(in_space) - len(good_len)
        if not good_len:
            return *tracker_input, embeddings, person_index
        stacked = np.array([v for _, _, v in good_len])  # same-length rows (checked above)
        finite = np.isfinite(stacked).all(axis=1)
        plausible = finite & plausible_norms(stacked, cfg.embedding_space)  # NaN / Inf lengths fail the range
        st.embeddings_rejected_norm += int(np.count_nonzero(finite & ~plausible))
        with np.errstate(invalid="ignore"):  # NaN rows are not plausible already
            constant = plausible & _constant_rows(stacked)
        st.embeddings_rejected_degenerate += int(np.count_nonzero(constant))
        plausible &= ~constant
        stacked = self.likelihood.scale(stacked)
        quality = np.array([people[i].face_quality for _, i, _ in good_len], dtype=np.float64)
        good_quality = quality >= cfg.min_face_quality
        st.embeddings_rejected_nonfinite += int(np.count_nonzero(~finite))
        st.embeddings_skipped_quality += int(np.count_nonzero(plausible & ~good_quality))
        for row in np.flatnonzero(plausible & good_quality):
            eye = float(people[good_len[row][1]].face_eye_distance_px)
            embeddings[good_len[row][0]] = (stacked[row], np.array([eye if math.isfinite(eye) and eye > 0 else 0.0]))
        return *tracker_input, embeddings, person_index

    def _appearance(self, bodies: list[Any], camera_id: str) -> NDArray[np.float32] | None:
        """Count the detections' body fields (cameras without bodies send none) and embed the well-formed
        descriptors of the body metric's space for the tracker: (N, r), NaN rows for the others; None when
        none is usable (or appearance tracking is off). One pass over the frame's bodies, one GEMM."""
        st, metric = self.stats, self.body_metric
        present = [(k, b) for k, b in enumerate(bodies) if b is not None]
        if not present:
            return None
        usable: list[int] = []  # of the metric's space: checked for NaN / Inf together below
        rows: list[NDArray[np.float32]] = []
        for k, body in present:
            descriptor = np.asarray(body.descriptor, dtype=np.float32)
            visible = body.visible_fraction
            if descriptor.ndim != 1 or not is_finite_number(visible) or not 0.0 <= float(visible) <= 1.0:
                st.bodies_rejected_malformed += 1
            elif metric is not None and descriptor.size and body.space == metric.space \
                    and descriptor.size == metric.length:
                usable.append(k)
                rows.append(descriptor)
            elif not np.isfinite(descriptor).all():
                st.bodies_rejected_malformed += 1
            else:
                st.bodies_received += 1
                if metric is not None and descriptor.size:
                    self._other_body_space(camera_id, str(body.space))
        if not rows:
            return None
        stacked = np.stack(rows)
        finite = np.isfinite(stacked).all(axis=1)
        st.bodies_received += int(np.count_nonzero(finite))
        st.bodies_rejected_malformed += int(np.count_nonzero(~finite))
        if not finite.any():
            return None
        assert metric is not None
        assert self.body_fused is not None
        embedded = self.body_fused.embed(stacked[finite])
        out = np.full((len(bodies), embedded.shape[1]), np.nan, dtype=np.float32)
        out[np.asarray(usable)[finite]] = embedded
        return out

    def _other_body_space(self, camera_id: str, space: str) -> None:
        """Count a descriptor of another projection than the body metric's; say it once per camera and space."""
        assert self.body_metric is not None
        self.stats.bodies_rejected_space += 1
        space = space[:64]
        if _first_notice(self._body_space_noticed, camera_id, space):
            self._notices.append(f"camera {shown(camera_id, 64)} sends body descriptors of space {space!r}, the body "
                                 "metric "
                                 f"compares {self.body_metric.space!r}: its bodies are not used for tracking (see the "
                                 "cameras' body_projection_path and face-reid-fit-body)")

    def _in_space(self, person: Any, camera_id: str) -> NDArray[np.float32] | None:
        """The person's embedding in the master's space (part of a joint one is fine; not yet weighted by the
        likelihood's component scale); None: another space.

        An empty array for a length that does not match its space. The first embedding of a space the master
        cannot use, per camera, becomes a notice for the node to log."""
        space = person.embedding_space if isinstance(person.embedding_space, str) else ""
        values = np.asarray(person.embedding, dtype=np.float32).reshape(-1)
        want = self.config.embedding_space
        try:
            if space != want and values.size != space_dim(space):
                return np.zeros(0, dtype=np.float32)
            part = extract_space(values, space, want)  # scaled by the likelihood's weights once checked
            why = f"its face embeddings are of space {space[:64]!r}, this master compares {want!r}"
        except ValueError as exc:
            part, why = None, f"its face embeddings are unusable ({exc})"
        if part is None and _first_notice(self._space_noticed, camera_id, space):
            self._notices.append(f"camera {camera_id[:64]!r}: {why}: they are not used for identity (its "
                                 "positions still are); see the embedder / embedding_space parameters")
        return part

    # ------------------------------------------------------------------------------ identities
    def _track_events(self, deleted: Iterable[int], stamp: float, lost: Iterable[int] = (),
                      recovered: Iterable[int] = ()) -> None:
        """The tracker's lost / recovered / deleted tracks of one update, told to the face table."""
        for track_id in lost:
            self.identity.track_lost(track_id)
        for track_id in recovered:
            self.identity.track_recovered(track_id)
        for track_id in deleted:
            self.identity.track_deleted(track_id, stamp)
            self._face_obs.pop(track_id, None)
            self._gone.append(track_id)
            self._birth.pop(track_id, None)
            self._moved.discard(track_id)

    def _identity_step(self, deleted: Iterable[int], stamp: float, lost: Iterable[int] = (),
                       recovered: Iterable[int] = ()) -> list[Any]:
        """One identity update after the given track events; returns its events with published track ids."""
        self._track_events(deleted, stamp, lost, recovered)
        events = self.identity.step(stamp)
        kept = []
        for ev in events:
            if ev.kind == IdentityEventKind.NEW_FACE and not self._room_for(ev.face_id):
                continue  # not learned (max_faces): the track stays unidentified
            public = self.public_id(ev.track_id)
            kept.append(ev if public == ev.track_id else dataclasses.replace(ev, track_id=public))
            if ev.kind == IdentityEventKind.NEW_FACE:
                self.stats.faces_created += 1
                self._save_faces([ev.face_id])
            elif ev.kind == IdentityEventKind.ASSIGNED_KNOWN:
                self.stats.faces_reidentified += 1
                self._save_faces([ev.face_id])
            elif ev.kind in (IdentityEventKind.RELEASED, IdentityEventKind.SWAPPED):
                self.stats.faces_released += 1
                self._save_faces([ev.face_id])
            if ev.kind == IdentityEventKind.SWAPPED:
                self.stats.faces_released_swapped += 1
                self._split_track(ev.track_id, stamp)
            self._name_checked.pop(ev.face_id, None)
        for track_id in self._gone:
            self._split.pop(track_id, None)
        self._gone.clear()
        return kept

    def _split_track(self, track_id: int, stamp: float) -> None:
        """A swapped track is someone else from now on: it is published under a new id, so that no consumer
        carries the person it was over to the one it has become (its old id ends here)."""
        self._split[track_id] = (self.tracker.reserve_id(), stamp)
        self._face_obs[track_id] = 0

    def public_id(self, track_id: int) -> int:
        """The id a tracker track is published under: its own until a swap split it, then a new one per swap."""
        split = self._split.get(track_id)
        return track_id if split is None else split[0]

    def published_confidence(self, track_id: int) -> float:
        """``identity_confidence`` of a track: a decided track's decision posterior through the confidence map
        (how often such decisions were right); 0 for an undecided track (it claims no face: its candidates' raw
        posteriors are the overconfident numbers the map exists to correct)."""
        evidence = self.identity.evidence_of(track_id)
        if not evidence:
            return 0.0
        raw = float(self.identity.confidence_of(track_id))
        return float(self.confidence_map(evidence, raw, self.identity.decided_new(track_id)))

    def _room_for(self, new_face: int) -> bool:
        """Face cap: a new face within max_faces evicts the least recently seen unnamed face not on a track;
        False (the new face is forgotten at once, counted) when there is none."""
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
            self._notices.append(f"max_faces ({self.config.max_faces}) reached and every face is named or on a "
                                 f"track: a new face was not learned ({self.stats.faces_refused_cap} so far, "
                                 "faces_refused_cap)")
        return False

    def _evict(self, face_ids: list[int]) -> None:
        """Forget unnamed faces for the cap (memory, names, store), counted; logged at 1, 10, 100, ... evictions."""
        for fid in face_ids:
            self._drop_from_memory(fid)
        self._forget_stored(face_ids)
        before = self.stats.faces_evicted
        self.stats.faces_evicted += len(face_ids)
        if any(_power_of_ten(n) for n in range(before + 1, self.stats.faces_evicted + 1)):
            self._notices.append(f"max_faces ({self.config.max_faces}) reached: evicted the least recently seen "
                                 f"unnamed face(s) {face_ids[:10]} ({self.stats.faces_evicted} so far, faces_evicted)")

    def _drop_from_memory(self, face_id: int) -> bool:
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
            self._notices.append(f"the face store held {len(faces)} faces, more than max_faces "
                                 f"({self.config.max_faces}): evicted the {len(gone)} least recently seen unnamed")
        return [f for f in faces if f.face_id not in gone]

    def _maintain_faces(self, stamp: float) -> None:
        cfg = self.config
        if self.store is not None and stamp - self._last_prune_s >= cfg.prune_interval_s:
            self._last_prune_s = stamp
            self._prune_unnamed(stamp)
        due = [fid for fid, since in self._dirty_faces.items() if stamp - since >= cfg.save_interval_s]
        if due:
            self._save_faces(due)
        for fid in set(self.identity.assigned_tracks().values()):
            if stamp - self._name_checked.get(fid, -math.inf) >= cfg.name_update_interval_s:
                self._name_checked[fid] = stamp
                self._refresh_name(fid, self.identity.face_features(fid))

    def _refresh_name(self, face_id: int, features: NDArray[np.floating]) -> None:
        if not self.people.names():
            return
        self.people.update_face(face_id, features)
        matches = self.people.assignments()
        self._names = {fid: m.name for fid, m in matches.items()}
        for fid, name in self._names.items():
            if self.identity.face_name(fid) != name:
                self.identity.set_face_name(fid, name)
                self._save_faces([fid])

    def _save_faces(self, face_ids: list[int]) -> None:
        """Write faces to the store in one transaction (one fsync however many)."""
        faces = []
        for fid in face_ids:
            self._dirty_faces.pop(fid, None)
            with contextlib.suppress(KeyError):
                faces.append(self.identity.export_face(fid))
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
        self.finish_frames()
        for fid in list(self._dirty_faces):
            self._save_faces([fid])

    # ------------------------------------------------------------------------------ people
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
        for fid in self.identity.face_ids():
            self._refresh_name(fid, self.identity.face_features(fid))

    def forget_person(self, name: str) -> bool:
        """Remove a predefined person (gallery) at run time; the faces named after them lose the name.
        True if there was one."""
        if name not in self.people.names():
            return False
        self.people.remove_person(name)
        for fid in self.identity.face_ids():
            self._refresh_name(fid, self.identity.face_features(fid))
        return True

    def forget_face(self, face_id: int) -> bool:
        """Delete a learned face everywhere (memory, names, store). True if it existed; ValueError for an id out
        of range."""
        face_id = check_face_id(face_id)
        found = self._drop_from_memory(face_id)
        if self.store is not None:
            found = bool(self.store.forget(face_id)) or found
        return found

    def face_name(self, face_id: int) -> str:
        """The name linked to a face (predefined match, else a stored name), or ''."""
        return self._names.get(face_id) or self.identity.face_name(face_id) or ""

    # ------------------------------------------------------------------------------ output
    def _follow_births(self, associations: Iterable[tuple[int, int]], positions: NDArray[np.float64],
                       stamp: float) -> None:
        """Where each track appeared (its first detection), until it moves further than static_clutter_radius_m
        from there (checked on every detection, so a walk there and back counts)."""
        radius = self.config.static_clutter_radius_m
        for tid, det in associations:
            if tid in self._moved:
                continue
            x, y = float(positions[det, 0]), float(positions[det, 1])
            birth = self._birth.get(tid)
            if birth is None:
                self._birth[tid] = (x, y, stamp)
            elif math.hypot(x - birth[0], y - birth[1]) > radius:
                self._moved.add(tid)
                del self._birth[tid]

    def _static_clutter(self, snaps: list[Any]) -> set[int]:
        """Tracks that never moved from where they appeared nor showed a face for static_clutter_after_s (a body
        descriptor does not count: cameras describe every person-sized cluster, a coat stand too)."""
        after = self.config.static_clutter_after_s
        if not after:
            return set()
        return {snap.track_id for snap in snaps if snap.track_id in self._birth
                and self._face_obs.get(snap.track_id, 0) == 0 and snap.stamp_s - self._birth[snap.track_id][2] >= after}

    def tracks(self, at_s: float | None = None) -> list[NamedTrackRecord]:
        """Current tracks with identities (confirmed and lost; tentative if configured), static clutter left
        out (:meth:`_static_clutter`)."""
        out = []
        snaps = [s for s in self.tracker.snapshots(at_s, include_tentative=self.config.publish_tentative)
                 if s.state != TrackState.DELETED]
        clutter = self._static_clutter(snaps)
        self.static_clutter_tracks = len(clutter)
        for snap in snaps:
            if snap.track_id in clutter:
                continue
            fid = self.identity.face_id_of(snap.track_id) or 0
            out.append(
                NamedTrackRecord(
                    track_id=self.public_id(snap.track_id),
                    face_id=fid,
                    name=self.face_name(fid) if fid else "",
                    identity_confidence=self.published_confidence(snap.track_id),
                    identity_evidence=self.identity.evidence_of(snap.track_id),
                    face_observations=self._face_obs.get(snap.track_id, 0),
                    position_xy=snap.position_xy,
                    velocity_xy=snap.velocity_xy,
                    covariance=snap.covariance,
                    height_m=float(snap.height_m),
                    state=int(snap.state),
                    first_seen_s=float(self._split[snap.track_id][1] if snap.track_id in self._split
                                       else snap.created_s),
                    last_seen_s=float(snap.last_seen_s),
                    cameras=tuple(sorted(snap.cameras)),
                )
            )
        return out
