"""Scenario simulator: people walking in a room watched by RGB-D cameras, as recorded camera messages.

Two levels share one world (:mod:`face_reid_master.sim.world`), one motion and one choice of photos:

- ``feature``: camera messages are made directly: detected people with noisy positions, and faces
  whose embeddings come from real photos run through the real YuNet + dlib-ResNet models (fast).
- ``pixel``: every camera frame is rendered (:func:`face_reid_master.sim.renderer.render_scene`,
  the chosen photo pasted on the face) and run through the real :class:`CameraPipeline`; its
  detections are matched to the simulated people by position for the ground truth (~30 ms/frame).

Glances and photo reuse: a *glance* is a run of one camera's frames in which a person's face is
visible (gaps under ``glance_gap_s`` bridged). One photo of the person is drawn per glance and used for
all its frames, so observations within a glance are correlated as in a real video. Feature level: each
photo is embedded once in ``NUM_VARIANTS`` versions, each a real image change re-detected and
re-embedded by the real models (brightness, +-8 deg rotation, JPEG, and down-sampling to the eye
distance a Kinect gives at 2-3 m and 3.3-4.5 m); each frame of a glance takes one variant allowed at its
range plus a little Gaussian noise (``embedding_noise_std`` per dimension). The variants lie 0.11-0.38
(L2) from the photo's own embedding; within a glance the feature level gives a median pairwise distance
of 0.33 where the pixel level (rendered frames through the real pipeline) gives 0.37 (6 people, 3
cameras, 200 s, seed 1), so the correlation of real consecutive frames is kept at the cost of a few
embeddings per photo (cached with ``cache_path``). Flips are not used: they change little and would
mirror asymmetric features.

Days: with ``second_day`` the same room and cameras are replayed ``day_gap_s`` after day 1 ends with
``people - new_people`` of the day-1 people (other photos: each identity's photos are split in two
halves, day 1 / day 2, by a fixed per-identity shuffle) and ``new_people`` identities never seen on day 1.

Output directory (written by :func:`write_scenario`, read by :func:`load_scenario`):

- ``scenario.json``: ``format`` ("face-reid-scenario"), ``version``, ``level``, ``seed``,
  ``parameters`` (every setting), ``room``, ``doors``, ``cameras`` (id, xyz_rpy, rotation, translation,
  intrinsics, frame phase), ``photos`` (index, identity, path relative to ``faces_dir``),
  ``identities`` (gt_id, name, height_m, days, photos per day as photo indices), ``days`` (day,
  start_s, end_s, gt_ids) and ``summary`` (frames, detections, faces, glances, false positives, track
  losses and visible segments per person and in total, coverage, skipped photos).
- ``frames.npz``: camera frames in stamp order (ties: camera order) and their detections, flat:
  ``frame_camera`` (F,) int16 index into cameras, ``frame_stamp_s`` (F,) float64, ``frame_offsets``
  (F+1,) int64: detections of frame i are rows offsets[i]:offsets[i+1] of ``det_position`` (D, 3)
  float64 world m, ``det_std_m`` (D,) float32, ``det_height_m`` (D,) float32, ``det_gt_id`` (D,) int32
  (-1 = false positive), ``det_face`` (D,) int32 row into the face arrays or -1; ``face_embedding``
  (E, 128) float32, ``face_score``, ``face_quality`` (E,) float32, ``face_photo`` (E,) int32 photo
  index (-1 unknown), ``face_glance`` (E,) int32, ``face_variant`` (E,) int16 (-1 at pixel level).
- ``ground_truth.npz``: ``t_s`` (T,) at ``ground_truth_rate_hz`` for each day, ``day`` (T,) int8,
  ``gt_id`` (P,) int32, ``xy`` (P, T, 2) float32 (NaN when the person is absent that day),
  ``facing_rad`` (P, T) float32, ``in_room`` (P, T), ``in_view`` (P, T, M), ``face_visible`` (P, T, M) bool.

The npz files are written with fixed zip timestamps, so the same seed gives byte-identical files.
"""

from __future__ import annotations

import io
import json
import math
import os
import time
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TextIO

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.pipeline import FaceQualityConfig, face_quality
from face_reid_master.records import EMBEDDING_DIM, CameraFrameRecord, PersonRecord
from face_reid_master.sim.world import (
    MotionConfig,
    Room,
    Trajectory,
    VisibilityConfig,
    World,
    camera_visibility,
    count_losses,
    coverage_fraction,
    glance_ids,
    make_world,
    plan_trajectory,
    room_size_for,
    sample_trajectories,
)

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LEVELS",
    "NUM_VARIANTS",
    "CameraSpec",
    "GroundTruth",
    "IdentityPhotos",
    "InsufficientFacesError",
    "PhotoBank",
    "PhotoVariants",
    "Scenario",
    "ScenarioFormatError",
    "SimConfig",
    "SimResult",
    "load_scenario",
    "load_scenario_document",
    "simulate",
    "write_scenario",
]

FORMAT_NAME = "face-reid-scenario"
FORMAT_VERSION = 1
LEVELS = ("feature", "pixel")
DEFAULT_RATE_HZ = {"feature": 15.0, "pixel": 5.0}

# Photo variants (index: change). Re-detected and re-embedded with the real models; see the module doc.
_VARIANT_SPECS: tuple[dict[str, float], ...] = (
    {},  # 0: the photo as is
    {"alpha": 0.7, "beta": -10.0},  # 1: darker, lower contrast
    {"alpha": 1.3, "beta": 20.0},  # 2: brighter
    {"rotate_deg": 8.0},  # 3: head roll
    {"rotate_deg": -8.0, "jpeg": 35.0},  # 4: roll the other way + compression
    {"eye_px": 14.0},  # 5: resolution of a Kinect face at ~2.4 m
    {"eye_px": 10.0},  # 6: ... at ~3.3 m
    {"eye_px": 9.0, "alpha": 0.8, "beta": -5.0, "rotate_deg": 5.0},  # 7: far, dim, rolled
)
NUM_VARIANTS = len(_VARIANT_SPECS)
_VARIANT_VERSION = "v1"  # bump when _VARIANT_SPECS change: invalidates cached variants
# Variants a frame may use, by face range (m): near, mid, far.
_RANGE_EDGES_M = (2.0, 3.3)
_RANGE_VARIANTS: tuple[tuple[int, ...], ...] = ((0, 1, 2, 3, 4), (1, 2, 3, 4, 5), (5, 6, 7))
_KINECT_FX_PX = 525.0
_EYE_DISTANCE_M = 0.063

# RNG stream ids: each concern draws from its own generator, so changing one option does not reshuffle
# the others (e.g. feature and pixel level of one seed share the world, the motion and the photos).
_S_WORLD, _S_IDENTITIES, _S_MOTION, _S_CAMERA, _S_FACES, _S_FP, _S_RENDER, _S_PHASE, _S_LOOK = range(9)


class InsufficientFacesError(ValueError):
    """The faces folder is empty or has fewer usable identities than the scenario needs."""


class ScenarioFormatError(ValueError):
    """A scenario directory is missing files or holds inconsistent data."""


# ---------------------------------------------------------------------------------------------------
# Configuration


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a scenario (with the faces folder and the seed)."""

    num_people: int = 6
    num_cameras: int = 3
    duration_s: float = 200.0
    seed: int = 0
    level: str = "feature"
    rate_hz: float | None = None  # None: 15 Hz (feature) / 5 Hz (pixel)
    second_day: bool = False
    new_people: int | None = None  # None: num_people // 3
    day_gap_s: float = 600.0
    room_size_m: tuple[float, float] | None = None  # None: scaled with the number of cameras
    miss_probability: float = 0.05
    false_positives_per_frame: float = 0.01
    position_noise_base_m: float = 0.04
    position_noise_per_m: float = 0.01
    calibration_error_m: float = 0.03
    height_noise_m: float = 0.03
    face_detect_probability: float = 0.95
    embedding_noise_std: float = 0.01
    glance_gap_s: float = 0.5
    min_photos_per_identity: int = 2
    loss_gap_s: float = 1.5
    ground_truth_rate_hz: float = 10.0
    motion: MotionConfig = field(default_factory=MotionConfig)
    visibility: VisibilityConfig = field(default_factory=VisibilityConfig)

    def __post_init__(self) -> None:
        for name, low, high in (("num_people", 1, 500), ("num_cameras", 1, 64), ("min_photos_per_identity", 1, 1000)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= high:
                raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.level not in LEVELS:
            raise ValueError(f"level must be one of {LEVELS}, got {self.level!r}")
        if not (_finite(self.duration_s) and 0 < self.duration_s <= 24 * 3600):
            raise ValueError(f"duration_s must be in (0, 86400] s, got {self.duration_s!r}")
        if self.rate_hz is not None and not (_finite(self.rate_hz) and 0 < self.rate_hz <= 120):
            raise ValueError(f"rate_hz must be in (0, 120] Hz, got {self.rate_hz!r}")
        if self.new_people is not None and (
            isinstance(self.new_people, bool) or not isinstance(self.new_people, (int, np.integer))
            or not 0 <= self.new_people <= self.num_people
        ):
            raise ValueError(
                f"new_people must be an integer in [0, num_people={self.num_people}], got {self.new_people!r}"
            )
        if self.room_size_m is not None:
            Room(*self.room_size_m)  # validates
        for name in ("miss_probability", "face_detect_probability"):
            value = getattr(self, name)
            if not (_finite(value) and 0 <= value <= 1):
                raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
        for name in ("false_positives_per_frame", "position_noise_per_m", "calibration_error_m", "height_noise_m",
                     "embedding_noise_std", "glance_gap_s", "loss_gap_s", "day_gap_s"):
            value = getattr(self, name)
            if not (_finite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not (_finite(self.position_noise_base_m) and self.position_noise_base_m > 0):
            raise ValueError(f"position_noise_base_m must be > 0, got {self.position_noise_base_m!r}")
        if not (_finite(self.ground_truth_rate_hz) and 0 < self.ground_truth_rate_hz <= 100):
            raise ValueError(f"ground_truth_rate_hz must be in (0, 100] Hz, got {self.ground_truth_rate_hz!r}")
        if not isinstance(self.motion, MotionConfig) or not isinstance(self.visibility, VisibilityConfig):
            raise ValueError("motion / visibility must be MotionConfig / VisibilityConfig instances")

    @property
    def frame_rate_hz(self) -> float:
        return float(self.rate_hz) if self.rate_hz is not None else DEFAULT_RATE_HZ[self.level]

    @property
    def num_new_people(self) -> int:
        if not self.second_day:
            return 0
        return int(self.new_people) if self.new_people is not None else self.num_people // 3

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["frame_rate_hz"] = self.frame_rate_hz
        out["num_new_people"] = self.num_new_people
        return out


def _finite(value: object) -> bool:
    real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    return real and math.isfinite(float(value))  # type: ignore[arg-type]


def _rng(seed: int, *stream: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), *(int(s) for s in stream)])


# ---------------------------------------------------------------------------------------------------
# Photos


@dataclass(frozen=True)
class PhotoVariants:
    """One usable photo: path relative to the faces folder, face box/score, and (NUM_VARIANTS, 128)
    embeddings of its variants (NaN rows: no face found in that variant; row 0 is always valid)."""

    rel_path: str
    box_xywh: NDArray[np.float32]
    score: float
    embeddings: NDArray[np.float32]


@dataclass(frozen=True)
class IdentityPhotos:
    """An identity folder's usable photos (file-name order) and their day-1 / day-2 split (indices)."""

    name: str
    photos: tuple[PhotoVariants, ...]
    day_photos: tuple[tuple[int, ...], tuple[int, ...]]


def _augment(image: NDArray[np.uint8], spec: dict[str, float], eye_px: float, centre: NDArray[np.float32]
             ) -> NDArray[np.uint8]:
    """Apply one variant spec (photometric, roll about the face centre, JPEG, down-sampling)."""
    out = image
    if "eye_px" in spec and eye_px > spec["eye_px"]:
        factor = spec["eye_px"] / eye_px
        h, w = out.shape[:2]
        small = cv2.resize(out, (max(8, round(w * factor)), max(8, round(h * factor))), interpolation=cv2.INTER_AREA)
        out = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    if "alpha" in spec:
        out = cv2.convertScaleAbs(out, alpha=spec["alpha"], beta=spec.get("beta", 0.0))
    if "rotate_deg" in spec:
        matrix = cv2.getRotationMatrix2D((float(centre[0]), float(centre[1])), spec["rotate_deg"], 1.0)
        out = cv2.warpAffine(out, matrix, (out.shape[1], out.shape[0]), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
    if "jpeg" in spec:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(spec["jpeg"])])
        if ok:
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


class PhotoBank:
    """Identity folders of a faces directory, embedded on demand (real models) with an optional npz cache.

    The cache maps ``path|mtime_ns|size|variant-version`` to the photo's status (usable / unreadable / no
    face), face box, score and variant embeddings; photos whose file changed are re-embedded.
    """

    _OK, _UNREADABLE, _NO_FACE = 0, 1, 2

    def __init__(self, faces_dir: str | Path, cache_path: str | Path | None = None,
                 min_photos_per_identity: int = 2, log: TextIO | None = None) -> None:
        from face_reid_camera.faces.photos import list_identity_photos

        self.faces_dir = Path(faces_dir)
        if not self.faces_dir.is_dir():
            raise InsufficientFacesError(f"faces folder {self.faces_dir} does not exist or is not a directory")
        photos, ignored = list_identity_photos(self.faces_dir)
        self.identity_files = {name: files for name, files in photos.items() if files}
        self.ignored_non_image = len(ignored)
        if not self.identity_files:
            raise InsufficientFacesError(
                f"faces folder {self.faces_dir} has no photos: expected one sub-folder per identity with image files"
            )
        self.min_photos = int(min_photos_per_identity)
        self.cache_path = Path(cache_path) if cache_path is not None else None
        self.log = log
        self.skipped_unreadable: list[str] = []
        self.skipped_no_face: list[str] = []
        self.too_few_photos: list[str] = []
        self._cache: dict[str, tuple[int, NDArray[np.float32], float, NDArray[np.float32]]] = {}
        self._cache_dirty = False
        self._embedder: Any = None
        self.embedded_now = 0
        if self.cache_path is not None and self.cache_path.is_file():
            self._load_cache()

    @property
    def photo_embedder(self) -> Any:
        """The real :class:`PhotoEmbedder` (YuNet + dlib ResNet), loaded on first use."""
        if self._embedder is None:
            from face_reid_camera.faces.photos import PhotoEmbedder

            self._embedder = PhotoEmbedder()
        return self._embedder

    # --- cache
    def _load_cache(self) -> None:
        assert self.cache_path is not None
        try:
            with np.load(self.cache_path, allow_pickle=False) as data:
                keys = [str(k) for k in data["keys"]]
                status, boxes, scores, embs = data["status"], data["boxes"], data["scores"], data["embeddings"]
                if embs.shape[1:] != (NUM_VARIANTS, EMBEDDING_DIM) or len({len(keys), len(status), len(boxes),
                                                                          len(scores), len(embs)}) != 1:
                    raise ValueError("inconsistent arrays")
                for i, key in enumerate(keys):
                    self._cache[key] = (int(status[i]), boxes[i].astype(np.float32), float(scores[i]),
                                        embs[i].astype(np.float32))
        except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
            self._say(f"ignoring unusable embedding cache {self.cache_path}: {exc}")
            self._cache = {}

    def save_cache(self) -> None:
        """Write the cache file (atomically) if anything new was embedded."""
        if self.cache_path is None or not self._cache_dirty:
            return
        keys = sorted(self._cache)
        arrays = {
            "keys": np.array(keys, dtype=np.str_),
            "status": np.array([self._cache[k][0] for k in keys], dtype=np.int8),
            "boxes": np.array([self._cache[k][1] for k in keys], dtype=np.float32).reshape(-1, 4),
            "scores": np.array([self._cache[k][2] for k in keys], dtype=np.float32),
            "embeddings": np.array([self._cache[k][3] for k in keys], dtype=np.float32).reshape(
                -1, NUM_VARIANTS, EMBEDDING_DIM),
        }
        self.cache_path.parent.mkdir(parents=True, exist_ok=True)
        _write_npz(self.cache_path, arrays)
        self._cache_dirty = False

    @staticmethod
    def _key(path: Path) -> str:
        st = path.stat()
        return f"{path.resolve()}|{st.st_mtime_ns}|{st.st_size}|{_VARIANT_VERSION}"

    def _say(self, message: str) -> None:
        if self.log is not None:
            self.log.write(message + "\n")
            self.log.flush()

    # --- embedding
    def _embed(self, path: Path) -> tuple[int, NDArray[np.float32], float, NDArray[np.float32]]:
        from face_reid_camera.faces.photos import PhotoError, read_photo

        nan_box = np.full(4, np.nan, dtype=np.float32)
        nan_embs = np.full((NUM_VARIANTS, EMBEDDING_DIM), np.nan, dtype=np.float32)
        try:
            image = read_photo(path)
        except PhotoError:
            return self._UNREADABLE, nan_box, 0.0, nan_embs
        embedder = self.photo_embedder
        base = embedder.embed_photo(image)
        if base is None:
            return self._NO_FACE, nan_box, 0.0, nan_embs
        embs = nan_embs.copy()
        embs[0] = base.embedding
        box = np.asarray(base.box_xywh, dtype=np.float32)
        centre = box[:2] + box[2:] / 2.0
        for v, spec in enumerate(_VARIANT_SPECS[1:], start=1):
            variant = embedder.embed_photo(_augment(image, spec, base.eye_distance_px, centre))
            if variant is not None:
                embs[v] = variant.embedding
        return self._OK, box, float(base.score), embs

    def load_identity(self, name: str) -> IdentityPhotos | None:
        """Embed (or fetch from the cache) one identity folder; None if it has too few usable photos."""
        files = self.identity_files[name]
        photos: list[PhotoVariants] = []
        for path in files:
            try:
                key = self._key(path)
            except OSError:  # vanished or unreadable since the folder was listed
                self.skipped_unreadable.append(path.relative_to(self.faces_dir).as_posix())
                continue
            entry = self._cache.get(key)
            if entry is None:
                entry = self._embed(path)
                self._cache[key] = entry
                self._cache_dirty = True
                self.embedded_now += 1
            status, box, score, embs = entry
            rel = path.relative_to(self.faces_dir).as_posix()
            if status == self._UNREADABLE:
                self.skipped_unreadable.append(rel)
            elif status == self._NO_FACE:
                self.skipped_no_face.append(rel)
            else:
                photos.append(PhotoVariants(rel, box, score, embs))
        if len(photos) < self.min_photos:
            self.too_few_photos.append(name)
            return None
        order = np.random.default_rng(zlib.crc32(name.encode("utf-8"))).permutation(len(photos))
        half = max(1, math.ceil(len(photos) / 2))
        day1 = tuple(sorted(int(i) for i in order[:half]))
        day2 = tuple(sorted(int(i) for i in order[half:])) or day1
        return IdentityPhotos(name, tuple(photos), (day1, day2))

    def choose(self, count: int, rng: np.random.Generator) -> list[IdentityPhotos]:
        """``count`` usable identities in a random order (folders are embedded only as needed)."""
        names = sorted(self.identity_files)
        chosen: list[IdentityPhotos] = []
        for i in rng.permutation(len(names)):
            if len(chosen) == count:
                break
            ident = self.load_identity(names[int(i)])
            if ident is not None:
                chosen.append(ident)
                self._say(f"  identity {ident.name}: {len(ident.photos)} usable photos")
        if len(chosen) < count:
            raise InsufficientFacesError(
                f"faces folder {self.faces_dir} has only {len(chosen)} usable identities (>= {self.min_photos} "
                f"photos with a detectable face), the scenario needs {count}; skipped "
                f"{len(self.skipped_unreadable)} unreadable files and {len(self.skipped_no_face)} photos "
                f"without a face"
            )
        return chosen


# ---------------------------------------------------------------------------------------------------
# Simulation


@dataclass
class _Columns:
    """Detections of one camera over one day, columnar (frame = index into that camera's stamps)."""

    frame: list[NDArray[np.int64]] = field(default_factory=list)
    gt: list[NDArray[np.int32]] = field(default_factory=list)
    position: list[NDArray[np.float64]] = field(default_factory=list)
    std: list[NDArray[np.float32]] = field(default_factory=list)
    height: list[NDArray[np.float32]] = field(default_factory=list)
    has_face: list[NDArray[np.bool_]] = field(default_factory=list)
    embedding: list[NDArray[np.float32]] = field(default_factory=list)  # rows only for faces
    face_score: list[NDArray[np.float32]] = field(default_factory=list)
    face_quality: list[NDArray[np.float32]] = field(default_factory=list)
    face_photo: list[NDArray[np.int32]] = field(default_factory=list)
    face_glance: list[NDArray[np.int32]] = field(default_factory=list)
    face_variant: list[NDArray[np.int16]] = field(default_factory=list)


@dataclass
class _FrameTable:
    """All frames of the scenario, flat (what frames.npz stores)."""

    camera: NDArray[np.int16]
    stamp_s: NDArray[np.float64]
    offsets: NDArray[np.int64]
    det: dict[str, NDArray[Any]]
    face: dict[str, NDArray[Any]]


@dataclass
class _Day:
    """One simulated day: its people (gt ids), their trajectories and photo choices."""

    day: int
    start_s: float
    gt_ids: list[int]
    trajectories: list[Trajectory]


@dataclass
class SimResult:
    """What :func:`simulate` produced: the json document, the frame table, the ground truth arrays."""

    document: dict[str, Any]
    frames: _FrameTable
    ground_truth: dict[str, NDArray[Any]]


def _camera_stamps(start_s: float, duration_s: float, rate_hz: float, phase_s: float) -> NDArray[np.float64]:
    n = math.floor((duration_s - phase_s) * rate_hz - 1e-9) + 1
    return start_s + phase_s + np.arange(max(n, 0), dtype=np.float64) / rate_hz


def _range_bucket(range_m: NDArray[np.float64]) -> NDArray[np.int64]:
    return np.searchsorted(np.asarray(_RANGE_EDGES_M), range_m, side="right").astype(np.int64)


def _valid_variants(photo: PhotoVariants) -> list[list[int]]:
    """Per range bucket, the variants of ``photo`` that had a face (fallback: the nearest valid ones)."""
    ok = np.isfinite(photo.embeddings).all(axis=1)
    out = []
    for bucket in _RANGE_VARIANTS:
        chosen = [v for v in bucket if ok[v]]
        if not chosen:
            chosen = [v for v in range(NUM_VARIANTS) if ok[v]][-2:]
        out.append(chosen)
    return out


def _feature_camera_day(
    cfg: SimConfig, world: World, cam_index: int, day: _Day, stamps: NDArray[np.float64],
    identities: list[IdentityPhotos], photo_offsets: list[int], heights: NDArray[np.float64],
    camera_bias: NDArray[np.float64], glance_counter: list[int],
) -> _Columns:
    """Camera messages of one camera over one day, made directly from the world model."""
    camera = world.cameras[cam_index]
    rng_det = _rng(cfg.seed, _S_CAMERA, day.day, cam_index)
    rng_face = _rng(cfg.seed, _S_FACES, day.day, cam_index)
    rng_fp = _rng(cfg.seed, _S_FP, day.day, cam_index)
    cols = _Columns()
    n_f, n_p = stamps.size, len(day.gt_ids)
    if n_f == 0:
        return cols
    xy, facing = sample_trajectories(day.trajectories, stamps)
    in_room = world.room.contains(xy)
    vis = camera_visibility(camera, xy, facing, heights, in_room, cfg.visibility)
    detected = vis.detectable & (rng_det.random((n_f, n_p)) >= cfg.miss_probability)
    # glances and their photos, per person
    photo_of = np.full((n_f, n_p), -1, dtype=np.int32)
    glance_of = np.full((n_f, n_p), -1, dtype=np.int32)
    for p, gt in enumerate(day.gt_ids):
        ids, n_glances = glance_ids(stamps, vis.face_visible[:, p], cfg.glance_gap_s)
        if n_glances == 0:
            continue
        pool = identities[gt].day_photos[0 if day.day == 1 else 1]
        picks = np.asarray(pool, dtype=np.int32)[rng_face.integers(len(pool), size=n_glances)]
        seen = ids >= 0
        photo_of[seen, p] = picks[ids[seen]] + photo_offsets[gt]
        glance_of[seen, p] = ids[seen] + glance_counter[0]
        glance_counter[0] += n_glances
    angle = vis.face_angle_deg
    rng_m = vis.range_m
    p_face = cfg.face_detect_probability * (1.0 - 0.3 * np.clip((angle - 30.0) / 20.0, 0.0, 1.0)) * (
        1.0 - 0.3 * np.clip((rng_m - 3.5) / 1.0, 0.0, 1.0))
    face_found = detected & vis.face_visible & (rng_face.random((n_f, n_p)) < p_face)
    f_idx, p_idx = np.nonzero(detected)
    n = f_idx.size
    horiz = np.hypot(*(xy[f_idx, p_idx] - camera.position[:2]).T) if n else np.zeros(0)
    std = cfg.position_noise_base_m + cfg.position_noise_per_m * horiz
    pos = np.zeros((n, 3))
    pos[:, :2] = xy[f_idx, p_idx] + camera_bias + rng_det.normal(size=(n, 2)) * std[:, None]
    height = heights[p_idx] + cfg.height_noise_m * rng_det.normal(size=n)
    gt = np.asarray(day.gt_ids, dtype=np.int32)[p_idx]
    has_face = face_found[f_idx, p_idx]
    # faces: embedding of a variant allowed at this range (+ noise); detector score and quality
    fi = np.flatnonzero(has_face)
    photos_flat = [ph for ident in identities for ph in ident.photos]
    valid_cache: dict[int, list[list[int]]] = {}
    buckets = _range_bucket(rng_m[f_idx[fi], p_idx[fi]])
    picks_u = rng_face.random(fi.size)
    embeddings = np.empty((fi.size, EMBEDDING_DIM), dtype=np.float32)
    variants = np.empty(fi.size, dtype=np.int16)
    face_photo = photo_of[f_idx[fi], p_idx[fi]]
    for k in range(fi.size):
        ph = int(face_photo[k])
        valid = valid_cache.get(ph)
        if valid is None:
            valid = valid_cache[ph] = _valid_variants(photos_flat[ph])
        choices = valid[int(buckets[k])]
        v = choices[min(int(picks_u[k] * len(choices)), len(choices) - 1)]
        variants[k] = v
        embeddings[k] = photos_flat[ph].embeddings[v]
    if fi.size and cfg.embedding_noise_std > 0:
        embeddings += (cfg.embedding_noise_std * rng_face.normal(size=embeddings.shape)).astype(np.float32)
    face_angle = angle[f_idx[fi], p_idx[fi]]
    face_range = rng_m[f_idx[fi], p_idx[fi]]
    score = np.clip(0.93 - 0.002 * face_angle - 0.02 * face_range + 0.03 * rng_face.normal(size=fi.size), 0.6, 0.99)
    eye_px = _KINECT_FX_PX * _EYE_DISTANCE_M / np.maximum(face_range, 0.1) * np.cos(np.radians(face_angle))
    qcfg = FaceQualityConfig()
    quality = np.array([face_quality(float(s), float(e), float(a), qcfg) for s, e, a in
                        zip(score, eye_px, face_angle, strict=True)], dtype=np.float32)
    _append(cols, f_idx, gt, pos, std, height, has_face, embeddings, score, quality, face_photo,
            glance_of[f_idx[fi], p_idx[fi]], variants)
    # false positives: clutter somewhere in the camera's view, never with a face
    n_fp = rng_fp.poisson(cfg.false_positives_per_frame, size=n_f)
    fp_frames = np.repeat(np.arange(n_f), n_fp)
    if fp_frames.size:
        m = fp_frames.size
        hfov = math.atan2(camera.intrinsics.width / 2.0, camera.intrinsics.fx)
        yaw = camera.xyz_rpy[5]
        dist = rng_fp.uniform(1.0, 0.8 * cfg.visibility.max_range_m, size=m)
        bearing = yaw + rng_fp.uniform(-hfov, hfov, size=m)
        fp_xy = camera.position[:2] + dist[:, None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=1)
        keep = world.room.contains(fp_xy)
        m = int(keep.sum())
        fp_pos = np.zeros((m, 3))
        fp_pos[:, :2] = fp_xy[keep]
        fp_std = (cfg.position_noise_base_m + cfg.position_noise_per_m * dist[keep]).astype(np.float32)
        _append(cols, fp_frames[keep], np.full(m, -1, np.int32), fp_pos, fp_std,
                rng_fp.uniform(1.0, 2.0, size=m), np.zeros(m, bool), np.zeros((0, EMBEDDING_DIM), np.float32),
                np.zeros(0), np.zeros(0), np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, np.int16))
    return cols


def _append(cols: _Columns, frame: NDArray[Any], gt: NDArray[Any], pos: NDArray[Any], std: NDArray[Any],
            height: NDArray[Any], has_face: NDArray[Any], emb: NDArray[Any], score: NDArray[Any],
            quality: NDArray[Any], photo: NDArray[Any], glance: NDArray[Any], variant: NDArray[Any]) -> None:
    cols.frame.append(np.asarray(frame, dtype=np.int64))
    cols.gt.append(np.asarray(gt, dtype=np.int32))
    cols.position.append(np.asarray(pos, dtype=np.float64).reshape(-1, 3))
    cols.std.append(np.asarray(std, dtype=np.float32))
    cols.height.append(np.asarray(height, dtype=np.float32))
    cols.has_face.append(np.asarray(has_face, dtype=bool))
    cols.embedding.append(np.asarray(emb, dtype=np.float32).reshape(-1, EMBEDDING_DIM))
    cols.face_score.append(np.asarray(score, dtype=np.float32))
    cols.face_quality.append(np.asarray(quality, dtype=np.float32))
    cols.face_photo.append(np.asarray(photo, dtype=np.int32))
    cols.face_glance.append(np.asarray(glance, dtype=np.int32))
    cols.face_variant.append(np.asarray(variant, dtype=np.int16))


def _assemble(per_camera: list[tuple[int, NDArray[np.float64], _Columns]], seed: int) -> _FrameTable:
    """Merge the cameras' columns into one frame table in stamp order, detections shuffled within frames."""
    frame_cam, frame_stamp, frame_key = [], [], []
    det_parts: dict[str, list[NDArray[Any]]] = {k: [] for k in ("frame", "gt", "position", "std", "height", "face")}
    face_parts: dict[str, list[NDArray[Any]]] = {k: [] for k in ("embedding", "score", "quality", "photo", "glance",
                                                                  "variant")}
    n_frames = 0
    n_faces = 0
    for cam_index, stamps, cols in per_camera:
        frame_cam.append(np.full(stamps.size, cam_index, dtype=np.int16))
        frame_stamp.append(stamps)
        frame_key.append(np.arange(stamps.size) + n_frames)
        for i in range(len(cols.frame)):
            det_parts["frame"].append(cols.frame[i] + n_frames)
            det_parts["gt"].append(cols.gt[i])
            det_parts["position"].append(cols.position[i])
            det_parts["std"].append(cols.std[i])
            det_parts["height"].append(cols.height[i])
            face_row = np.full(cols.has_face[i].size, -1, dtype=np.int64)
            k = int(cols.has_face[i].sum())
            face_row[cols.has_face[i]] = np.arange(k) + n_faces
            n_faces += k
            det_parts["face"].append(face_row)
            face_parts["embedding"].append(cols.embedding[i])
            face_parts["score"].append(cols.face_score[i])
            face_parts["quality"].append(cols.face_quality[i])
            face_parts["photo"].append(cols.face_photo[i])
            face_parts["glance"].append(cols.face_glance[i])
            face_parts["variant"].append(cols.face_variant[i])
        n_frames += stamps.size
    cam = np.concatenate(frame_cam) if frame_cam else np.zeros(0, np.int16)
    stamp = np.concatenate(frame_stamp) if frame_stamp else np.zeros(0)
    order = np.lexsort((cam, stamp))  # by stamp, then camera
    new_index = np.empty(order.size, dtype=np.int64)
    new_index[order] = np.arange(order.size)

    def cat(parts: list[NDArray[Any]], dtype: Any, width: int = 0) -> NDArray[Any]:
        if parts:
            return np.concatenate(parts).astype(dtype)
        return np.zeros((0, width) if width else 0, dtype=dtype)

    det_frame = new_index[cat(det_parts["frame"], np.int64)]
    shuffle = _rng(seed, 99).random(det_frame.size)
    det_order = np.lexsort((shuffle, det_frame))
    det = {
        "position": cat(det_parts["position"], np.float64, 3)[det_order],
        "std_m": cat(det_parts["std"], np.float32)[det_order],
        "height_m": cat(det_parts["height"], np.float32)[det_order],
        "gt_id": cat(det_parts["gt"], np.int32)[det_order],
    }
    face_row = cat(det_parts["face"], np.int64)[det_order]
    # renumber faces in detection order
    has = face_row >= 0
    face_order = face_row[has]
    det_face = np.full(face_row.size, -1, dtype=np.int32)
    det_face[has] = np.arange(face_order.size, dtype=np.int32)
    det["face"] = det_face
    face = {
        "embedding": cat(face_parts["embedding"], np.float32, EMBEDDING_DIM)[face_order],
        "score": cat(face_parts["score"], np.float32)[face_order],
        "quality": cat(face_parts["quality"], np.float32)[face_order],
        "photo": cat(face_parts["photo"], np.int32)[face_order],
        "glance": cat(face_parts["glance"], np.int32)[face_order],
        "variant": cat(face_parts["variant"], np.int16)[face_order],
    }
    counts = np.bincount(det_frame, minlength=order.size)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return _FrameTable(cam[order], stamp[order], offsets, det, face)


def _pixel_camera_frames(
    cfg: SimConfig, world: World, day: _Day, per_cam_stamps: list[NDArray[np.float64]],
    identities: list[IdentityPhotos], photo_offsets: list[int], heights: NDArray[np.float64],
    bank: PhotoBank, glance_counter: list[int], log: TextIO | None, frames_done: list[int], frames_total: int,
) -> list[_Columns]:
    """Render every camera frame of one day and run the real camera pipeline on it."""
    from scipy.optimize import linear_sum_assignment

    from face_reid_camera.faces.photos import read_photo
    from face_reid_camera.pipeline import CameraPipeline, CameraPipelineConfig
    from face_reid_master.sim.renderer import SyntheticPerson, crop_face_for_rendering, render_scene

    photos_flat = [ph for ident in identities for ph in ident.photos]
    crops: dict[int, NDArray[np.uint8]] = {}

    def crop_of(photo: int) -> NDArray[np.uint8]:
        if photo not in crops:
            ph = photos_flat[photo]
            crops[photo] = crop_face_for_rendering(read_photo(bank.faces_dir / ph.rel_path), ph.box_xywh)
        return crops[photo]

    embedder = bank.photo_embedder
    look = _rng(cfg.seed, _S_LOOK, day.day)
    clothes = {gt: (tuple(int(c) for c in look.integers(20, 230, 3)), tuple(int(c) for c in look.integers(20, 120, 3)),
                    tuple(int(c) for c in look.integers(10, 90, 3))) for gt in day.gt_ids}
    floor = float(max(world.room.width_m, world.room.depth_m) + 4.0)
    out: list[_Columns] = []
    step = max(1, frames_total // 10)
    for cam_index, stamps in enumerate(per_cam_stamps):
        camera = world.cameras[cam_index]
        rng_face = _rng(cfg.seed, _S_FACES, day.day, cam_index)
        pipeline = CameraPipeline(CameraPipelineConfig(camera_id=camera.camera_id), camera.pose,
                                  embedder.detector, embedder.embedder)
        cols = _Columns()
        out.append(cols)
        if stamps.size == 0:
            continue
        xy, facing = sample_trajectories(day.trajectories, stamps)
        in_room = world.room.contains(xy)
        vis = camera_visibility(camera, xy, facing, heights, in_room, cfg.visibility)
        n_p = len(day.gt_ids)
        photo_of = np.full((stamps.size, n_p), -1, dtype=np.int32)
        glance_of = np.full((stamps.size, n_p), -1, dtype=np.int32)
        for p, gt in enumerate(day.gt_ids):
            ids, n_glances = glance_ids(stamps, vis.face_visible[:, p], cfg.glance_gap_s)
            if n_glances:
                pool = identities[gt].day_photos[0 if day.day == 1 else 1]
                picks = np.asarray(pool, dtype=np.int32)[rng_face.integers(len(pool), size=n_glances)]
                seen = ids >= 0
                photo_of[seen, p] = picks[ids[seen]] + photo_offsets[gt]
                glance_of[seen, p] = ids[seen] + glance_counter[0]
                glance_counter[0] += n_glances
        for f in range(stamps.size):
            people, index = [], []
            for p, gt in enumerate(day.gt_ids):
                if not in_room[f, p]:
                    continue
                face = crop_of(int(photo_of[f, p])) if photo_of[f, p] >= 0 else None
                body, legs, hair = clothes[gt]
                people.append(SyntheticPerson(float(xy[f, p, 0]), float(xy[f, p, 1]), float(heights[p]),
                                              float(facing[f, p]), face_image_bgr=face, body_color_bgr=body,
                                              legs_color_bgr=legs, hair_color_bgr=hair))
                index.append(p)
            frame = render_scene(people, camera.intrinsics, camera.pose,
                                 rng=_rng(cfg.seed, _S_RENDER, day.day, cam_index, f),
                                 max_face_angle_deg=cfg.visibility.max_face_angle_deg, floor_size_m=floor,
                                 max_range_m=cfg.visibility.max_range_m)  # the depth range of the world model
            depth = frame.depth_mm.astype(np.float32) / np.float32(1000.0)
            depth[frame.depth_mm == 0] = np.nan
            result = pipeline.process(frame.rgb_bgr, depth, camera.intrinsics)
            dets = result.people
            gt_ids = np.full(len(dets), -1, dtype=np.int32)
            matched_p = np.full(len(dets), -1, dtype=np.int64)
            if dets and index:
                det_xy = np.array([d.position_world[:2] for d in dets])
                true_xy = xy[f, index]
                cost = np.linalg.norm(det_xy[:, None] - true_xy[None], axis=2)
                rows, cols_ = linear_sum_assignment(cost)
                for r, c in zip(rows, cols_, strict=True):
                    if cost[r, c] <= 0.5:
                        matched_p[r] = index[c]
                        gt_ids[r] = day.gt_ids[index[c]]
            has_face = np.array([d.face is not None for d in dets], dtype=bool)
            fi = np.flatnonzero(has_face)
            emb = np.array([dets[i].face.embedding for i in fi], dtype=np.float32).reshape(-1, EMBEDDING_DIM)  # type: ignore[union-attr]
            score = np.array([dets[i].face.detection.score for i in fi], dtype=np.float32)  # type: ignore[union-attr]
            quality = np.array([dets[i].face.quality for i in fi], dtype=np.float32)  # type: ignore[union-attr]
            photo = np.array([photo_of[f, matched_p[i]] if matched_p[i] >= 0 else -1 for i in fi], dtype=np.int32)
            glance = np.array([glance_of[f, matched_p[i]] if matched_p[i] >= 0 else -1 for i in fi], dtype=np.int32)
            _append(cols, np.full(len(dets), f), gt_ids,
                    np.array([d.position_world for d in dets]).reshape(-1, 3),
                    np.array([d.position_std_m for d in dets]), np.array([d.height_m for d in dets]),
                    has_face, emb, score, quality, photo, glance, np.full(fi.size, -1, np.int16))
            frames_done[0] += 1
            if log is not None and (frames_done[0] % step == 0 or frames_done[0] == frames_total):
                log.write(f"  rendered + processed {frames_done[0]}/{frames_total} frames\n")
                log.flush()
    return out


def simulate(faces_dir: str | Path, config: SimConfig, cache_path: str | Path | None = None,
             log: TextIO | None = None, bank: PhotoBank | None = None) -> SimResult:
    """Run a scenario. Raises InsufficientFacesError for an empty / too small faces folder."""
    cfg = config

    def say(message: str) -> None:
        if log is not None:
            log.write(message + "\n")
            log.flush()

    t0 = time.perf_counter()
    bank = bank if bank is not None else PhotoBank(faces_dir, cache_path, cfg.min_photos_per_identity, log)
    n_day1, n_new = cfg.num_people, cfg.num_new_people
    say(f"choosing {n_day1 + n_new} identities in {bank.faces_dir} ({len(bank.identity_files)} folders)")
    identities = bank.choose(n_day1 + n_new, _rng(cfg.seed, _S_IDENTITIES))
    bank.save_cache()
    say(f"photos ready in {time.perf_counter() - t0:.1f} s ({bank.embedded_now} embedded now, the rest cached; "
        f"skipped {len(bank.skipped_unreadable)} unreadable, {len(bank.skipped_no_face)} without a face)")
    photo_offsets = list(np.cumsum([0] + [len(i.photos) for i in identities[:-1]]).astype(int))
    room = Room(*cfg.room_size_m) if cfg.room_size_m is not None else room_size_for(cfg.num_cameras)
    world = make_world(cfg.num_cameras, _rng(cfg.seed, _S_WORLD), room=room)
    rate = cfg.frame_rate_hz
    phases = _rng(cfg.seed, _S_PHASE).uniform(0.0, 1.0 / rate, size=cfg.num_cameras)
    bias_rng = _rng(cfg.seed, _S_CAMERA, 0)
    camera_bias = [bias_rng.normal(size=2) * cfg.calibration_error_m / math.sqrt(2.0) for _ in world.cameras]
    heights_all = _rng(cfg.seed, _S_MOTION, 0).uniform(*cfg.motion.height_range_m, size=len(identities))

    days = [_Day(1, 0.0, list(range(n_day1)), [])]
    if cfg.second_day:
        keep = sorted(int(i) for i in _rng(cfg.seed, _S_IDENTITIES, 2).permutation(n_day1)[: n_day1 - n_new])
        days.append(_Day(2, cfg.duration_s + cfg.day_gap_s, keep + list(range(n_day1, n_day1 + n_new)), []))
    for day in days:
        for gt in day.gt_ids:
            day.trajectories.append(plan_trajectory(world, _rng(cfg.seed, _S_MOTION, day.day, gt + 1), cfg.duration_s,
                                                    cfg.motion, start_s=day.start_s, height_m=float(heights_all[gt])))

    per_camera: list[tuple[int, NDArray[np.float64], _Columns]] = []
    glance_counter = [0]
    t1 = time.perf_counter()
    frames_total = sum(_camera_stamps(d.start_s, cfg.duration_s, rate, float(ph)).size for d in days for ph in phases)
    say(f"simulating {len(days)} day(s) x {cfg.duration_s:g} s, {cfg.num_cameras} cameras at {rate:g} Hz "
        f"({frames_total} camera frames, level {cfg.level})")
    frames_done = [0]
    for day in days:
        heights = heights_all[day.gt_ids]
        stamps = [_camera_stamps(day.start_s, cfg.duration_s, rate, float(ph)) for ph in phases]
        if cfg.level == "feature":
            for c in range(cfg.num_cameras):
                cols = _feature_camera_day(cfg, world, c, day, stamps[c], identities, photo_offsets, heights,
                                           camera_bias[c], glance_counter)
                per_camera.append((c, stamps[c], cols))
        else:
            cols_list = _pixel_camera_frames(cfg, world, day, stamps, identities, photo_offsets, heights, bank,
                                             glance_counter, log, frames_done, frames_total)
            per_camera.extend((c, stamps[c], cols) for c, cols in enumerate(cols_list))
    table = _assemble(per_camera, cfg.seed)
    say(f"camera frames done in {time.perf_counter() - t1:.1f} s: {table.stamp_s.size} frames, "
        f"{table.det['gt_id'].size} detections, {table.face['score'].size} faces")
    gt_arrays, loss_info = _ground_truth(cfg, world, days, heights_all)
    document = _document(cfg, bank, world, identities, photo_offsets, days, heights_all, phases, table, gt_arrays,
                         loss_info, glance_counter[0])
    return SimResult(document, table, gt_arrays)


def _ground_truth(cfg: SimConfig, world: World, days: list[_Day], heights_all: NDArray[np.float64]
                  ) -> tuple[dict[str, NDArray[Any]], list[dict[str, Any]]]:
    """Trajectories and visibility sampled at ``ground_truth_rate_hz``, and the losses per day."""
    n_id, n_cam = heights_all.size, len(world.cameras)
    parts_t, parts_day, parts_xy, parts_fac, parts_room, parts_view, parts_face = [], [], [], [], [], [], []
    loss_info = []
    for day in days:
        t = day.start_s + np.arange(0.0, cfg.duration_s, 1.0 / cfg.ground_truth_rate_hz)
        xy, facing = sample_trajectories(day.trajectories, t)
        in_room = world.room.contains(xy)
        heights = heights_all[day.gt_ids]
        view = np.zeros((t.size, len(day.gt_ids), n_cam), dtype=bool)
        face = np.zeros_like(view)
        for c, camera in enumerate(world.cameras):
            vis = camera_visibility(camera, xy, facing, heights, in_room, cfg.visibility)
            view[:, :, c], face[:, :, c] = vis.detectable, vis.face_visible
        losses = count_losses(t, view.any(axis=2).T, cfg.loss_gap_s)
        loss_info.append({
            "day": day.day,
            "losses": losses.total_losses,
            "visible_segments": losses.total_segments,
            "losses_per_person": {str(gt): int(n) for gt, n in zip(day.gt_ids, losses.losses, strict=True)},
            "segments": {str(gt): [[round(a, 3), round(b, 3)] for a, b in seg]
                         for gt, seg in zip(day.gt_ids, losses.segments, strict=True)},
            "exits": int(((~in_room[1:]) & in_room[:-1]).sum()),
            "in_view_fraction": round(float(view.any(axis=2).mean()), 4),
            "face_visible_fraction": round(float(face.any(axis=2).mean()), 4),
        })
        full_xy = np.full((n_id, t.size, 2), np.nan, dtype=np.float32)
        full_fac = np.full((n_id, t.size), np.nan, dtype=np.float32)
        full_room = np.zeros((n_id, t.size), dtype=bool)
        full_view = np.zeros((n_id, t.size, n_cam), dtype=bool)
        full_face = np.zeros_like(full_view)
        ids = np.asarray(day.gt_ids)
        full_xy[ids] = xy.transpose(1, 0, 2)
        full_fac[ids] = facing.T
        full_room[ids] = in_room.T
        full_view[ids] = view.transpose(1, 0, 2)
        full_face[ids] = face.transpose(1, 0, 2)
        parts_t.append(t)
        parts_day.append(np.full(t.size, day.day, dtype=np.int8))
        parts_xy.append(full_xy)
        parts_fac.append(full_fac)
        parts_room.append(full_room)
        parts_view.append(full_view)
        parts_face.append(full_face)
    arrays = {
        "t_s": np.concatenate(parts_t),
        "day": np.concatenate(parts_day),
        "gt_id": np.arange(n_id, dtype=np.int32),
        "xy": np.concatenate(parts_xy, axis=1),
        "facing_rad": np.concatenate(parts_fac, axis=1),
        "in_room": np.concatenate(parts_room, axis=1),
        "in_view": np.concatenate(parts_view, axis=1),
        "face_visible": np.concatenate(parts_face, axis=1),
    }
    return arrays, loss_info


def _document(cfg: SimConfig, bank: PhotoBank, world: World, identities: list[IdentityPhotos],
              photo_offsets: list[int], days: list[_Day], heights: NDArray[np.float64], phases: NDArray[np.float64],
              table: _FrameTable, gt: dict[str, NDArray[Any]], loss_info: list[dict[str, Any]], n_glances: int
              ) -> dict[str, Any]:
    photos = []
    for ident, offset in zip(identities, photo_offsets, strict=True):
        for k, ph in enumerate(ident.photos):
            photos.append({"index": int(offset + k), "identity": ident.name, "path": ph.rel_path})
    ident_docs = []
    for gt_id, (ident, offset) in enumerate(zip(identities, photo_offsets, strict=True)):
        present = [d.day for d in days if gt_id in d.gt_ids]
        ident_docs.append({
            "gt_id": gt_id,
            "name": ident.name,
            "height_m": round(float(heights[gt_id]), 4),
            "days": present,
            "photos": {str(d): [int(offset + i) for i in ident.day_photos[0 if d == 1 else 1]] for d in present},
        })
    n_det = int(table.det["gt_id"].size)
    summary = {
        "duration_s": cfg.duration_s,
        "days": len(days),
        "people_per_day": cfg.num_people,
        "identities": len(identities),
        "cameras": len(world.cameras),
        "frames": int(table.stamp_s.size),
        "detections": n_det,
        "false_positives": int((table.det["gt_id"] < 0).sum()),
        "face_detections": int(table.face["score"].size),
        "glances": int(n_glances),
        "losses": int(sum(d["losses"] for d in loss_info)),
        "visible_segments": int(sum(d["visible_segments"] for d in loss_info)),
        "coverage_fraction": round(coverage_fraction(world, cfg.visibility), 4),
        "per_day": loss_info,
        "skipped_unreadable": sorted(set(bank.skipped_unreadable)),
        "skipped_no_face": sorted(set(bank.skipped_no_face)),
        "identities_with_too_few_photos": sorted(set(bank.too_few_photos)),
    }
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "generator": "face-reid-sim",
        "level": cfg.level,
        "seed": int(cfg.seed),
        "faces_dir": str(bank.faces_dir),
        "parameters": cfg.to_json(),
        "room": {"width_m": world.room.width_m, "depth_m": world.room.depth_m},
        "doors": [{"centre_xy": [round(float(v), 4) for v in d.centre_xy],
                   "inward_normal": [float(v) for v in d.inward_normal], "width_m": d.width_m} for d in world.doors],
        "cameras": [{
            "camera_id": c.camera_id,
            "xyz_rpy": [round(float(v), 6) for v in c.xyz_rpy],
            "rotation": np.round(c.pose.rotation, 9).tolist(),
            "translation": np.round(c.pose.translation, 9).tolist(),
            "intrinsics": {"fx": c.intrinsics.fx, "fy": c.intrinsics.fy, "cx": c.intrinsics.cx, "cy": c.intrinsics.cy,
                           "width": c.intrinsics.width, "height": c.intrinsics.height},
            "frame_phase_s": round(float(ph), 9),
        } for c, ph in zip(world.cameras, phases, strict=True)],
        "photos": photos,
        "identities": ident_docs,
        "days": [{"day": d.day, "start_s": d.start_s, "end_s": d.start_s + cfg.duration_s, "gt_ids": d.gt_ids}
                 for d in days],
        "summary": summary,
    }


# ---------------------------------------------------------------------------------------------------
# Files


def _write_npz(path: Path, arrays: dict[str, NDArray[Any]]) -> None:
    """An uncompressed .npz with fixed zip timestamps (byte-identical for identical arrays), atomically."""
    tmp = path.with_name(path.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())
    os.replace(tmp, path)


def write_scenario(result: SimResult, out_dir: str | Path) -> Path:
    """Write scenario.json, frames.npz and ground_truth.npz into ``out_dir`` (created if needed)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = result.frames
    arrays = {
        "frame_camera": table.camera, "frame_stamp_s": table.stamp_s, "frame_offsets": table.offsets,
        "det_position": table.det["position"], "det_std_m": table.det["std_m"], "det_height_m": table.det["height_m"],
        "det_gt_id": table.det["gt_id"], "det_face": table.det["face"],
        "face_embedding": table.face["embedding"], "face_score": table.face["score"],
        "face_quality": table.face["quality"], "face_photo": table.face["photo"], "face_glance": table.face["glance"],
        "face_variant": table.face["variant"],
    }
    _write_npz(out / "frames.npz", arrays)
    _write_npz(out / "ground_truth.npz", result.ground_truth)
    tmp = out / "scenario.json.tmp"
    tmp.write_text(json.dumps(result.document, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, out / "scenario.json")
    return out


@dataclass(frozen=True)
class CameraSpec:
    """A camera of a loaded scenario."""

    camera_id: str
    intrinsics: CameraIntrinsics
    pose: CameraPose
    xyz_rpy: tuple[float, ...]


@dataclass(frozen=True)
class GroundTruth:
    """True state sampled on a regular grid per day (see the module doc for shapes)."""

    t_s: NDArray[np.float64]
    day: NDArray[np.int8]
    gt_id: NDArray[np.int32]
    xy: NDArray[np.float32]
    facing_rad: NDArray[np.float32]
    in_room: NDArray[np.bool_]
    in_view: NDArray[np.bool_]
    face_visible: NDArray[np.bool_]


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario: the frames as master-core records in stamp order, plus parallel ground truth.

    ``frame_gt_ids[i][j]`` is the true person (gt_id, -1 = false positive) of ``frames[i].people[j]``;
    ``frame_face_photos[i][j]`` the photo index its face came from (-1: no face / unknown).
    """

    directory: Path
    document: dict[str, Any]
    cameras: tuple[CameraSpec, ...]
    frames: list[CameraFrameRecord]
    frame_gt_ids: list[NDArray[np.int32]]
    frame_face_photos: list[NDArray[np.int32]]
    ground_truth: GroundTruth

    @property
    def level(self) -> str:
        return str(self.document["level"])

    @property
    def seed(self) -> int:
        return int(self.document["seed"])

    @property
    def identities(self) -> list[dict[str, Any]]:
        return list(self.document["identities"])

    @property
    def days(self) -> list[dict[str, Any]]:
        return list(self.document["days"])

    @property
    def summary(self) -> dict[str, Any]:
        return dict(self.document["summary"])


_FRAME_KEYS = ("frame_camera", "frame_stamp_s", "frame_offsets", "det_position", "det_std_m", "det_height_m",
               "det_gt_id", "det_face", "face_embedding", "face_score", "face_quality", "face_photo", "face_glance",
               "face_variant")
_GT_KEYS = ("t_s", "day", "gt_id", "xy", "facing_rad", "in_room", "in_view", "face_visible")


def _read_npz(path: Path, keys: Sequence[str]) -> dict[str, NDArray[Any]]:
    if not path.is_file():
        raise ScenarioFormatError(f"scenario file {path} is missing")
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in keys if k not in data.files]
            if missing:
                raise ScenarioFormatError(f"{path} lacks arrays {missing}")
            return {k: data[k] for k in keys}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        if isinstance(exc, ScenarioFormatError):
            raise
        raise ScenarioFormatError(f"{path} is not a readable npz file: {exc}") from exc


def load_scenario_document(directory: str | Path) -> dict[str, Any]:
    """The checked ``scenario.json`` of a scenario directory; ScenarioFormatError if missing or foreign."""
    base = Path(directory)
    doc_path = base / "scenario.json"
    if not doc_path.is_file():
        raise ScenarioFormatError(f"{base} is not a scenario directory (no scenario.json)")
    try:
        doc = json.loads(doc_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ScenarioFormatError(f"{doc_path} is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
        raise ScenarioFormatError(f"{doc_path} is not a {FORMAT_NAME} document")
    if doc.get("version") != FORMAT_VERSION:
        raise ScenarioFormatError(f"{doc_path} has format version {doc.get('version')!r}, this reader knows "
                                  f"{FORMAT_VERSION}")
    if not isinstance(doc.get("identities"), list):
        raise ScenarioFormatError(f"{doc_path} has no identities list")
    return doc


def load_scenario(directory: str | Path) -> Scenario:
    """Read a scenario directory written by :func:`write_scenario`; ScenarioFormatError if it is broken."""
    base = Path(directory)
    doc_path = base / "scenario.json"
    doc = load_scenario_document(base)
    try:
        cameras = tuple(
            CameraSpec(c["camera_id"], CameraIntrinsics(**c["intrinsics"]),
                       CameraPose(np.array(c["rotation"], dtype=np.float64),
                                  np.array(c["translation"], dtype=np.float64)),
                       tuple(float(v) for v in c["xyz_rpy"]))
            for c in doc["cameras"])
        n_ids = len(doc["identities"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ScenarioFormatError(f"{doc_path} has malformed cameras/identities: {exc}") from exc
    a = _read_npz(base / "frames.npz", _FRAME_KEYS)
    n_f, n_d, n_e = a["frame_stamp_s"].size, a["det_gt_id"].size, a["face_score"].size
    offsets = a["frame_offsets"]
    problems = []
    if a["frame_camera"].shape != (n_f,) or offsets.shape != (n_f + 1,):
        problems.append("frame arrays disagree in length")
    elif offsets[0] != 0 or offsets[-1] != n_d or np.any(np.diff(offsets) < 0):
        problems.append("frame_offsets are not a monotone 0..detections partition")
    if n_f and (a["frame_camera"].min() < 0 or a["frame_camera"].max() >= len(cameras)):
        problems.append("frame_camera index out of range")
    if n_f > 1 and np.any(np.diff(a["frame_stamp_s"]) < 0):
        problems.append("frames are not in stamp order")
    if a["det_position"].shape != (n_d, 3) or any(a[k].shape != (n_d,) for k in ("det_std_m", "det_height_m",
                                                                                   "det_face")):
        problems.append("detection arrays disagree in shape")
    if a["face_embedding"].shape != (n_e, EMBEDDING_DIM) or any(
            a[k].shape != (n_e,) for k in ("face_quality", "face_photo", "face_glance", "face_variant")):
        problems.append("face arrays disagree in shape")
    if n_d and (a["det_face"].max() >= n_e or a["det_face"].min() < -1 or a["det_gt_id"].max() >= n_ids
                or a["det_gt_id"].min() < -1):
        problems.append("det_face / det_gt_id out of range")
    if not (np.isfinite(a["det_position"]).all() and np.isfinite(a["face_embedding"]).all()
            and np.isfinite(a["frame_stamp_s"]).all()):
        problems.append("non-finite positions, stamps or embeddings")
    if problems:
        raise ScenarioFormatError(f"{base / 'frames.npz'}: " + "; ".join(problems))
    g = _read_npz(base / "ground_truth.npz", _GT_KEYS)
    ground_truth = GroundTruth(**g)
    frames: list[CameraFrameRecord] = []
    gt_ids: list[NDArray[np.int32]] = []
    face_photos: list[NDArray[np.int32]] = []
    camera_ids = [c.camera_id for c in cameras]
    pos, std, height, det_face, det_gt = (a["det_position"], a["det_std_m"].tolist(), a["det_height_m"].tolist(),
                                          a["det_face"].tolist(), a["det_gt_id"])
    emb, f_score, f_quality, f_photo = a["face_embedding"], a["face_score"].tolist(), a["face_quality"].tolist(), \
        a["face_photo"]
    for i in range(n_f):
        lo, hi = int(offsets[i]), int(offsets[i + 1])
        people = []
        photos = np.full(hi - lo, -1, dtype=np.int32)
        for j in range(lo, hi):
            k = det_face[j]
            if k >= 0:
                people.append(PersonRecord(pos[j], std[j], height[j], emb[k], f_score[k], f_quality[k]))
                photos[j - lo] = f_photo[k]
            else:
                people.append(PersonRecord(pos[j], std[j], height[j]))
        frames.append(CameraFrameRecord(camera_ids[int(a["frame_camera"][i])], float(a["frame_stamp_s"][i]),
                                        tuple(people)))
        gt_ids.append(det_gt[lo:hi])
        face_photos.append(photos)
    return Scenario(base, doc, cameras, frames, gt_ids, face_photos, ground_truth)

