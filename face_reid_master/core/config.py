"""The master core's parameters (one declaration each: type, default, description, range)."""

from __future__ import annotations

from dataclasses import dataclass, field

from face_reid_camera.common.checks import check_real
from face_reid_camera.common.embedding_spaces import DLIB_SPACE, EMBEDDER_CHOICES, SFACE_SPACE, embedder_space
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_master.tracking.config import TrackerConfig

__all__ = ["MasterConfig"]

_SPACE_CHOICES = tuple(embedder_space(choice) for choice in EMBEDDER_CHOICES)


@dataclass(frozen=True)
class MasterConfig:
    """Parameters of the master core: each declared once with its type, default, description and range
    (the node's parameters, ``config/master.yaml`` and their validation come from these declarations)."""

    method: str = param("bayes", "Face classification: 'bayes' (the paper's table) or 'threshold' (baseline).",
                        choices=("bayes", "threshold"))
    embedding_space: str = param(
        DLIB_SPACE + "+" + SFACE_SPACE, "Embedder space compared for identity; cameras must send it or a joint "
        "space containing it (other embeddings are not used, said once per camera).", choices=_SPACE_CHOICES,
        read_only=True)
    known_camera_ids: tuple[str, ...] = ()  # accepted camera ids (empty: any; the node parameter of that name)
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
    name_update_interval_s: float = 0.5  # how often a live face's predefined-name match is re-evaluated (s)
    prune_interval_s: float = 60.0  # how often the store's retention of unnamed faces runs (s)
    # identity (Bayesian)
    posterior_threshold: float = param(0.95, "Assign a face when its posterior exceeds this (0.5..1).",
                                       low=0.5, high=0.999, high_open=True)
    prior_probability: float = param(0.1, "Prior of a new cell of the face table (0..1).",
                                     low=0.0, high=1.0, low_open=True, high_open=True)
    min_observations: int = param(3, "Face observations needed before a decision (count).", low=1, high=1000)
    learn_confidence: float = param(
        0.99, "A face decision at least this certain teaches its face the track's face and body embeddings; a less "
        "certain one identifies the track but teaches nothing: one wrong decision cannot make a face, or its person's "
        "clothes, another person's (0..1).",
        low=0.0, high=1.0)
    new_person_scale_c: float = param(1.0, "The paper's c: larger = readier to call a face new.",
                                      low=0.0, high=1e6, low_open=True)
    max_features_per_face: int = param(50, "Embeddings kept per face, a diverse subset (count).", low=1, high=10000)
    max_faces: int = param(
        3000, "Learned faces kept at most (count); a new face evicts the least recently seen unnamed face not on a "
        "track, named faces never go.",
        low=1, high=1_000_000)
    learn_only_consistent_features: bool = param(
        True, "An identified track's embedding joins its face only if within the decision distance (guards "
        "faces against tracker swaps; false = the paper).")
    release_after_inconsistent: int = param(
        3, "A decided track whose last this many face embeddings were beyond the decision distance was swapped: "
        "it goes on under a new track id, undecided (count; 0 = never).", low=0, high=1000)
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
    alike_face_distance: float = param(
        0.0, "Two learned faces closer than this face-embedding distance count as one person: a track's face and "
        "body posteriors are summed over them (0 = half the face decision distance).", low=0.0, high=4.0)
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
