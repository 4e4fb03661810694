"""Face photos of a scenario and the camera's view of them: identity folders embedded with the real models.

Each usable photo is embedded in ``NUM_VARIANTS`` versions, each a real image change re-detected and
re-embedded by the real models (brightness, +-8 deg rotation, JPEG, and down-sampling to the eye distance a
Kinect gives at 2-3 m and 3.3-4.5 m); a frame takes one variant allowed at its face range, so frames of one
photo differ as real camera frames do. Flips are not used: they change little and would mirror asymmetric
features. One photo of a person is drawn per *glance* (:func:`glance_photos`) and used for all its frames.
Each identity's photos are split in two halves, day 1 / day 2, by a fixed per-identity shuffle.
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

from face_reid_camera.common.embedding_spaces import embedder_space, space_dim
from face_reid_master.sim.scenario_files import write_npz
from face_reid_master.sim.visibility import glance_ids

T = TypeVar("T")

__all__ = [
    "NUM_VARIANTS",
    "IdentityPhotos",
    "InsufficientFacesError",
    "PhotoBank",
    "PhotoVariants",
    "choose_usable",
    "glance_photos",
    "range_bucket",
    "valid_variants",
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
_VARIANT_VERSION = "v2"  # bump when _VARIANT_SPECS or the cached fields change: invalidates cached variants
# Variants a frame may use, by face range (m): near, mid, far.
_RANGE_EDGES_M = (2.0, 3.3)
_RANGE_VARIANTS: tuple[tuple[int, ...], ...] = ((0, 1, 2, 3, 4), (1, 2, 3, 4, 5), (5, 6, 7))


class InsufficientFacesError(ValueError):
    """The faces folder is empty or has fewer usable identities than the scenario needs."""


@dataclass(frozen=True)
class PhotoVariants:
    """One usable photo: path relative to the faces folder, face box/score, eye distance (px) of the photo's
    face, and (NUM_VARIANTS, dim) embeddings of its variants (NaN rows: no face found in that variant; row 0
    is always valid)."""

    rel_path: str
    box_xywh: NDArray[np.float32]
    score: float
    embeddings: NDArray[np.float32]
    eye_px: float = 0.0


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

    ``embedder``: dlib | sface | both (the camera's choice; both = the two rows side by side).
    The cache maps ``path|mtime_ns|size|variant-version`` to the photo's status (usable / unreadable / no
    face), face box, score, eye distance and variant embeddings; photos whose file changed are re-embedded.
    A cache of another embedder space is ignored (and overwritten on save).
    """

    _OK, _UNREADABLE, _NO_FACE = 0, 1, 2

    def __init__(self, faces_dir: str | Path, cache_path: str | Path | None = None,
                 min_photos_per_identity: int = 2, log: TextIO | None = None, embedder: str = "dlib") -> None:
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
        self.cache_path = Path(cache_path) if cache_path is not None else None
        self.log = log
        self.skipped_unreadable: list[str] = []
        self.skipped_no_face: list[str] = []
        self.too_few_photos: list[str] = []
        self._cache: dict[str, tuple[int, NDArray[np.float32], float, NDArray[np.float32], float]] = {}
        self._cache_dirty = False
        self._embedder: Any = None
        self.embedded_now = 0
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
                eyes = data["eye_px"]
                if embs.shape[1:] != (NUM_VARIANTS, self.dim) or len({len(keys), len(status), len(boxes),
                                                                      len(scores), len(embs), len(eyes)}) != 1:
                    raise ValueError("inconsistent arrays")
                for i, key in enumerate(keys):
                    self._cache[key] = (int(status[i]), boxes[i].astype(np.float32), float(scores[i]),
                                        embs[i].astype(np.float32), float(eyes[i]))
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
                -1, NUM_VARIANTS, self.dim),
            "eye_px": np.array([self._cache[k][4] for k in keys], dtype=np.float32),
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
    def _embed(self, path: Path) -> tuple[int, NDArray[np.float32], float, NDArray[np.float32], float]:
        from face_reid_camera.faces.photos import PhotoError, read_photo

        nan_box = np.full(4, np.nan, dtype=np.float32)
        nan_embs = np.full((NUM_VARIANTS, self.dim), np.nan, dtype=np.float32)
        try:
            image = read_photo(path)
        except PhotoError:
            return self._UNREADABLE, nan_box, 0.0, nan_embs, 0.0
        embedder = self.photo_embedder
        base = embedder.embed_photo(image)
        if base is None:
            return self._NO_FACE, nan_box, 0.0, nan_embs, 0.0
        embs = nan_embs.copy()
        embs[0] = base.embedding
        box = np.asarray(base.box_xywh, dtype=np.float32)
        centre = box[:2] + box[2:] / 2.0
        for v, spec in enumerate(_VARIANT_SPECS[1:], start=1):
            variant = embedder.embed_photo(_augment(image, spec, base.eye_distance_px, centre))
            if variant is not None:
                embs[v] = variant.embedding
        return self._OK, box, float(base.score), embs, float(base.eye_distance_px)

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
            status, box, score, embs, eye_px = entry
            rel = path.relative_to(self.faces_dir).as_posix()
            if status == self._UNREADABLE:
                self.skipped_unreadable.append(rel)
            elif status == self._NO_FACE:
                self.skipped_no_face.append(rel)
            else:
                photos.append(PhotoVariants(rel, box, score, embs, eye_px))
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
    """Eye distance (px) of the face a variant shows: the photo's, or the smaller size it was reduced to."""
    return np.minimum(_VARIANT_EYE_PX[np.asarray(variant)], photo.eye_px if photo.eye_px > 0 else np.inf)


def range_bucket(range_m: NDArray[np.float64]) -> NDArray[np.int64]:
    """Range bucket of each face range (m): 0 near, 1 mid, 2 far (the variants a frame may use)."""
    return np.searchsorted(np.asarray(_RANGE_EDGES_M), range_m, side="right").astype(np.int64)


def valid_variants(photo: PhotoVariants) -> list[list[int]]:
    """Per range bucket, the variants of ``photo`` that had a face (fallback: the nearest valid ones)."""
    ok = np.isfinite(photo.embeddings).all(axis=1)
    out = []
    for bucket in _RANGE_VARIANTS:
        chosen = [v for v in bucket if ok[v]]
        if not chosen:
            chosen = [v for v in range(NUM_VARIANTS) if ok[v]][-2:]
        out.append(chosen)
    return out


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
