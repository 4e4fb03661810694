"""One camera's per-frame pipeline: depth people detection -> head ROIs -> faces -> embeddings, and bodies.

Pure core (no rclpy): the camera node, the replay tool, the simulator and the benchmarks all
call :meth:`CameraPipeline.process` with numpy images and get a :class:`FrameResult` back.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.body.observation import GEOMETRY_FIELDS, BodyObservation
from face_reid_camera.body.person_body import BodyConfig, describe_body
from face_reid_camera.body.projection import BodyProjection
from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.param_table import param, validate_fields
from face_reid_camera.faces.detector import FaceDetection, YuNetDetector
from face_reid_camera.faces.embedder import CombinedEmbedder, FaceEmbedder
from face_reid_camera.faces.embedding_schedule import EmbeddingScheduler
from face_reid_camera.faces.head_roi import head_roi_px
from face_reid_camera.people.detector import FloorCheck, PersonCandidate, PersonDetector, PersonDetectorConfig
from face_reid_camera.people.ground_plane import GroundPlane


@dataclass(frozen=True)
class FaceQualityConfig:
    """How face size and pose turn into a 0..1 quality score (the camera node's quality parameters)."""

    min_eye_distance_px: float = param(6.0, "Quality is 0 at this eye distance (px).", low=0.0, high=500.0,
                                       low_open=True)
    good_eye_distance_px: float = param(20.0, "Quality size factor is 1 from here (px).", low=0.0, high=500.0,
                                        low_open=True)
    max_face_yaw_deg: float = param(75.0, "Quality frontality factor reaches 0 at this yaw (deg).", low=0.0,
                                    high=90.0, low_open=True)

    def __post_init__(self) -> None:
        validate_fields(self)
        if not self.min_eye_distance_px < self.good_eye_distance_px:
            raise ValueError("need min_eye_distance_px < good_eye_distance_px")


@dataclass(frozen=True)
class CameraPipelineConfig:
    """Parameters of the per-frame pipeline (units in the names)."""

    camera_id: str = param("camera", "Unique id of this camera, sent in every message (string).", read_only=True)
    head_roi_size_m: float = param(0.3, "Side of the metric square around each head (m).", low=0.05, high=2.0)
    detect_faces: bool = param(True, "Run face detection and embedding (false = people positions only).")
    max_faces_per_frame: int = param(16, "Faces embedded per frame, nearest first (count).", low=0, high=1000)
    min_face_quality: float = param(0.0, "Faces below this quality (0..1) are not embedded.", low=0.0, high=1.0)
    embed_budget_ms: float = param(
        40.0, "Embedding time per frame (ms; 0 = every face); over budget, the faces embedded longest ago go "
        "first.",
        low=0.0, high=10000.0)
    describe_bodies: bool = param(
        True, "Describe each person's body: appearance (projected HSV + SILTP descriptor), depth geometry and "
        "visibility (bool).")
    max_bodies_per_frame: int = param(16, "Bodies described per frame, nearest people first (count).", low=0,
                                      high=1000)
    position_std_base_m: float = param(0.05, "Position uncertainty at 0 m range (m).", low=0.0, high=5.0,
                                       low_open=True)
    position_std_per_m2: float = param(0.005, "Uncertainty growth with range squared (m/m^2).", low=0.0, high=1.0)
    position_far_side_offset_m: float = param(
        0.045, "A camera sees the near half of a head: positions are moved this far away from the camera along the "
        "line of sight, so cameras on opposite sides agree (m; measured on rendered heads, 0 = off).",
        low=0.0, high=0.5)
    person: PersonDetectorConfig = field(default_factory=PersonDetectorConfig)
    quality: FaceQualityConfig = field(default_factory=FaceQualityConfig)
    body: BodyConfig = field(default_factory=BodyConfig)

    def __post_init__(self) -> None:
        validate_fields(self)
        if not self.camera_id:
            raise ValueError("camera_id must be a non-empty string")


@dataclass(frozen=True)
class FaceObservation:
    """A face found in a person's head ROI, with its embedding (None: not embedded in this frame, the
    embedding budget went to other faces) in space ``embedding_space``."""

    detection: FaceDetection
    quality: float
    yaw_deg: float
    eye_distance_px: float
    embedding: NDArray[np.float32] | None
    embedding_space: str = ""


@dataclass(frozen=True)
class PersonObservation:
    """One detected person in one frame (the core twin of face_reid_msgs/PersonObservation)."""

    position_world: NDArray[np.float64]
    position_camera: NDArray[np.float64]
    position_std_m: float
    height_m: float
    num_points: int
    head_roi_xywh: tuple[int, int, int, int] | None
    face: FaceObservation | None = None
    body: BodyObservation | None = None

    def to_json(self) -> dict[str, object]:
        """A JSON-friendly dict (what the replay tool prints)."""
        out: dict[str, object] = {
            "position_world": [round(float(v), 4) for v in self.position_world],
            "position_camera": [round(float(v), 4) for v in self.position_camera],
            "position_std_m": round(self.position_std_m, 4),
            "height_m": round(self.height_m, 3),
            "num_points": self.num_points,
            "head_roi": list(self.head_roi_xywh) if self.head_roi_xywh else None,
            "face_found": self.face is not None,
            "face_score": round(self.face.detection.score, 4) if self.face else 0.0,
        }
        if self.face is not None:
            out["face_box"] = [round(float(v), 1) for v in self.face.detection.box_xywh]
            out["face_quality"] = round(self.face.quality, 3)
            out["face_yaw_deg"] = round(self.face.yaw_deg, 1)
            out["face_embedded"] = self.face.embedding is not None
        if self.body is not None:
            g = self.body.geometry
            out["body"] = {
                "visible_fraction": round(self.body.visible_fraction, 3),
                "part_visible": [round(v, 3) for v in self.body.part_visible],
                "descriptor_length": int(self.body.descriptor.size),
                "geometry_m": {name.removesuffix("_m"): (round(v, 3) if math.isfinite(v) else None)
                               for name, v in zip(GEOMETRY_FIELDS, g.vector().tolist(), strict=True)},
            }
        return out


@dataclass(frozen=True)
class FrameResult:
    """Everything the pipeline found in one frame, with per-stage timings in milliseconds."""

    people: list[PersonObservation]
    ground_plane_found: bool
    timings_ms: dict[str, float]
    ground_plane: GroundPlane | None = None
    ground_plane_source: str = "none"
    floor_check: FloorCheck | None = None  # the pose checked against the floor measured without it (this frame)
    ground_support: float | None = None  # share of the points on the floor estimated in this frame (None: not now)

    @property
    def num_faces(self) -> int:
        return sum(1 for p in self.people if p.face is not None)

    @property
    def num_embedded(self) -> int:
        return sum(1 for p in self.people if p.face is not None and p.face.embedding is not None)


def face_pose_from_landmarks(landmarks: NDArray[np.floating]) -> tuple[float, float]:
    """Rough head yaw (degrees) and inter-ocular distance (px) from YuNet's 5 landmarks.

    Yaw comes from how far the nose sits from the eyes' midpoint relative to the eye distance
    (0 = frontal; positive = the subject turned to their left, i.e. the nose moved image-right).
    """
    lm = np.asarray(landmarks, dtype=np.float64).reshape(5, 2)
    eye_vec = lm[1] - lm[0]
    eye_dist = float(np.hypot(*eye_vec))
    if eye_dist < 1e-6:
        return 90.0, 0.0
    mid = (lm[0] + lm[1]) / 2.0
    # Nose offset along the eye axis, normalised: ~0.5 at a 90-degree profile.
    offset = float(np.dot(lm[2] - mid, eye_vec) / (eye_dist * eye_dist))
    yaw = math.degrees(math.asin(max(-1.0, min(1.0, 2.0 * offset))))
    return yaw, eye_dist


def face_quality(score: float, eye_distance_px: float, yaw_deg: float, config: FaceQualityConfig) -> float:
    """0..1: detector score x size factor x frontality factor."""
    size = (eye_distance_px - config.min_eye_distance_px) / (
        config.good_eye_distance_px - config.min_eye_distance_px
    )
    size = min(1.0, max(0.0, size))
    frontal = max(0.0, 1.0 - abs(yaw_deg) / config.max_face_yaw_deg)
    return float(min(1.0, max(0.0, score)) * size * frontal)


class CameraPipeline:
    """Runs the per-frame pipeline of one camera.

    ``face_detector`` / ``embedder`` may be None when ``config.detect_faces`` is false (people
    only). ``body_projection`` makes the body descriptor compact (None: bodies get geometry and
    visibility only, no appearance descriptor). The person detector keeps the floor estimate between
    frames (see PersonDetector); the embedding schedule keeps which heads were embedded when (see EmbeddingScheduler).
    """

    def __init__(
        self,
        config: CameraPipelineConfig,
        camera_pose: CameraPose,
        face_detector: YuNetDetector | None = None,
        embedder: FaceEmbedder | CombinedEmbedder | None = None,
        seed_ground_from_pose: bool = True,
        body_projection: BodyProjection | None = None,
    ) -> None:
        if config.detect_faces and (face_detector is None or embedder is None):
            raise ValueError("detect_faces=True needs a face detector and an embedder")
        if body_projection is not None and not isinstance(body_projection, BodyProjection):
            raise ValueError(f"body_projection must be a BodyProjection or None, got {type(body_projection).__name__}")
        self.config = config
        self.body_projection = body_projection
        self.body_errors = 0  # bodies that could not be described (the person is still reported, without one)
        self.thin_support_rejected = 0  # person-shaped clusters standing on a thin pole (coat stands), not reported
        self.cut_by_border_rejected = 0  # person-shaped clusters whose top is where the image ends, not reported
        self.camera_pose = camera_pose
        self.face_detector = face_detector
        self.embedder = embedder
        self.person_detector = PersonDetector(config.person, camera_pose if seed_ground_from_pose else None)
        self.schedule = EmbeddingScheduler(config.embed_budget_ms)

    def process(
        self,
        color_bgr: NDArray[np.uint8] | None,
        depth_m: NDArray[np.floating],
        intrinsics: CameraIntrinsics,
        color_intrinsics: CameraIntrinsics | None = None,
        stamp_s: float | None = None,
    ) -> FrameResult:
        """Detect people in ``depth_m`` (metres, NaN/0 invalid) and their faces in ``color_bgr``.

        ``intrinsics`` describe the depth image; ``color_intrinsics`` the colour image (default:
        registered, i.e. the depth intrinsics scaled to the colour size): faces are detected and
        embedded on the colour image's own pixels, whatever its resolution. ``color_bgr`` None
        means people only. ``stamp_s``: capture time (s) for the embedding schedule (None: the
        monotonic clock).
        """
        t0 = time.perf_counter()
        stamp = time.monotonic() if stamp_s is None else float(stamp_s)
        detection = self.person_detector.detect_depth(depth_m, intrinsics)
        self.thin_support_rejected += detection.num_thin_support
        self.cut_by_border_rejected += detection.num_cut_by_border
        t1 = time.perf_counter()
        if color_bgr is not None and color_intrinsics is None:
            h, w = color_bgr.shape[:2]
            color_intrinsics = (
                intrinsics if (w, h) == (intrinsics.width, intrinsics.height) else intrinsics.scaled(w, h)
            )
        plane = detection.ground_plane
        people = [self._observation(cand, plane, color_intrinsics or intrinsics) for cand in detection.people]
        rois = [p.head_roi_xywh for p in people]
        timings = {"people_ms": (t1 - t0) * 1e3, "face_detect_ms": 0.0, "embed_ms": 0.0, "body_ms": 0.0}
        if self.config.detect_faces and color_bgr is not None and people:
            people = self._add_faces(color_bgr, people, rois, timings, stamp)
        if self.config.describe_bodies and color_bgr is not None and people and plane is not None:
            assert color_intrinsics is not None
            t_body = time.perf_counter()
            people = self._add_bodies(color_bgr, depth_m, intrinsics, color_intrinsics, plane, detection.people,
                                      people)
            timings["body_ms"] = (time.perf_counter() - t_body) * 1e3
        timings["total_ms"] = (time.perf_counter() - t0) * 1e3
        # found: seen in the data (now or in a previous frame); the pose's floor alone counts only when trusted
        found = detection.ground_plane is not None and (
            detection.ground_plane_source != "pose" or self.person_detector.config.people_on_pose_floor)
        return FrameResult(
            people, found, timings, detection.ground_plane, detection.ground_plane_source,
            detection.floor_check, detection.ground_support,
        )

    def _observation(self, cand: PersonCandidate, plane: GroundPlane | None,
                     color_intrinsics: CameraIntrinsics) -> PersonObservation:
        """A detected person: position on the floor (world and camera frame) with its spread, and the head's
        region in the colour image."""
        head = np.asarray(cand.head_cam, dtype=np.float64)
        # The person's position is the head centre dropped onto the floor: unlike the centroid
        # of the visible surface it does not shift towards whichever camera sees the person.
        cam = head - float(plane.height_of(head[None, :])[0]) * plane.normal if plane is not None else head
        cam = self._beyond_near_side(cam, plane)
        rng = float(np.linalg.norm(cam))
        std = self.config.position_std_base_m + self.config.position_std_per_m2 * rng * rng
        return PersonObservation(
            position_world=self.camera_pose.to_world(cam)[0],
            position_camera=cam,
            position_std_m=float(std),
            height_m=float(cand.height_m),
            num_points=int(cand.num_points),
            head_roi_xywh=head_roi_px(np.asarray(cand.head_cam), color_intrinsics, self.config.head_roi_size_m),
        )

    def _beyond_near_side(self, cam: NDArray[np.float64], plane: GroundPlane | None) -> NDArray[np.float64]:
        """Move a floor position position_far_side_offset_m further from the camera, horizontally (the visible head
        cap is biased towards the camera by about that much)."""
        offset = self.config.position_far_side_offset_m
        if offset <= 0 or plane is None:
            return cam
        away = cam - float(cam @ plane.normal) * plane.normal  # horizontal direction from the camera
        norm = float(np.linalg.norm(away))
        return cam if norm < 1e-6 else cam + (offset / norm) * away

    def _add_bodies(
        self, color_bgr: NDArray[np.uint8], depth_m: NDArray[np.floating], intrinsics: CameraIntrinsics,
        color_intrinsics: CameraIntrinsics, plane: GroundPlane, candidates: list[PersonCandidate],
        people: list[PersonObservation],
    ) -> list[PersonObservation]:
        """Each person's body (nearest first, at most ``max_bodies_per_frame``), their pixels cut out by depth."""
        tops = np.array([np.asarray(c.top_cam, dtype=np.float64) for c in candidates])
        feet = tops - np.array([c.height_m for c in candidates])[:, None] * plane.normal[None, :]
        order = sorted(range(len(people)), key=lambda i: float(people[i].position_camera[2]))
        people = list(people)
        for i in order[: self.config.max_bodies_per_frame]:
            try:
                body = describe_body(color_bgr, depth_m, intrinsics, color_intrinsics, plane, tops[i],
                                     float(candidates[i].height_m), np.delete(feet, i, axis=0), self.config.body,
                                     self.body_projection)
            except (ValueError, cv2.error, FloatingPointError):  # a degenerate view: the position still counts
                self.body_errors += 1
                continue
            if body is not None:
                people[i] = dataclasses.replace(people[i], body=body)
        return people

    def _add_faces(
        self,
        color_bgr: NDArray[np.uint8],
        people: list[PersonObservation],
        rois: list[tuple[int, int, int, int] | None],
        timings: dict[str, float],
        stamp_s: float,
    ) -> list[PersonObservation]:
        assert self.face_detector is not None and self.embedder is not None
        # Nearest people first, so the per-frame face budget goes to the best-resolved heads.
        order = sorted(
            (i for i, r in enumerate(rois) if r is not None),
            key=lambda i: float(people[i].position_camera[2]),
        )[: self.config.max_faces_per_frame]
        if not order:
            return people
        t0 = time.perf_counter()
        faces = self.face_detector.detect_in_rois(color_bgr, [rois[i] for i in order])
        t1 = time.perf_counter()
        found: list[tuple[int, FaceDetection, float, float, float]] = []
        for i, face in zip(order, faces, strict=True):
            if face is None:
                continue
            yaw, eye_dist = face_pose_from_landmarks(face.landmarks)
            quality = face_quality(face.score, eye_dist, yaw, self.config.quality)
            if quality < self.config.min_face_quality:
                continue
            found.append((i, face, quality, yaw, eye_dist))
        if found:
            heads = np.array([people[f[0]].position_camera for f in found], dtype=np.float64)
            chosen = self.schedule.choose(stamp_s, heads, np.array([f[2] for f in found]))
            t_embed = time.perf_counter()
            embeddings = self.embedder.embed_faces(color_bgr, [found[k][1].landmarks for k in chosen])
            self.schedule.embedded(stamp_s, chosen, (time.perf_counter() - t_embed) * 1e3)
            embedding_of = dict(zip(chosen, embeddings, strict=True))
            people = list(people)
            space = self.embedder.space
            for k, (i, face, quality, yaw, eye_dist) in enumerate(found):
                emb = embedding_of.get(k)
                if emb is not None and not np.all(np.isfinite(emb)):
                    continue
                obs = FaceObservation(face, quality, yaw, eye_dist,
                                      None if emb is None else np.asarray(emb, dtype=np.float32),
                                      space if emb is not None else "")
                people[i] = dataclasses.replace(people[i], face=obs)
        t2 = time.perf_counter()
        timings["face_detect_ms"] = (t1 - t0) * 1e3
        timings["embed_ms"] = (t2 - t1) * 1e3
        return people
