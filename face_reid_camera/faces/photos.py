"""Face PHOTOS -> 128-d embeddings: gallery photos, identity folders (likelihood fitting, simulator).

One photo gives at most one embedding, of its LARGEST face (a portrait may show bystanders).  Big photos
are shrunk to ``max_side_px`` for detection only (speed); the landmarks are mapped back and the face is
aligned on the full-resolution pixels (pre-shrunk with area averaging only when the face is much larger
than the embedder chip, so bilinear resampling does not alias).  Files that cannot be decoded raise
:class:`PhotoError`; :meth:`PhotoEmbedder.embed_folder_tree` counts them (and photos without a face) and
carries on.
"""

from __future__ import annotations

import math
import os
import stat
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import shown
from face_reid_camera.common.embedding_spaces import EMBEDDER_CHOICES, embedder_space, space_dim
from face_reid_camera.faces.detector import YuNetDetector
from face_reid_camera.faces.embedder import CombinedEmbedder, FaceEmbedder

__all__ = [
    "IMAGE_SUFFIXES",
    "FaceFolderResult",
    "PhotoEmbedder",
    "PhotoEmbedding",
    "PhotoError",
    "ProgressBar",
    "ProgressCallback",
    "RequestPhotos",
    "decode_photo",
    "embed_request_photos",
    "image_size",
    "list_identity_photos",
    "progress_bar",
    "read_confined_photo",
    "read_photo",
]

# Suffixes (lower case) treated as photos in identity folders; other files are ignored (and reported).
IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".jpe", ".png", ".bmp", ".webp", ".tif", ".tiff", ".ppm", ".pgm"})

ProgressCallback = Callable[[int, int], None]
"""Called as ``progress(done, total)`` after each photo."""

_EMBEDDING_LENGTHS = frozenset(space_dim(embedder_space(choice)) for choice in EMBEDDER_CHOICES)
# Faces whose eyes are more than this many times farther apart than in the embedder's chip template are
# shrunk with INTER_AREA before the (bilinear) alignment warp.
_MAX_WARP_SHRINK = 2.0
DEFAULT_MAX_PIXELS = 100_000_000  # a decoded photo larger than this is refused (3 bytes per pixel in memory)
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SOF = frozenset({0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})


class PhotoError(ValueError):
    """A photo file is missing, unreadable or not a decodable image."""


@dataclass(frozen=True)
class PhotoEmbedding:
    """Embedding of the largest face of one photo; geometry in the photo's full-resolution pixels.

    ``path``: the file (None for an in-memory image). ``embedding``: (dim,) float32, read-only (128 values;
    256 for a combined embedder).
    ``box_xywh``: (4,) float32 face box. ``score``: detector confidence. ``eye_distance_px``: distance
    between the eye landmarks, a face-size / quality indicator. ``landmarks``: (5, 2) float32 YuNet landmarks
    (eyes, nose, mouth corners; None when not known), so the face can be re-aligned in a resized copy.
    """

    path: Path | None
    embedding: NDArray[np.float32]
    box_xywh: NDArray[np.float32]
    score: float
    eye_distance_px: float
    landmarks: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        emb = np.array(self.embedding, dtype=np.float32).reshape(-1)
        box = np.array(self.box_xywh, dtype=np.float32).reshape(-1)
        if emb.size not in _EMBEDDING_LENGTHS or not np.all(np.isfinite(emb)):
            raise ValueError(f"embedding must be {' or '.join(map(str, sorted(_EMBEDDING_LENGTHS)))} finite values "
                             f"(one embedder's or a combined one's), got shape {emb.shape}")
        if box.shape != (4,):
            raise ValueError(f"box_xywh must have 4 values, got shape {box.shape}")
        emb.flags.writeable = False
        box.flags.writeable = False
        object.__setattr__(self, "embedding", emb)
        object.__setattr__(self, "box_xywh", box)
        object.__setattr__(self, "score", float(self.score))
        object.__setattr__(self, "eye_distance_px", float(self.eye_distance_px))
        if self.path is not None:
            object.__setattr__(self, "path", Path(self.path))
        if self.landmarks is not None:
            marks = np.array(self.landmarks, dtype=np.float32)
            if marks.shape != (5, 2):
                raise ValueError(f"landmarks must be (5, 2), got shape {marks.shape}")
            marks.flags.writeable = False
            object.__setattr__(self, "landmarks", marks)


@dataclass
class FaceFolderResult:
    """Embeddings of a folder tree with one sub-folder per identity, and what could not be used.

    ``identities``: identity (folder name) -> embeddings in file-name order; identities without any usable
    photo are absent. ``skipped_unreadable``: image files that could not be decoded.
    ``skipped_no_face``: photos in which no face was detected. ``ignored_non_image``: files whose suffix
    is not in :data:`IMAGE_SUFFIXES`.
    """

    identities: dict[str, list[PhotoEmbedding]]
    skipped_unreadable: list[Path] = field(default_factory=list)
    skipped_no_face: list[Path] = field(default_factory=list)
    ignored_non_image: list[Path] = field(default_factory=list)

    @property
    def n_photos(self) -> int:
        """Number of embedded photos (over all identities)."""
        return sum(len(v) for v in self.identities.values())


def read_photo(path: str | Path) -> NDArray[np.uint8]:
    """Decode a photo file to (H, W, 3) uint8 BGR (EXIF orientation applied); PhotoError if impossible."""
    p = Path(path)
    try:
        data = np.fromfile(p, dtype=np.uint8)  # not cv2.imread: works with any path encoding
    except OSError as exc:
        raise PhotoError(f"cannot read photo {p}: {exc.strerror or exc}") from None
    return decode_photo(data.tobytes(), f"photo {p}")


def image_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) read from a JPEG or PNG header; None for another format or an unreadable header."""
    if data[:8] == _PNG_SIGNATURE and data[12:16] == b"IHDR" and len(data) >= 24:
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _JPEG_SOF:
            if i + 9 > len(data):
                return None
            return int.from_bytes(data[i + 7:i + 9], "big"), int.from_bytes(data[i + 5:i + 7], "big")
        if marker == 0x01 or 0xD0 <= marker <= 0xD9:  # markers without a length
            i += 2
            continue
        i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return None


def decode_photo(data: bytes, what: str = "photo", max_pixels: int = DEFAULT_MAX_PIXELS,
                 jpeg_png_only: bool = False) -> NDArray[np.uint8]:
    """Decode an encoded photo to (H, W, 3) uint8 BGR; PhotoError if it is empty, corrupt, larger than
    ``max_pixels`` by its header, or (``jpeg_png_only``) not a JPEG / PNG whose size the header gives."""
    if not data:
        raise PhotoError(f"{what} is an empty file")
    size = image_size(data)
    if size is None and jpeg_png_only:
        raise PhotoError(f"{what} is not a JPEG or PNG image")
    if size is not None and size[0] * size[1] > max_pixels:
        raise PhotoError(f"{what} is {size[0]} x {size[1]} pixels, more than {max_pixels}")
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    except (cv2.error, MemoryError) as exc:
        raise PhotoError(f"{what} cannot be decoded: {str(exc).strip()[:120]}") from None
    if image is None or image.size == 0:
        raise PhotoError(f"{what} is not a decodable image (corrupt or unsupported format)")
    return image


def read_confined_photo(root: str | Path, requested: str, max_bytes: int) -> bytes:
    """The bytes of photo ``requested`` (relative to ``root``, or absolute) if it is a regular file of at most
    ``max_bytes`` inside ``root`` once every symlink is resolved; PhotoError otherwise. Never blocks (FIFOs and
    devices are refused before they are read) and never reads more than ``max_bytes`` + 1 bytes."""
    quoted = shown(requested)
    if not str(root):
        raise PhotoError("photo paths are refused: no photo root is configured")
    if not requested or "\x00" in requested or len(requested) > 4096:
        raise PhotoError(f"photo path {quoted} is empty, too long or holds a NUL byte")
    base = os.path.realpath(root)
    real = os.path.realpath(os.path.join(base, requested))
    if os.path.commonpath([base, real]) != base:
        raise PhotoError(f"photo path {quoted} is outside the photo root")
    try:
        if not stat.S_ISREG(os.stat(real).st_mode):  # FIFOs, devices, sockets, directories: never opened
            raise PhotoError(f"photo path {quoted} is not a regular file")
        fd = os.open(real, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise PhotoError(f"cannot open photo {quoted}: {exc.strerror or exc}") from None
    try:
        st = os.fstat(fd)  # what was opened (the path may have changed since)
        if not stat.S_ISREG(st.st_mode):
            raise PhotoError(f"photo path {quoted} is not a regular file")
        if st.st_size > max_bytes:
            raise PhotoError(f"photo {quoted} is {st.st_size} bytes, more than {max_bytes}")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise PhotoError(f"cannot read photo {quoted}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise PhotoError(f"photo {quoted} is more than {max_bytes} bytes")
    return data


@dataclass
class RequestPhotos:
    """What the photos of one add-person request gave: an embedding per usable photo, and why others were not."""

    embeddings: list[np.ndarray]
    notes: list[str]


def embed_request_photos(embedder: PhotoEmbedder, root: str | Path, paths: list[str], max_bytes: int,
                         max_pixels: int, pixel_budget: int) -> RequestPhotos:
    """Each photo of ``paths`` read inside ``root`` (:func:`read_confined_photo`), decoded and embedded, one at a
    time; a photo that is unreadable, larger than ``max_pixels``, without a face, or beyond the request's
    ``pixel_budget`` (pixels decoded so far, by the headers) is skipped with a note. Bounds the time and memory
    one request can take."""
    out = RequestPhotos([], [])
    spent = 0
    for path in paths:
        try:
            data = read_confined_photo(root, path, max_bytes)
            width, height = image_size(data) or (0, 0)
            if spent + width * height > pixel_budget and width * height <= max_pixels:
                raise PhotoError(f"{shown(path)} is beyond this request's budget of {pixel_budget} pixels")
            spent += width * height
            found = embedder.embed_photo(decode_photo(data, shown(path), max_pixels, jpeg_png_only=True))
        except PhotoError as exc:
            out.notes.append(f"skipped: {exc}")
            continue
        if found is None:
            out.notes.append(f"skipped {shown(path)}: no face found")
        else:
            out.embeddings.append(found.embedding)
    return out


def list_identity_photos(root: str | Path) -> tuple[dict[str, list[Path]], list[Path]]:
    """({identity: photo paths sorted by name}, ignored non-image files) of a one-folder-per-identity tree.

    Hidden entries (``.name``) and files directly in ``root`` are ignored. ValueError if ``root`` is not
    a directory.
    """
    base = Path(root)
    if not base.is_dir():
        raise ValueError(f"face folder {base} does not exist or is not a directory")
    photos: dict[str, list[Path]] = {}
    ignored: list[Path] = []
    for sub in sorted(base.iterdir()):
        if sub.name.startswith(".") or not sub.is_dir():
            continue
        files = sorted(f for f in sub.iterdir() if not f.name.startswith(".") and f.is_file())
        photos[sub.name] = [f for f in files if f.suffix.lower() in IMAGE_SUFFIXES]
        ignored.extend(f for f in files if f.suffix.lower() not in IMAGE_SUFFIXES)
    return photos, ignored


class PhotoEmbedder:
    """Detects the largest face of a photo (YuNet) and embeds it (dlib ResNet by default): one embedding per photo.

    ``detector`` / ``embedder``: shared instances (None: YuNet and dlib; a :class:`CombinedEmbedder` gives the
    concatenated rows, each network aligned on its own chip). ``max_side_px``: photos
    whose longer side exceeds it are shrunk to it for detection only (>= 64).
    """

    def __init__(
        self,
        detector: YuNetDetector | None = None,
        embedder: FaceEmbedder | CombinedEmbedder | None = None,
        max_side_px: int = 640,
    ) -> None:
        if isinstance(max_side_px, bool) or not isinstance(max_side_px, (int, np.integer)) or max_side_px < 64:
            raise ValueError(f"max_side_px must be an integer >= 64, got {max_side_px!r}")
        if detector is not None and not isinstance(detector, YuNetDetector):
            raise ValueError(f"detector must be a YuNetDetector, got {type(detector).__name__}")
        if embedder is not None and not isinstance(embedder, (FaceEmbedder, CombinedEmbedder)):
            raise ValueError(f"embedder must be a FaceEmbedder or CombinedEmbedder, got {type(embedder).__name__}")
        self.max_side_px = int(max_side_px)
        self.detector = detector if detector is not None else YuNetDetector()
        self.embedder = embedder if embedder is not None else FaceEmbedder()

    def embed_photo(self, photo: str | Path | np.ndarray) -> PhotoEmbedding | None:
        """Embedding of the largest face of a photo file or a uint8 BGR / grey image; None if no face.

        Raises PhotoError for a file that cannot be decoded, ValueError for a malformed array.
        """
        if isinstance(photo, np.ndarray):
            path, image = None, photo
        elif isinstance(photo, (str, Path)):
            path, image = Path(photo), read_photo(photo)
        else:
            raise ValueError(f"photo must be a path or a numpy image, got {type(photo).__name__}")
        if image.ndim == 3 and image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)

        height, width = image.shape[:2]
        scale = min(1.0, self.max_side_px / max(height, width, 1))
        small = image
        if scale < 1.0:
            size = (max(1, round(width * scale)), max(1, round(height * scale)))
            small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
            scale_xy = np.array([width / size[0], height / size[1]], dtype=np.float32)
        else:
            scale_xy = np.ones(2, dtype=np.float32)
        detections = self.detector.detect(small)  # validates the array (dtype, shape, emptiness)
        if not detections:
            return None
        best = max(detections, key=lambda det: float(det.box_xywh[2] * det.box_xywh[3]))
        box = best.box_xywh.copy()
        box[:2] *= scale_xy
        box[2:] *= scale_xy
        landmarks = best.landmarks * scale_xy
        return self.embed_face(image, box, landmarks, best.score, path)

    def embed_face(self, image: NDArray[np.uint8], box_xywh: NDArray[np.floating], landmarks: NDArray[np.floating],
                   score: float = 1.0, path: Path | None = None) -> PhotoEmbedding:
        """Embedding of the face at known ``landmarks`` (5, 2) of a BGR image, without detecting it (e.g. a
        resized copy of a photo whose face was detected at full size)."""
        box = np.asarray(box_xywh, dtype=np.float32).reshape(4)
        landmarks = np.asarray(landmarks, dtype=np.float32).reshape(5, 2)
        eye_distance_px = float(np.linalg.norm(landmarks[1] - landmarks[0]))
        parts = self.embedder.embedders if isinstance(self.embedder, CombinedEmbedder) else (self.embedder,)
        rows = []
        for part in parts:
            template = part.spec.template
            chip_eye_px = float(np.linalg.norm(template[1] - template[0]))
            crop, crop_landmarks = _alignment_source(image, box, landmarks, eye_distance_px, chip_eye_px)
            rows.append(part.embed_faces(crop, [crop_landmarks])[0])
        embedding = rows[0] if len(rows) == 1 else np.concatenate(rows)
        return PhotoEmbedding(path, embedding, box, score, eye_distance_px, landmarks)

    def embed_folder_tree(
        self, root: str | Path, progress: ProgressCallback | None = None
    ) -> FaceFolderResult:
        """Embed every photo of ``root/<identity>/*`` (one sub-folder per identity, name = identity).

        Unreadable files and photos without a face are listed in the result, never fatal. ValueError if
        ``root`` is not a directory, has no identity sub-folder with photos, or no identity has a usable
        photo.
        """
        photos, ignored = list_identity_photos(root)
        total = sum(len(v) for v in photos.values())
        if total == 0:
            raise ValueError(
                f"face folder {root} has no photos: expected one sub-folder per identity holding "
                f"{'/'.join(sorted(s.lstrip('.') for s in IMAGE_SUFFIXES))} files"
            )
        result = FaceFolderResult(identities={}, ignored_non_image=ignored)
        done = 0
        for identity, files in photos.items():
            embedded: list[PhotoEmbedding] = []
            for f in files:
                try:
                    emb = self.embed_photo(f)
                except PhotoError:
                    result.skipped_unreadable.append(f)
                else:
                    if emb is None:
                        result.skipped_no_face.append(f)
                    else:
                        embedded.append(emb)
                done += 1
                if progress is not None:
                    progress(done, total)
            if embedded:
                result.identities[identity] = embedded
        if not result.identities:
            raise ValueError(
                f"no identity in {root} has a usable photo ({len(result.skipped_unreadable)} unreadable, "
                f"{len(result.skipped_no_face)} without a detectable face, of {total})"
            )
        return result


def _alignment_source(
    image: NDArray[np.uint8], box: NDArray[np.float32], landmarks: NDArray[np.float32], eye_distance_px: float,
    chip_eye_distance_px: float,
) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
    """Image and landmarks to align on: the full image, or for a face far larger than the chip (whose eyes
    are ``chip_eye_distance_px`` apart) an area-shrunk crop around it (same chip, without the aliasing of a
    large bilinear downscale)."""
    shrink = eye_distance_px / (_MAX_WARP_SHRINK * chip_eye_distance_px)
    if shrink <= 1.0:
        return image, landmarks
    height, width = image.shape[:2]
    side = float(max(box[2], box[3]))
    x0 = max(0, math.floor(box[0] - side))
    y0 = max(0, math.floor(box[1] - side))
    x1 = min(width, math.ceil(box[0] + box[2] + side))
    y1 = min(height, math.ceil(box[1] + box[3] + side))
    if x1 - x0 < 2 or y1 - y0 < 2:
        return image, landmarks
    crop = image[y0:y1, x0:x1]
    size = (max(1, round((x1 - x0) / shrink)), max(1, round((y1 - y0) / shrink)))
    small = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
    factor = np.array([size[0] / (x1 - x0), size[1] / (y1 - y0)], dtype=np.float32)
    # pixel-centre convention of cv2.resize: x_small + 0.5 = (x + 0.5) * factor
    return small, ((landmarks - np.array([x0, y0], dtype=np.float32) + 0.5) * factor - 0.5).astype(np.float32)


class ProgressBar:
    """Progress on stderr: a single redrawn line on a terminal, else one line per 10% (CI logs).

    Call it as ``bar(done, total)`` (a :data:`ProgressCallback`); ``total`` may change between calls.
    """

    def __init__(self, total: int, label: str, stream: TextIO | None = None, width_chars: int = 30) -> None:
        if isinstance(total, bool) or not isinstance(total, (int, np.integer)) or total < 0:
            raise ValueError(f"total must be an integer >= 0, got {total!r}")
        self.total = int(total)
        self.label = str(label)
        self.stream = stream if stream is not None else sys.stderr
        self.width_chars = int(width_chars)
        isatty = getattr(self.stream, "isatty", None)
        self.interactive = bool(isatty()) if callable(isatty) else False
        self._last_decile = -1
        self._finished = False

    def __call__(self, done: int, total: int | None = None) -> None:
        if total is not None:
            self.total = int(total)
        if self._finished:
            return
        done = max(0, min(int(done), self.total)) if self.total > 0 else int(done)
        fraction = done / self.total if self.total > 0 else 1.0
        percent = int(100 * fraction)
        if self.interactive:
            filled = int(self.width_chars * fraction)
            bar = "#" * filled + "-" * (self.width_chars - filled)
            self.stream.write(f"\r{self.label} [{bar}] {done}/{self.total} {percent:3d}%")
        else:
            decile = percent // 10
            if decile == self._last_decile:
                return
            self._last_decile = decile
            self.stream.write(f"{self.label}: {percent}% ({done}/{self.total})\n")
        if fraction >= 1.0:
            self._finished = True
            if self.interactive:
                self.stream.write("\n")
        self.stream.flush()


def progress_bar(total: int, label: str, stream: TextIO | None = None) -> ProgressBar:
    """A :class:`ProgressBar` on stderr (or ``stream``) for ``total`` items."""
    return ProgressBar(total, label, stream)
