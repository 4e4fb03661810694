"""Face photos of a scenario and the camera's view of them: identity folders embedded with the real models.

Camera-true views (:meth:`PhotoBank.camera_view`, what the simulator's frames carry): a face never shows more
pixels than the camera's geometry gives. A frame's face is its glance's photo after the glance's one of the
``NUM_FRAME_CHANGES`` real image changes (as is, darker, brighter, +-8 deg roll, roll + JPEG), down-sampled
(area) so that its eyes are at most the eye distance the camera delivers (:func:`eye_level`: the photo's
detected landmarks give its own eye distance; the frame's eye distance, continuous, is taken down to a grid
of ``EYE_LEVEL_STEP`` ratios), then re-detected (YuNet, on the small image; the full-size landmarks, scaled,
when YuNet misses it) and re-embedded by the real models. A photo smaller than the geometry gives is used at
its own size (never enlarged). Views are cached per (photo, change, eye level) and embedding space, in memory
and in the optional npz cache, so a long scenario embeds each once. Flips are not used: they change little
and would mirror asymmetric features. One photo of a person is drawn per *glance* (:func:`glance_photos`) and
used for all its frames. Each identity's photos are split in two halves, day 1 / day 2, by a fixed
per-identity shuffle.

Fixed variants (``PhotoBank(variants=True)``, the default): every usable photo is also embedded in
``NUM_VARIANTS`` versions (the changes above and down-sampling to 14, 10 and 9 px between the eyes), the
camera views ``face-reid-fit-likelihood --camera-views`` fits on; the simulator does not use them.
"""

from __future__ import annotations

import math
import zipfile
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO, TypeVar

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.atomic_file import write_npz
from face_reid_camera.common.embedding_spaces import embedder_space, space_dim
from face_reid_camera.tools.eval_faces import HEAD_ROI_SIDE_PER_EYE_DISTANCE, head_roi_for_face
from face_reid_master.sim.visibility import glance_ids

T = TypeVar("T")

__all__ = [
    "EYE_LEVEL_STEP",
    "MIN_EYE_PX",
    "NUM_FRAME_CHANGES",
    "NUM_VARIANTS",
    "IdentityPhotos",
    "InsufficientFacesError",
    "PhotoBank",
    "PhotoVariants",
    "choose_usable",
    "eye_level",
    "glance_photos",
    "level_eye_px",
    "variant_eye_px",
]

# Photo variants (index: change). Re-detected and re-embedded with the real models.
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
_VARIANT_EYE_PX = np.array([spec.get("eye_px", np.inf) for spec in _VARIANT_SPECS])  # inf: the photo's own size
_VARIANT_VERSION = "v4"  # bump when _VARIANT_SPECS, the views or the cached fields change: invalidates the cache
# Camera-true views: the frame-to-frame image changes (the full-size variants 0-4), then the camera's down-sampling.
NUM_FRAME_CHANGES = 5
MIN_EYE_PX = 3.0  # a face whose eyes are closer than this in the image is not a face to any detector
EYE_LEVEL_STEP = 1.06  # eye distances are taken down to MIN_EYE_PX x EYE_LEVEL_STEP^k (at most 6 % fewer pixels)
NATIVE_LEVEL, TOO_SMALL_LEVEL = -1, -2


class InsufficientFacesError(ValueError):
    """The faces folder is empty or has fewer usable identities than the scenario needs."""


@dataclass(frozen=True)
class PhotoVariants:
    """One usable photo: path relative to the faces folder, face box/score, eye distance (px) of the photo's
    face, (NUM_VARIANTS, dim) embeddings of its variants (NaN rows: no face found in that variant, or variants
    not made; row 0, the photo as is, is always valid) and its face's (5, 2) YuNet landmarks."""

    rel_path: str
    box_xywh: NDArray[np.float32]
    score: float
    embeddings: NDArray[np.float32]
    eye_px: float = 0.0
    landmarks: NDArray[np.float32] | None = None


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
    out = _photometric(out, spec, centre)
    if "jpeg" in spec:
        out = _jpeg(out, spec["jpeg"])
    return out


def _photometric(image: NDArray[np.uint8], spec: dict[str, float], centre: NDArray[np.float32]) -> NDArray[np.uint8]:
    """Brightness / contrast and roll about the face centre of a variant spec."""
    out = image
    if "alpha" in spec:
        out = cv2.convertScaleAbs(out, alpha=spec["alpha"], beta=spec.get("beta", 0.0))
    if "rotate_deg" in spec:
        matrix = cv2.getRotationMatrix2D((float(centre[0]), float(centre[1])), spec["rotate_deg"], 1.0)
        out = cv2.warpAffine(out, matrix, (out.shape[1], out.shape[0]), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
    return out


def _jpeg(image: NDArray[np.uint8], quality: float) -> NDArray[np.uint8]:
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    return cv2.imdecode(buf, cv2.IMREAD_COLOR) if ok else image


@dataclass
class ViewStats:
    """What the camera-true views cost: made now (re-embedded), found in the cache, and of the made ones how
    many YuNet re-detected on the small image (the others were aligned on the scaled full-size landmarks)."""

    made: int = 0
    cached: int = 0
    redetected: int = 0


class PhotoBank:
    """Identity folders of a faces directory, embedded on demand (real models) with an optional npz cache.

    ``embedder``: dlib | sface | both (the camera's choice; both = the two rows side by side).
    ``variants``: also embed every photo's ``NUM_VARIANTS`` fixed variants (``face-reid-fit-likelihood
    --camera-views``); the simulator needs only the photo as is and its camera views (:meth:`camera_view`).
    The cache maps ``path|mtime_ns|size|version`` to the photo's status (usable / unreadable / no face), face
    box, score, eye distance, landmarks and variant embeddings, and ``that key|change|eye level`` to a camera
    view's embedding; photos whose file changed are re-embedded. A cache of another embedder space is ignored
    (and overwritten on save).
    """

    _OK, _UNREADABLE, _NO_FACE, _OK_BASE = 0, 1, 2, 3  # _OK_BASE: usable, fixed variants not made

    def __init__(self, faces_dir: str | Path, cache_path: str | Path | None = None,
                 min_photos_per_identity: int = 2, log: TextIO | None = None, embedder: str = "dlib",
                 variants: bool = True) -> None:
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
        self.embedder_choice = embedder
        self.space = embedder_space(embedder)
        self.dim = space_dim(self.space)
        self.variants = bool(variants)
        self.cache_path = Path(cache_path) if cache_path is not None else None
        self.log = log
        self.skipped_unreadable: list[str] = []
        self.skipped_no_face: list[str] = []
        self.too_few_photos: list[str] = []
        self._cache: dict[str, tuple[int, NDArray[np.float32], float, NDArray[np.float32], float,
                                     NDArray[np.float32]]] = {}
        self._views: dict[str, tuple[NDArray[np.float32], bool]] = {}
        self._photo_keys: dict[str, str] = {}  # rel_path -> cache key of the photo's file
        self._images: dict[str, NDArray[np.uint8]] = {}
        self._cache_dirty = False
        self._embedder: Any = None
        self.embedded_now = 0
        self.view_stats = ViewStats()
        if self.cache_path is not None and self.cache_path.is_file():
            self._load_cache()

    @property
    def photo_embedder(self) -> Any:
        """The real :class:`PhotoEmbedder` (YuNet + the chosen embedder), loaded on first use."""
        if self._embedder is None:
            from face_reid_camera.faces.embedder import load_embedder
            from face_reid_camera.faces.photos import PhotoEmbedder

            self._embedder = PhotoEmbedder(embedder=load_embedder(self.embedder_choice))
        return self._embedder

    # --- cache
    def _load_cache(self) -> None:
        assert self.cache_path is not None
        try:
            with np.load(self.cache_path, allow_pickle=False) as data:
                # write_npz stores the 0-d space string as a 1-element array (np.ascontiguousarray)
                space = str(data["space"].reshape(-1)[0]) if "space" in data.files else "dlib_resnet_v1"
                if space != self.space:
                    raise ValueError(f"it holds embeddings of space {space!r}, not {self.space!r}")
                keys = [str(k) for k in data["keys"]]
                status, boxes, scores, embs = data["status"], data["boxes"], data["scores"], data["embeddings"]
                eyes, marks = data["eye_px"], data["landmarks"]
                view_keys = [str(k) for k in data["view_keys"]]
                view_embs, view_found = data["view_embeddings"], data["view_redetected"]
                if embs.shape[1:] != (NUM_VARIANTS, self.dim) or len({len(keys), len(status), len(boxes),
                                                                      len(scores), len(embs), len(eyes),
                                                                      len(marks)}) != 1 \
                        or view_embs.shape != (len(view_keys), self.dim) or view_found.shape != (len(view_keys),):
                    raise ValueError("inconsistent arrays")
                for i, key in enumerate(keys):
                    self._cache[key] = (int(status[i]), boxes[i].astype(np.float32), float(scores[i]),
                                        embs[i].astype(np.float32), float(eyes[i]), marks[i].astype(np.float32))
                for i, key in enumerate(view_keys):
                    self._views[key] = (view_embs[i].astype(np.float32), bool(view_found[i]))
        except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
            self._say(f"ignoring unusable embedding cache {self.cache_path}: {exc}")
            self._cache, self._views = {}, {}

    def save_cache(self) -> None:
        """Write the cache file (atomically) if anything new was embedded."""
        if self.cache_path is None or not self._cache_dirty:
            return
        keys = sorted(self._cache)
        view_keys = sorted(self._views)
        arrays = {
            "keys": np.array(keys, dtype=np.str_),
            "status": np.array([self._cache[k][0] for k in keys], dtype=np.int8),
            "boxes": np.array([self._cache[k][1] for k in keys], dtype=np.float32).reshape(-1, 4),
            "scores": np.array([self._cache[k][2] for k in keys], dtype=np.float32),
            "embeddings": np.array([self._cache[k][3] for k in keys], dtype=np.float32).reshape(
                -1, NUM_VARIANTS, self.dim),
            "eye_px": np.array([self._cache[k][4] for k in keys], dtype=np.float32),
            "landmarks": np.array([self._cache[k][5] for k in keys], dtype=np.float32).reshape(-1, 5, 2),
            "view_keys": np.array(view_keys, dtype=np.str_),
            "view_embeddings": np.array([self._views[k][0] for k in view_keys], dtype=np.float32).reshape(
                -1, self.dim),
            "view_redetected": np.array([self._views[k][1] for k in view_keys], dtype=bool),
            "space": np.array(self.space),
        }
        self.cache_path.parent.mkdir(parents=True, exist_ok=True)
        write_npz(self.cache_path, arrays)
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
    def _embed(self, path: Path) -> tuple[int, NDArray[np.float32], float, NDArray[np.float32], float,
                                          NDArray[np.float32]]:
        from face_reid_camera.faces.photos import PhotoError, read_photo

        nan_box = np.full(4, np.nan, dtype=np.float32)
        nan_marks = np.full((5, 2), np.nan, dtype=np.float32)
        nan_embs = np.full((NUM_VARIANTS, self.dim), np.nan, dtype=np.float32)
        try:
            image = read_photo(path)
        except PhotoError:
            return self._UNREADABLE, nan_box, 0.0, nan_embs, 0.0, nan_marks
        embedder = self.photo_embedder
        base = embedder.embed_photo(image)
        if base is None:
            return self._NO_FACE, nan_box, 0.0, nan_embs, 0.0, nan_marks
        embs = nan_embs.copy()
        embs[0] = base.embedding
        box = np.asarray(base.box_xywh, dtype=np.float32)
        if self.variants:
            centre = box[:2] + box[2:] / 2.0
            for v, spec in enumerate(_VARIANT_SPECS[1:], start=1):
                variant = embedder.embed_photo(_augment(image, spec, base.eye_distance_px, centre))
                if variant is not None:
                    embs[v] = variant.embedding
        status = self._OK if self.variants else self._OK_BASE
        return status, box, float(base.score), embs, float(base.eye_distance_px), np.asarray(base.landmarks,
                                                                                            dtype=np.float32)

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
            if entry is None or (self.variants and entry[0] == self._OK_BASE):
                entry = self._embed(path)
                self._cache[key] = entry
                self._cache_dirty = True
                self.embedded_now += 1
            status, box, score, embs, eye_px, marks = entry
            rel = path.relative_to(self.faces_dir).as_posix()
            if status == self._UNREADABLE:
                self.skipped_unreadable.append(rel)
            elif status == self._NO_FACE:
                self.skipped_no_face.append(rel)
            else:
                self._photo_keys[rel] = key
                photos.append(PhotoVariants(rel, box, score, embs, eye_px, marks))
        if len(photos) < self.min_photos:
            self.too_few_photos.append(name)
            return None
        order = np.random.default_rng(zlib.crc32(name.encode("utf-8"))).permutation(len(photos))
        half = max(1, math.ceil(len(photos) / 2))
        day1 = tuple(sorted(int(i) for i in order[:half]))
        day2 = tuple(sorted(int(i) for i in order[half:])) or day1
        return IdentityPhotos(name, tuple(photos), (day1, day2))

    def choose(self, count: int, rng: np.random.Generator) -> list[IdentityPhotos]:
        """``count`` usable identities in a random order (folders are embedded only as needed; too few folders
        are refused before any is embedded)."""
        if len(self.identity_files) < count:
            raise InsufficientFacesError(
                f"faces folder {self.faces_dir} has {len(self.identity_files)} identity folders with photos, the "
                f"scenario needs {count}: ask for fewer people or add identity folders"
            )
        chosen = choose_usable(sorted(self.identity_files), count, rng, self.load_identity)
        for ident in chosen:
            self._say(f"  identity {ident.name}: {len(ident.photos)} usable photos")
        if len(chosen) < count:
            raise InsufficientFacesError(
                f"faces folder {self.faces_dir} has only {len(chosen)} usable identities (>= {self.min_photos} "
                f"photos with a detectable face), the scenario needs {count}; skipped "
                f"{len(self.skipped_unreadable)} unreadable files and {len(self.skipped_no_face)} photos "
                f"without a face"
            )
        return chosen

    # --- camera-true views
    def camera_view(self, photo: PhotoVariants, change: int, level: int) -> tuple[NDArray[np.float32], bool]:
        """Embedding of ``photo`` after frame change ``change`` (< NUM_FRAME_CHANGES) seen with its eyes at
        :func:`level_eye_px` (``level`` from :func:`eye_level`; NATIVE_LEVEL: the photo's own size), and whether
        YuNet found the face in that view (else it was aligned on the photo's scaled landmarks); cached."""
        if not 0 <= change < NUM_FRAME_CHANGES or level < NATIVE_LEVEL:
            raise ValueError(f"no camera view for change {change}, eye level {level}")
        if level == NATIVE_LEVEL and (change == 0 or np.isfinite(photo.embeddings[change]).all()):
            return photo.embeddings[change], True  # the fixed variant is this very view
        key = f"{self._photo_keys[photo.rel_path]}|{change}|{level}"
        entry = self._views.get(key)
        if entry is None:
            entry = self._views[key] = self._make_view(photo, change, level)
            self._cache_dirty = True
            self.view_stats.made += 1
            self.view_stats.redetected += int(entry[1])
        else:
            self.view_stats.cached += 1
        return entry

    def _image(self, rel_path: str) -> NDArray[np.uint8]:
        from face_reid_camera.faces.photos import read_photo

        image = self._images.get(rel_path)
        if image is None:
            image = self._images[rel_path] = read_photo(self.faces_dir / rel_path)
        return image

    def _make_view(self, photo: PhotoVariants, change: int, level: int) -> tuple[NDArray[np.float32], bool]:
        """Change the photo at full size, down-sample it (area) to the level's eye distance, JPEG if the change
        says so, then detect as the camera does (YuNet on the head ROI, the photo's border replicated around it)
        and embed; when YuNet misses the small face, align on the full-size landmarks carried through the same
        change and scaling."""
        spec = _VARIANT_SPECS[change]
        box = np.asarray(photo.box_xywh, dtype=np.float64)
        centre = box[:2] + box[2:] / 2.0
        marks = np.asarray(photo.landmarks, dtype=np.float64).reshape(5, 2)
        image = _photometric(self._image(photo.rel_path), spec, centre.astype(np.float32))
        if "rotate_deg" in spec:
            matrix = cv2.getRotationMatrix2D((float(centre[0]), float(centre[1])), spec["rotate_deg"], 1.0)
            marks = marks @ matrix[:, :2].T + matrix[:, 2]
        target = level_eye_px(level, photo.eye_px)
        factor = min(1.0, target / photo.eye_px) if photo.eye_px > 0 else 1.0
        h, w = image.shape[:2]
        size = (max(1, round(w * factor)), max(1, round(h * factor)))
        if size != (w, h):
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        if "jpeg" in spec:
            image = _jpeg(image, spec["jpeg"])
        scale = np.array([size[0] / w, size[1] / h])
        marks = (marks + 0.5) * scale - 0.5  # cv2.resize's pixel-centre convention
        box_small = np.concatenate([(box[:2] + 0.5) * scale - 0.5, box[2:] * scale])
        # the camera's detection: YuNet on the head ROI (0.3 m square around the face) resized to its input
        pad = math.ceil(HEAD_ROI_SIDE_PER_EYE_DISTANCE * target)
        pad_x, pad_y = pad, pad
        padded = cv2.copyMakeBorder(image, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
        embedder = self.photo_embedder
        centre_small = box_small[:2] + box_small[2:] / 2.0 + pad
        roi = head_roi_for_face(centre_small, target, padded.shape[1], padded.shape[0])
        found = embedder.detector.detect_in_rois(padded, [roi])[0]
        if found is not None:  # the same face (eyes where the scaled landmarks put them)?
            found_marks = np.asarray(found.landmarks, dtype=np.float64) - pad
            found_eye = float(np.linalg.norm(found_marks[1] - found_marks[0]))
            if np.linalg.norm(found_marks[:2].mean(axis=0) - marks[:2].mean(axis=0)) <= 0.5 * max(target, 1.0) \
                    and 0.6 * target <= found_eye <= 1.6 * target:
                view = embedder.embed_face(padded, found.box_xywh, found.landmarks, found.score)
                return np.asarray(view.embedding, dtype=np.float32), True
        offset = np.array([pad_x, pad_y], dtype=np.float64)
        shifted = marks + offset
        box_padded = np.concatenate([box_small[:2] + offset, box_small[2:]])
        view = embedder.embed_face(padded, box_padded, shifted, photo.score)
        return np.asarray(view.embedding, dtype=np.float32), False


def choose_usable(names: Sequence[str], count: int, rng: np.random.Generator,
                  load: Callable[[str], T | None]) -> list[T]:
    """Up to ``count`` loaded items of ``names`` in a random order, skipping the ones ``load`` refuses (None);
    each name is loaded only when its turn comes, so a large folder costs only what the scenario uses."""
    chosen: list[T] = []
    for i in rng.permutation(len(names)):
        if len(chosen) == count:
            break
        item = load(names[int(i)])
        if item is not None:
            chosen.append(item)
    return chosen


def variant_eye_px(photo: PhotoVariants, variant: int | NDArray[np.integer]) -> NDArray[np.float64]:
    """Eye distance (px) of the face a fixed variant shows: the photo's, or the smaller size it was reduced to."""
    return np.minimum(_VARIANT_EYE_PX[np.asarray(variant)], photo.eye_px if photo.eye_px > 0 else np.inf)


def eye_level(eye_px: NDArray[np.floating], native_eye_px: NDArray[np.floating]) -> NDArray[np.int64]:
    """The camera-true eye level of faces whose eyes the camera shows ``eye_px`` apart, of photos whose own eyes
    are ``native_eye_px`` apart: NATIVE_LEVEL where the photo has no more (never enlarged), TOO_SMALL_LEVEL
    below MIN_EYE_PX (no face), else the largest k with MIN_EYE_PX x EYE_LEVEL_STEP^k <= eye_px."""
    eye = np.asarray(eye_px, dtype=np.float64)
    native = np.broadcast_to(np.asarray(native_eye_px, dtype=np.float64), eye.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.floor(np.log(np.maximum(eye, 1e-9) / MIN_EYE_PX) / math.log(EYE_LEVEL_STEP) + 1e-9)
    k = np.where(np.isfinite(k), k, -1).astype(np.int64)
    below = MIN_EYE_PX * EYE_LEVEL_STEP ** np.maximum(k, 0)
    out = np.where(below >= native, NATIVE_LEVEL, k)
    return np.where(eye < MIN_EYE_PX, TOO_SMALL_LEVEL, out).astype(np.int64)


def level_eye_px(level: int | NDArray[np.integer], native_eye_px: float | NDArray[np.floating]
                 ) -> NDArray[np.float64]:
    """Eye distance (px) a camera view of this level shows (NATIVE_LEVEL: the photo's own; TOO_SMALL_LEVEL: 0)."""
    lv = np.asarray(level, dtype=np.int64)
    native = np.asarray(native_eye_px, dtype=np.float64)
    shown = np.where(lv == NATIVE_LEVEL, native, MIN_EYE_PX * EYE_LEVEL_STEP ** np.maximum(lv, 0))
    return np.where(lv == TOO_SMALL_LEVEL, 0.0, shown)


def glance_photos(stamps: NDArray[np.float64], face_visible: NDArray[np.bool_], gt_ids: list[int], day: int,
                  identities: list[IdentityPhotos], photo_offsets: list[int], glance_gap_s: float,
                  rng: np.random.Generator, glance_counter: list[int]) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
    """Photo index and glance number (F, P) of every frame where a person's face is visible (-1 elsewhere).

    ``face_visible`` (F, P) of one camera at ``stamps``; each glance of person ``gt_ids[p]`` draws one photo of
    the identity's ``day`` half from ``rng``; glances are numbered on from ``glance_counter[0]`` (updated).
    """
    photo_of = np.full(face_visible.shape, -1, dtype=np.int32)
    glance_of = np.full(face_visible.shape, -1, dtype=np.int32)
    for p, gt in enumerate(gt_ids):
        ids, n_glances = glance_ids(stamps, face_visible[:, p], glance_gap_s)
        if n_glances == 0:
            continue
        pool = identities[gt].day_photos[0 if day == 1 else 1]
        picks = np.asarray(pool, dtype=np.int32)[rng.integers(len(pool), size=n_glances)]
        seen = ids >= 0
        photo_of[seen, p] = picks[ids[seen]] + photo_offsets[gt]
        glance_of[seen, p] = ids[seen] + glance_counter[0]
        glance_counter[0] += n_glances
    return photo_of, glance_of
