"""``face-reid-eval-faces FACES_DIR``: how well the camera's face pipeline identifies faces, per embedder and size.

FACES_DIR holds one sub-folder per identity (name = identity), as for ``face-reid-fit-likelihood``.

Protocol (printed with every report):

1. **Photos.** Every photo of every identity folder; ``--exclude GLOB`` drops identities (glob on the folder
   name) or single photos (glob on ``identity/file``).  With ``--colour-only`` (the default) grey photos
   are dropped: a photo is grey when its three decoded channels are equal everywhere (single-channel
   files decode that way too).  ``--max-identities N`` keeps a seeded random sample of N identities.
2. **Reference face.** YuNet on the whole photo, shrunk to <= 640 px for detection (INTER_AREA, as
   :class:`~face_reid_camera.faces.photos.PhotoEmbedder` does); the largest face, mapped back to the photo's
   pixels, gives the face position and the reference eye distance ``e0``.  A photo without a face fails to
   enrol at every size.
3. **Face sizes.** For each target eye distance ``t`` (``--eye-px``; ``full`` = the photo as it is) the
   WHOLE photo is shrunk with INTER_AREA by ``t / e0`` so the eyes are ``t`` pixels apart (a face already
   smaller than ``t`` is used unshrunk, and counted).
4. **Camera path.** The face is detected again through the camera's head-ROI path
   (:meth:`~face_reid_camera.faces.detector.YuNetDetector.detect_in_rois`, ROI resized to 96 px): a square
   ROI centred on the reference face box, of side ``0.3 / 0.063 x`` the eye distance at that size (a
   0.3 m head ROI around a 0.063 m eye distance), clipped to the image.  A face the ROI path misses is a
   failure to enrol at that size.  The found landmarks are used to align and embed with each embedder on
   those (shrunk) pixels (:meth:`~face_reid_camera.faces.embedder.FaceEmbedder.embed_faces`, one face per
   call, one ONNX Runtime thread).
5. **Photo set.** All metrics use only the photos enrolled at EVERY requested size, so all rows compare the
   same photos and pairs.
6. **Scores.** dlib: -L2 distance; SFace: cosine similarity; ``both``: the sum of the dlib and SFace scores,
   each z-normalised by the mean and standard deviation of that embedder's scores over all pairs at that
   size.  Higher = more alike.
7. **Metrics** per (size, embedder):
   TAR@FAR f — share of all same-identity pairs scoring above the threshold that at most a share f of all
   different-identity pairs exceeds (:func:`threshold_at_rate`);
   rank-1 — closed set, leave one out: each photo of an identity with >= 2 photos is correct when its
   highest-scoring other photo (of any identity) is of its identity;
   rank-1 (1-photo gallery) — closed set, every identity enrolled with ONE random photo, all other photos
   are probes; mean over 10 seeded galleries (the definition behind the rank-1 figures in the models notes);
   DIR@FPIR 1e-2 — open set, one seeded split shared by all rows: half the identities are enrolled with
   one random gallery photo each; probes are the other photos of enrolled identities (known) and all
   photos of the others (unknown); a known probe is right when its best gallery match is its identity and
   scores above the threshold that lets 1 % of the unknown probes through;
   ROC AUC — over all same- vs different-identity pairs (ties count half);
   ms/face — median time of ``embed_faces`` (alignment + network) per face, ``both`` = dlib + SFace.

``--cache PATH.npz`` keeps every (photo path, mtime, size, eye-px, embedder) embedding with its timing, so a
second run only scores; entries of other model files are ignored.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "EMBEDDER_NAMES",
    "HEAD_ROI_SIDE_PER_EYE_DISTANCE",
    "EmbedderMetrics",
    "OpenSetSplit",
    "dir_at_fpir",
    "evaluate_scores",
    "head_roi_for_face",
    "main",
    "one_photo_galleries",
    "open_set_split",
    "pair_scores",
    "parse_eye_px",
    "rank1_one_photo_gallery",
    "rank1_rate",
    "roc_auc",
    "score_matrix",
    "shrink_to_eye_distance",
    "tar_at_far",
    "threshold_at_rate",
    "z_normalised",
]

PROG = "face-reid-eval-faces"
FULL = "full"
EMBEDDER_NAMES: tuple[str, ...] = ("dlib", "sface", "both")
_NETWORKS: tuple[str, ...] = ("dlib", "sface")  # what actually runs; "both" combines their scores
_SCORE_KIND = {"dlib": "neg_l2", "sface": "cosine"}
HEAD_ROI_SIZE_M = 0.3
EYE_DISTANCE_M = 0.063
HEAD_ROI_SIDE_PER_EYE_DISTANCE = HEAD_ROI_SIZE_M / EYE_DISTANCE_M
DETECT_MAX_SIDE_PX = 640
ROI_INPUT_PX = 96  # the camera's face_roi_input_px default
FARS: tuple[float, ...] = (1e-3, 1e-2)
FPIR = 1e-2
GALLERY_REPEATS = 10
_CACHE_VERSION = 1
_MAX_LISTED_FAILURES = 200

# Per (photo, size) outcome.
_OK, _NO_FACE, _ROI_MISS = 0, 1, 2

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


# --------------------------------------------------------------------------------------------- metrics


def threshold_at_rate(impostor_scores: NDArray[np.floating], rate: float) -> float:
    """Threshold ``t`` for "accept when score > t" that at most ``rate`` of ``impostor_scores`` exceed.

    ``t`` is the (k+1)-th highest impostor score with k = floor(rate x n): exactly k impostors score above it
    when there are no ties (fewer with ties).  -inf when k >= n (everything may pass), +inf for no scores.
    """
    scores = np.asarray(impostor_scores, dtype=np.float64).reshape(-1)
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"rate must be in [0, 1], got {rate!r}")
    n = scores.size
    if n == 0:
        return math.inf
    k = math.floor(rate * n + 1e-9)
    if k >= n:
        return -math.inf
    index = n - 1 - k
    return float(np.partition(scores, index)[index])


def tar_at_far(genuine_scores: NDArray[np.floating], impostor_scores: NDArray[np.floating], far: float) -> float:
    """Share of genuine scores above :func:`threshold_at_rate` of the impostor scores (nan if no genuine)."""
    genuine = np.asarray(genuine_scores, dtype=np.float64).reshape(-1)
    if genuine.size == 0:
        return math.nan
    return float(np.mean(genuine > threshold_at_rate(impostor_scores, far)))


def roc_auc(genuine_scores: NDArray[np.floating], impostor_scores: NDArray[np.floating]) -> float:
    """Area under the ROC curve = P(genuine > impostor) + P(tie) / 2 (nan if either side is empty)."""
    genuine = np.asarray(genuine_scores, dtype=np.float64).reshape(-1)
    impostor = np.sort(np.asarray(impostor_scores, dtype=np.float64).reshape(-1))
    if genuine.size == 0 or impostor.size == 0:
        return math.nan
    below = np.searchsorted(impostor, genuine, side="left").astype(np.float64)
    at_or_below = np.searchsorted(impostor, genuine, side="right").astype(np.float64)
    return float(np.sum(below + 0.5 * (at_or_below - below)) / (genuine.size * impostor.size))


def score_matrix(embeddings: NDArray[np.floating], kind: str) -> FloatArray:
    """(n, n) similarity of all rows: ``neg_l2`` = -Euclidean distance, ``cosine`` = cosine similarity."""
    x = np.asarray(embeddings, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"embeddings must be (n, dim), got shape {x.shape}")
    if kind == "neg_l2":
        sq = np.einsum("ij,ij->i", x, x)
        return -np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * (x @ x.T), 0.0))
    if kind == "cosine":
        norms = np.linalg.norm(x, axis=1, keepdims=True)
        if np.any(norms <= 0.0):
            raise ValueError("cosine scores need non-zero embeddings")
        unit = x / norms
        return np.clip(unit @ unit.T, -1.0, 1.0)
    raise ValueError(f"kind must be 'neg_l2' or 'cosine', got {kind!r}")


def z_normalised(scores: NDArray[np.floating]) -> FloatArray:
    """A symmetric score matrix minus the mean, over the std, of its pairs (upper triangle, i < j)."""
    s = np.asarray(scores, dtype=np.float64)
    iu = np.triu_indices(s.shape[0], k=1)
    pairs = s[iu]
    if pairs.size < 2:
        raise ValueError("z-normalisation needs at least 3 items (2 pairs)")
    std = float(pairs.std())
    if std <= 0.0:
        raise ValueError("z-normalisation of constant scores")
    return (s - float(pairs.mean())) / std


def pair_scores(scores: NDArray[np.floating], labels: NDArray[np.integer]) -> tuple[FloatArray, FloatArray]:
    """(genuine, impostor) scores of all unordered pairs i < j: same label vs different label."""
    s = np.asarray(scores, dtype=np.float64)
    lab = np.asarray(labels).reshape(-1)
    if s.shape != (lab.size, lab.size):
        raise ValueError(f"scores must be ({lab.size}, {lab.size}), got {s.shape}")
    iu, ju = np.triu_indices(lab.size, k=1)
    same = lab[iu] == lab[ju]
    values = s[iu, ju]
    return values[same], values[~same]


def rank1_rate(scores: NDArray[np.floating], labels: NDArray[np.integer]) -> tuple[float, int]:
    """Closed-set leave-one-out rank-1 rate and the number of probes (photos whose identity has >= 2).

    Each probe's gallery is every other photo; it is right when its highest-scoring one has its label.
    """
    s = np.array(scores, dtype=np.float64)  # a copy: the diagonal is overwritten
    lab = np.asarray(labels).reshape(-1)
    if s.shape != (lab.size, lab.size):
        raise ValueError(f"scores must be ({lab.size}, {lab.size}), got {s.shape}")
    _, inverse, counts = np.unique(lab, return_inverse=True, return_counts=True)
    probes = np.flatnonzero(counts[inverse] >= 2)
    if probes.size == 0:
        return math.nan, 0
    np.fill_diagonal(s, -np.inf)
    nearest = np.argmax(s[probes], axis=1)
    return float(np.mean(lab[nearest] == lab[probes])), int(probes.size)


def one_photo_galleries(labels: NDArray[np.integer], rng: np.random.Generator, repeats: int = 10) -> IntArray:
    """(repeats, identities) indices: in each row one random photo of every identity (sorted identity order)."""
    lab = np.asarray(labels).reshape(-1)
    ids = np.unique(lab)
    members = [np.flatnonzero(lab == i) for i in ids.tolist()]
    return np.array([[int(rng.choice(m)) for m in members] for _ in range(repeats)], dtype=np.intp).reshape(
        repeats, ids.size)


def rank1_one_photo_gallery(scores: NDArray[np.floating], labels: NDArray[np.integer],
                            galleries: NDArray[np.integer]) -> float:
    """Closed-set rank-1 with ONE gallery photo per identity, averaged over the rows of ``galleries``.

    Probes are all photos not in that row's gallery; a probe is right when its highest-scoring gallery photo
    has its label.  nan without probes.
    """
    s = np.asarray(scores, dtype=np.float64)
    lab = np.asarray(labels).reshape(-1)
    rates = []
    for gallery in np.atleast_2d(np.asarray(galleries, dtype=np.intp)):
        probes = np.setdiff1d(np.arange(lab.size), gallery)
        if probes.size == 0:
            continue
        best = np.argmax(s[np.ix_(probes, gallery)], axis=1)
        rates.append(float(np.mean(lab[gallery][best] == lab[probes])))
    return float(np.mean(rates)) if rates else math.nan


@dataclass(frozen=True)
class OpenSetSplit:
    """Indices of the gallery photos (one per enrolled identity), known probes and unknown probes."""

    gallery: IntArray
    known: IntArray
    unknown: IntArray


def open_set_split(labels: NDArray[np.integer], rng: np.random.Generator) -> OpenSetSplit:
    """Half the identities (floor, >= 1) enrolled, each with one random photo as gallery; the other photos of
    enrolled identities are known probes, all photos of the rest unknown probes."""
    lab = np.asarray(labels).reshape(-1)
    ids = np.unique(lab)
    if ids.size < 2:
        raise ValueError("an open-set split needs at least 2 identities")
    enrolled = np.sort(rng.permutation(ids)[: max(1, ids.size // 2)])
    gallery: list[int] = []
    for identity in enrolled.tolist():
        gallery.append(int(rng.choice(np.flatnonzero(lab == identity))))
    gallery_idx = np.array(sorted(gallery), dtype=np.intp)
    is_enrolled = np.isin(lab, enrolled)
    known = np.flatnonzero(is_enrolled & ~np.isin(np.arange(lab.size), gallery_idx))
    unknown = np.flatnonzero(~is_enrolled)
    return OpenSetSplit(gallery_idx, known.astype(np.intp), unknown.astype(np.intp))


def dir_at_fpir(scores: NDArray[np.floating], labels: NDArray[np.integer], split: OpenSetSplit,
                fpir: float = FPIR) -> float:
    """Detection-and-identification rate of the known probes at the false-positive identification rate ``fpir``.

    Threshold: :func:`threshold_at_rate` of the unknown probes' best gallery scores.  A known probe counts when
    its best gallery match has its label and scores above the threshold.  nan without known probes.
    """
    s = np.asarray(scores, dtype=np.float64)
    lab = np.asarray(labels).reshape(-1)
    if split.known.size == 0 or split.gallery.size == 0:
        return math.nan
    unknown_best = s[np.ix_(split.unknown, split.gallery)].max(axis=1) if split.unknown.size else np.zeros(0)
    threshold = threshold_at_rate(unknown_best, fpir)
    known_scores = s[np.ix_(split.known, split.gallery)]
    best = np.argmax(known_scores, axis=1)
    best_score = known_scores[np.arange(best.size), best]
    right = (lab[split.gallery][best] == lab[split.known]) & (best_score > threshold)
    return float(np.mean(right))


@dataclass
class EmbedderMetrics:
    """Everything measured for one (size, embedder); ``ms_per_face`` is None when not timed."""

    tar_at_far: dict[str, float]
    rank1: float
    rank1_one_photo_gallery: float
    dir_at_fpir: float
    roc_auc: float
    ms_per_face: float | None = None
    n_genuine_pairs: int = 0
    n_impostor_pairs: int = 0
    n_rank1_probes: int = 0


def evaluate_scores(scores: NDArray[np.floating], labels: NDArray[np.integer], split: OpenSetSplit,
                    galleries: NDArray[np.integer] | None = None, fars: Sequence[float] = FARS,
                    fpir: float = FPIR) -> EmbedderMetrics:
    """All metrics of one score matrix (higher = more alike); ``galleries`` for :func:`rank1_one_photo_gallery`
    (None: not measured, nan)."""
    genuine, impostor = pair_scores(scores, labels)
    rank1, n_probes = rank1_rate(scores, labels)
    return EmbedderMetrics(
        tar_at_far={f"{far:g}": tar_at_far(genuine, impostor, far) for far in fars},
        rank1=rank1,
        rank1_one_photo_gallery=math.nan if galleries is None else rank1_one_photo_gallery(scores, labels, galleries),
        dir_at_fpir=dir_at_fpir(scores, labels, split, fpir),
        roc_auc=roc_auc(genuine, impostor),
        n_genuine_pairs=int(genuine.size),
        n_impostor_pairs=int(impostor.size),
        n_rank1_probes=n_probes,
    )


# ------------------------------------------------------------------------------------------ geometry


def parse_eye_px(text: str) -> list[str]:
    """``full,14,10`` -> ["full", "14", "10"] (numbers normalised, > 0, no duplicates); ValueError if bad."""
    labels: list[str] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        if part.lower() == FULL:
            label = FULL
        else:
            try:
                value = float(part)
            except ValueError:
                raise ValueError(f"--eye-px: {part!r} is neither 'full' nor a number") from None
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f"--eye-px: {part!r} must be a positive number of pixels")
            label = f"{value:g}"
        if label in labels:
            raise ValueError(f"--eye-px: {label} given twice")
        labels.append(label)
    if not labels:
        raise ValueError("--eye-px: no size given")
    return labels


def shrink_to_eye_distance(image: NDArray[np.uint8], eye_distance_px: float, target_px: float | None
                           ) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """The whole image shrunk with INTER_AREA so a face whose eyes are ``eye_distance_px`` apart has them
    ``target_px`` apart, and the per-axis (x, y) factor.  Unchanged when ``target_px`` is None or not smaller.
    Points map as ``(p + 0.5) * factor - 0.5`` (cv2.resize's pixel-centre convention)."""
    if target_px is None or target_px >= eye_distance_px:
        return image, np.ones(2)
    height, width = image.shape[:2]
    scale = target_px / eye_distance_px
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    return small, np.array([size[0] / width, size[1] / height])


def head_roi_for_face(centre_xy: NDArray[np.floating], eye_distance_px: float, width: int, height: int
                      ) -> tuple[int, int, int, int]:
    """Square x, y, w, h ROI of side 0.3 / 0.063 x the eye distance centred on the face, clipped to the image."""
    side = HEAD_ROI_SIDE_PER_EYE_DISTANCE * eye_distance_px
    cx, cy = float(centre_xy[0]), float(centre_xy[1])
    x0 = max(0, math.floor(cx - side / 2.0 + 0.5))
    y0 = max(0, math.floor(cy - side / 2.0 + 0.5))
    x1 = min(width, math.ceil(cx + side / 2.0 + 0.5))
    y1 = min(height, math.ceil(cy + side / 2.0 + 0.5))
    return x0, y0, max(1, x1 - x0), max(1, y1 - y0)


# -------------------------------------------------------------------------------------- photo selection


@dataclass
class Selection:
    """The photos to evaluate and what was left out on the way."""

    identities: list[str]
    photos: list[tuple[str, Path]]  # (identity, path), identities in order
    n_identities_listed: int = 0
    n_photos_listed: int = 0
    excluded_photos: int = 0
    excluded_identities: list[str] = field(default_factory=list)
    grey_photos: int = 0
    grey_identities: list[str] = field(default_factory=list)  # identities left without a colour photo
    unreadable: list[str] = field(default_factory=list)
    ignored_non_image: int = 0


def _file_key(path: Path) -> str:
    st = path.stat()
    return f"{path.resolve()}|{st.st_mtime_ns}|{st.st_size}"


def _is_grey(image: NDArray[np.uint8]) -> bool:
    return bool(np.array_equal(image[..., 0], image[..., 1]) and np.array_equal(image[..., 1], image[..., 2]))


# ------------------------------------------------------------------------------------------------ cache


class EmbeddingCache:
    """(photo path|mtime|size, eye-px, embedder) -> (status, embedding, ms, eye px seen, reference eye px)."""

    def __init__(self, path: Path | None, model_ids: dict[str, str]) -> None:
        self.path = path
        self.meta = {"version": _CACHE_VERSION, "models": model_ids, "detect_max_side_px": DETECT_MAX_SIDE_PX,
                     "head_roi_side_per_eye": HEAD_ROI_SIDE_PER_EYE_DISTANCE}
        self.entries: dict[str, tuple[int, NDArray[np.float32], float, float, float]] = {}
        self.grey: dict[str, bool] = {}
        self.loaded = 0
        self.dirty = False
        if path is not None and path.is_file():
            self._load(path)

    def _load(self, path: Path) -> None:
        try:
            with np.load(path, allow_pickle=False) as data:
                if json.loads(str(data["meta"])) != json.loads(json.dumps(self.meta)):
                    print(f"{PROG}: cache {path} is of other models or another protocol: not used", file=sys.stderr)
                    return
                keys = data["keys"].tolist()
                status, emb, ms, eye, eye0 = (data[k] for k in ("status", "embedding", "ms", "eye_px", "ref_eye_px"))
                for i, key in enumerate(keys):
                    self.entries[key] = (int(status[i]), emb[i].astype(np.float32), float(ms[i]), float(eye[i]),
                                         float(eye0[i]))
                self.grey = dict(zip(data["grey_keys"].tolist(), data["grey"].astype(bool).tolist(), strict=True))
        except (OSError, ValueError, KeyError) as exc:
            print(f"{PROG}: cache {path} unreadable ({exc}): not used", file=sys.stderr)
            self.entries, self.grey = {}, {}
            return
        self.loaded = len(self.entries)

    def save(self) -> None:
        if self.path is None or not self.dirty:
            return
        keys = sorted(self.entries)
        dim = max((len(self.entries[k][1]) for k in keys), default=128)
        emb = np.zeros((len(keys), dim), dtype=np.float32)
        for i, k in enumerate(keys):
            if self.entries[k][1].size:
                emb[i] = self.entries[k][1]
        grey_keys = sorted(self.grey)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "wb") as f:
            np.savez(
                f, meta=np.array(json.dumps(self.meta)), keys=np.array(keys, dtype=str),
                status=np.array([self.entries[k][0] for k in keys], dtype=np.int8), embedding=emb,
                ms=np.array([self.entries[k][2] for k in keys]), eye_px=np.array([self.entries[k][3] for k in keys]),
                ref_eye_px=np.array([self.entries[k][4] for k in keys]),
                grey_keys=np.array(grey_keys, dtype=str), grey=np.array([self.grey[k] for k in grey_keys], dtype=bool),
            )
        os.replace(tmp, self.path)


def _model_id(path: Path) -> str:
    st = path.stat()
    return f"{path.name}|{st.st_size}|{st.st_mtime_ns}"


# ------------------------------------------------------------------------------------------- embedding


@dataclass
class SizeResult:
    """Per photo at one size: status, the landmarks' eye distance, embeddings and ms per network."""

    status: NDArray[np.int8]
    eye_px: FloatArray
    ref_eye_px: FloatArray
    embeddings: dict[str, NDArray[np.float32]]
    ms: dict[str, FloatArray]


class FaceSizeRunner:
    """Runs steps 2-4 of the protocol for one photo (all sizes, all networks), through the cache."""

    def __init__(self, networks: Sequence[str], sizes: Sequence[str], cache: EmbeddingCache) -> None:
        from face_reid_camera.faces.detector import YuNetDetector
        from face_reid_camera.faces.embedder import FaceEmbedder

        self.networks = tuple(networks)
        self.sizes = tuple(sizes)
        self.cache = cache
        self._detector: Any = None
        self._embedders: dict[str, Any] = {}
        self._make_detector = lambda: YuNetDetector(roi_input_size_px=ROI_INPUT_PX, num_threads=1)
        self._make_embedder = lambda kind: FaceEmbedder(num_threads=1, kind=kind)
        self.computed = 0

    def detector(self) -> Any:
        if self._detector is None:
            self._detector = self._make_detector()
        return self._detector

    def embedder(self, kind: str) -> Any:
        if kind not in self._embedders:
            self._embedders[kind] = self._make_embedder(kind)
        return self._embedders[kind]

    def run(self, file_key: str, load: Callable[[], NDArray[np.uint8]]
            ) -> dict[tuple[str, str], tuple[int, NDArray[np.float32], float, float, float]]:
        """{(size, network): entry} for one photo; ``load()`` decodes it if something is not cached."""
        out: dict[tuple[str, str], tuple[int, NDArray[np.float32], float, float, float]] = {}
        missing = []
        for size in self.sizes:
            for kind in self.networks:
                entry = self.cache.entries.get(f"{file_key}|{size}|{kind}")
                if entry is None:
                    missing.append((size, kind))
                else:
                    out[(size, kind)] = entry
        if not missing:
            return out
        image = load()
        reference = self._reference_face(image)
        for size in sorted({s for s, _ in missing}, key=self.sizes.index):
            kinds = [k for s, k in missing if s == size]
            for kind, entry in self._embed_at_size(image, reference, size, kinds).items():
                out[(size, kind)] = entry
                self.cache.entries[f"{file_key}|{size}|{kind}"] = entry
                self.cache.dirty = True
        self.computed += 1
        return out

    def _reference_face(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float64], float] | None:
        """(box centre, eye distance) of the largest face, in the photo's pixels; None without a face."""
        height, width = image.shape[:2]
        scale = min(1.0, DETECT_MAX_SIDE_PX / max(height, width, 1))
        small = image
        factor = np.ones(2)
        if scale < 1.0:
            size = (max(1, round(width * scale)), max(1, round(height * scale)))
            small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
            factor = np.array([width / size[0], height / size[1]])
        detections = self.detector().detect(small)
        if not detections:
            return None
        best = max(detections, key=lambda d: float(d.box_xywh[2] * d.box_xywh[3]))
        box = best.box_xywh.astype(np.float64)
        centre = (box[:2] + box[2:] / 2.0) * factor
        landmarks = best.landmarks.astype(np.float64) * factor
        return centre, float(np.linalg.norm(landmarks[1] - landmarks[0]))

    def _embed_at_size(self, image: NDArray[np.uint8], reference: tuple[NDArray[np.float64], float] | None,
                       size: str, kinds: Sequence[str]
                       ) -> dict[str, tuple[int, NDArray[np.float32], float, float, float]]:
        empty = np.zeros(0, dtype=np.float32)
        if reference is None:
            return {k: (_NO_FACE, empty, math.nan, math.nan, math.nan) for k in kinds}
        centre, ref_eye = reference
        target = None if size == FULL else float(size)
        small, factor = shrink_to_eye_distance(image, ref_eye, target)
        eye_now = ref_eye * float(np.sqrt(factor[0] * factor[1]))
        centre_now = (centre + 0.5) * factor - 0.5
        roi = head_roi_for_face(centre_now, eye_now, small.shape[1], small.shape[0])
        (found,) = self.detector().detect_in_rois(small, [roi])
        if found is None:
            return {k: (_ROI_MISS, empty, math.nan, math.nan, ref_eye) for k in kinds}
        from face_reid_camera.pipeline import face_pose_from_landmarks

        _, eye_seen = face_pose_from_landmarks(found.landmarks)
        result = {}
        for kind in kinds:
            embedder = self.embedder(kind)
            start = time.perf_counter()
            row = embedder.embed_faces(small, [found.landmarks])[0]
            ms = (time.perf_counter() - start) * 1e3
            result[kind] = (_OK, np.asarray(row, dtype=np.float32), ms, eye_seen, ref_eye)
        return result


# ---------------------------------------------------------------------------------------------- report


@dataclass
class SizeReport:
    eye_px: str
    median_eye_px_seen: float
    enrol_failures: int
    smaller_than_target: int
    failed_photos: list[str]
    metrics: dict[str, EmbedderMetrics]


def _fmt(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    return f"{value:.{digits}f}"


def _size_label(report: SizeReport) -> str:
    if report.eye_px == FULL:
        return f"full photo (median {report.median_eye_px_seen:.1f} px)"
    return f"{report.eye_px} px (median {report.median_eye_px_seen:.1f} seen)"


_TITLES = {"dlib": "dlib", "sface": "SFace", "both": "both (sum of z-scores)"}


def render_markdown(result: dict[str, Any], sizes: list[SizeReport], embedders: Sequence[str]) -> str:
    """The printed report: protocol, counts, a summary table, a full table."""
    c = result["counts"]
    lines = [
        f"# Face identification by embedder and face size: {result['faces_dir']}",
        "",
        "Protocol: largest YuNet face of each photo (detected on the photo shrunk to <= 640 px); the whole photo "
        "shrunk (INTER_AREA) so the eyes are N px apart ('full' = unshrunk); face re-detected through the "
        "camera's head-ROI path (square ROI of 0.3/0.063 x eye distance around the face, resized to 96 px); "
        "aligned and embedded on those pixels. Scores: dlib -L2, SFace cosine, both = sum of the two "
        "z-normalised (mean/std over all pairs at that size). Only photos enrolled at every size are scored. "
        "TAR@FAR over all genuine vs impostor pairs; rank-1 leave-one-out (identities with >= 2 photos); rank-1 "
        "(1-photo gallery): every identity enrolled with one random photo, the others probe (mean of 10 galleries); "
        f"DIR@FPIR 1e-2 on a seeded split (seed {result['seed']}: half the identities enrolled with one photo); "
        "ms/face = median align + embed time, 1 thread.",
        "",
        f"Photos: {c['identities_listed']} identities / {c['photos_listed']} photos listed"
        + (f"; excluded {c['excluded_photos']} photos ({len(c['excluded_identities'])} whole identities)"
           if c["excluded_photos"] else "")
        + (f"; {c['grey_photos']} grey photos dropped ({len(c['grey_identities'])} identities left without colour)"
           if result["colour_only"] else "; grey photos kept")
        + (f"; {len(c['unreadable'])} unreadable" if c["unreadable"] else "")
        + (f"; sample of {c['identities_evaluated']} identities (seed {result['seed']})"
           if result["max_identities"] else "")
        + f". Evaluated: {c['identities_evaluated']} identities / {c['photos_evaluated']} photos; no face on the "
        f"full photo: {c['no_face']}; enrolled at every size (scored): {c['identities_scored']} identities / "
        f"{c['photos_scored']} photos.",
        "",
    ]
    header = "| eye distance | " + " | ".join(f"{_TITLES[e]} TAR@FAR 1e-3 / rank-1" for e in embedders)
    lines += [header + " | enrol failures |", "|" + "---|" * (len(embedders) + 2)]
    for rep in sizes:
        cells = [f"{_fmt(rep.metrics[e].tar_at_far['0.001'])} / {_fmt(rep.metrics[e].rank1)}" for e in embedders]
        lines.append(f"| {_size_label(rep)} | " + " | ".join(cells) + f" | {rep.enrol_failures} |")
    lines += [
        "",
        "| eye distance | embedder | TAR@FAR 1e-3 | TAR@FAR 1e-2 | rank-1 | rank-1 (1-photo gallery) | DIR@FPIR 1e-2 "
        "| ROC AUC | ms/face | enrol failures | faces smaller than target |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for rep in sizes:
        for e in embedders:
            m = rep.metrics[e]
            lines.append(
                f"| {_size_label(rep)} | {_TITLES[e]} | {_fmt(m.tar_at_far['0.001'])} | {_fmt(m.tar_at_far['0.01'])} "
                f"| {_fmt(m.rank1)} | {_fmt(m.rank1_one_photo_gallery)} | {_fmt(m.dir_at_fpir)} "
                f"| {_fmt(m.roc_auc, 4)} | {_fmt(m.ms_per_face, 1)} "
                f"| {rep.enrol_failures} | {rep.smaller_than_target} |"
            )
    if sizes:
        m0 = sizes[0].metrics[embedders[0]]
        split = result["open_set"]
        lines += [
            "",
            f"Pairs per row: {m0.n_genuine_pairs:,} genuine, {m0.n_impostor_pairs:,} impostor; rank-1 probes: "
            f"{m0.n_rank1_probes}; open set: {split['gallery']} gallery photos, {split['known_probes']} known and "
            f"{split['unknown_probes']} unknown probes. Enrol failures = faces found on the full photo but missed "
            f"by the head-ROI path at that size. Run time {result['run_time_s']:.0f} s "
            f"({result['photos_computed']} photos computed, {result['photos_from_cache']} from the cache).",
        ]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------------- CLI


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="How well the camera's face pipeline identifies faces, per embedder and "
                "face size (see the module docstring for the protocol).")
    p.add_argument("faces_dir", metavar="FACES_DIR", help="one sub-folder of photos per identity")
    p.add_argument("--eye-px", default="full,14,10", help="target eye distances, 'full' = unshrunk (full,14,10)")
    p.add_argument("--embedders", default="dlib,sface,both", help="any of dlib,sface,both (dlib,sface,both)")
    p.add_argument("--exclude", action="append", default=[], metavar="GLOB",
                   help="leave out identities (glob on the folder name) or photos (glob on identity/file); repeatable")
    colour = p.add_mutually_exclusive_group()
    colour.add_argument("--colour-only", dest="colour_only", action="store_true", default=True,
                        help="drop grey photos (three equal channels): the default")
    colour.add_argument("--all-photos", dest="colour_only", action="store_false", help="keep grey photos")
    p.add_argument("--max-identities", type=int, default=None, metavar="N", help="a seeded sample of N identities")
    p.add_argument("--seed", type=int, default=0, help="identity sample and open-set split (0)")
    p.add_argument("--json", type=Path, default=None, metavar="OUT.json", help="also write the results as JSON")
    p.add_argument("--cache", type=Path, default=None, metavar="PATH.npz", help="embedding cache (read and updated)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


class _UsageError(Exception):
    pass


def _parse_embedders(text: str) -> list[str]:
    names = [n.strip().lower() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in EMBEDDER_NAMES]
    if bad or not names:
        raise _UsageError(f"--embedders: expected some of {','.join(EMBEDDER_NAMES)}, got {text!r}")
    return list(dict.fromkeys(names))


def _select(args: argparse.Namespace, cache: EmbeddingCache) -> Selection:
    from face_reid_camera.faces.photos import PhotoError, list_identity_photos, read_photo

    try:
        listed, ignored = list_identity_photos(args.faces_dir)
    except ValueError as exc:
        raise _UsageError(str(exc)) from None
    n_photos = sum(len(v) for v in listed.values())
    if n_photos == 0:
        raise _UsageError(f"face folder {args.faces_dir} has no photos (expected one sub-folder of photos per "
                          "identity)")
    sel = Selection(identities=[], photos=[], n_identities_listed=sum(1 for v in listed.values() if v),
                    n_photos_listed=n_photos, ignored_non_image=len(ignored))
    kept: dict[str, list[Path]] = {}
    for identity, files in listed.items():
        if not files:
            continue
        if any(fnmatch.fnmatchcase(identity, g) for g in args.exclude):
            sel.excluded_identities.append(identity)
            sel.excluded_photos += len(files)
            continue
        use = [f for f in files if not any(fnmatch.fnmatchcase(f"{identity}/{f.name}", g) for g in args.exclude)]
        sel.excluded_photos += len(files) - len(use)
        if args.colour_only:
            colour = []
            for f in use:
                key = _file_key(f)
                grey = cache.grey.get(key)
                if grey is None:
                    try:
                        grey = _is_grey(read_photo(f))
                    except PhotoError:
                        sel.unreadable.append(str(f))
                        continue
                    cache.grey[key] = grey
                    cache.dirty = True
                if grey:
                    sel.grey_photos += 1
                else:
                    colour.append(f)
            if use and not colour:
                sel.grey_identities.append(identity)
            use = colour
        if use:
            kept[identity] = use
    names = sorted(kept)
    if args.max_identities is not None and args.max_identities < len(names):
        rng = np.random.default_rng([args.seed, 0])
        names = sorted(rng.choice(np.array(names), size=args.max_identities, replace=False).tolist())
    if len(names) < 2:
        raise _UsageError(f"need at least 2 identities with usable photos in {args.faces_dir}, got {len(names)}")
    sel.identities = names
    sel.photos = [(n, f) for n in names for f in kept[n]]
    return sel


def run(args: argparse.Namespace) -> tuple[dict[str, Any], str]:
    """Steps 1-7: (JSON-able results, markdown report)."""
    from face_reid_camera.common.resources import models_dir
    from face_reid_camera.faces.detector import DEFAULT_MODEL_FILENAME
    from face_reid_camera.faces.embedder import EMBEDDERS
    from face_reid_camera.faces.photos import PhotoError, progress_bar, read_photo

    started = time.perf_counter()
    sizes = parse_eye_px(args.eye_px)
    embedders = _parse_embedders(args.embedders)
    networks = [n for n in _NETWORKS if n in embedders or "both" in embedders]
    if args.max_identities is not None and args.max_identities < 2:
        raise _UsageError("--max-identities must be >= 2")
    folder = Path(args.faces_dir)
    if not folder.is_dir():
        raise _UsageError(f"face folder {folder} does not exist or is not a directory")
    models = models_dir()
    detector_path = models / DEFAULT_MODEL_FILENAME
    model_ids = {"detector": _model_id(detector_path)} if detector_path.is_file() else {}
    for n in networks:
        path = models / EMBEDDERS[n].model_filename
        if not path.is_file():
            raise _UsageError(f"{n} embedder model not found: {path}")
        model_ids[n] = _model_id(path)
    cache = EmbeddingCache(args.cache, model_ids)
    sel = _select(args, cache)

    runner = FaceSizeRunner(networks, sizes, cache)
    n = len(sel.photos)
    status = np.zeros((len(sizes), n), dtype=np.int8)
    eye_seen = np.full((len(sizes), n), np.nan)
    ref_eye = np.full(n, np.nan)
    emb = {(i, k): np.zeros((n, 128), dtype=np.float32) for i in range(len(sizes)) for k in networks}
    ms = {(i, k): np.full(n, np.nan) for i in range(len(sizes)) for k in networks}
    bar = None if args.quiet else progress_bar(n, "embedding faces")
    unreadable = list(sel.unreadable)
    for j, (_, path) in enumerate(sel.photos):
        try:
            entries = runner.run(_file_key(path), lambda p=path: read_photo(p))
        except PhotoError:
            unreadable.append(str(path))
            status[:, j] = _NO_FACE
            entries = {}
        for i, size in enumerate(sizes):
            for k in networks:
                if (size, k) not in entries:
                    continue
                st, row, t_ms, e_seen, e_ref = entries[(size, k)]
                status[i, j] = st
                eye_seen[i, j] = e_seen
                ref_eye[j] = e_ref
                ms[(i, k)][j] = t_ms
                if st == _OK:
                    emb[(i, k)][j] = row
        if bar is not None:
            bar(j + 1, n)
    cache.save()

    ok_everywhere = np.all(status == _OK, axis=0)
    no_face = int(np.sum(np.any(status == _NO_FACE, axis=0)))
    id_index = {name: i for i, name in enumerate(sel.identities)}
    labels_all = np.array([id_index[identity] for identity, _ in sel.photos], dtype=np.intp)
    keep = np.flatnonzero(ok_everywhere)
    labels = labels_all[keep]
    scored_ids = np.unique(labels)
    if scored_ids.size < 2:
        raise _UsageError(f"fewer than 2 identities have a face enrolled at every size ({scored_ids.size})")
    split = open_set_split(labels, np.random.default_rng([args.seed, 1]))
    galleries = one_photo_galleries(labels, np.random.default_rng([args.seed, 2]), GALLERY_REPEATS)

    reports: list[SizeReport] = []
    for i, size in enumerate(sizes):
        scores = {k: score_matrix(emb[(i, k)][keep], _SCORE_KIND[k]) for k in networks}
        if "both" in embedders:
            scores["both"] = z_normalised(scores["dlib"]) + z_normalised(scores["sface"])
        timings = {k: ms[(i, k)][keep] for k in networks}
        if "both" in embedders:
            timings["both"] = timings["dlib"] + timings["sface"]
        metrics = {}
        for e in embedders:
            m = evaluate_scores(scores[e], labels, split, galleries)
            finite = timings[e][np.isfinite(timings[e])]
            m.ms_per_face = float(np.median(finite)) if finite.size else None
            metrics[e] = m
        failed = np.flatnonzero(status[i] == _ROI_MISS)
        target = None if size == FULL else float(size)
        smaller = 0 if target is None else int(np.sum(ref_eye[ok_everywhere] <= target))
        reports.append(SizeReport(
            eye_px=size,
            median_eye_px_seen=float(np.median(eye_seen[i, keep])),
            enrol_failures=int(failed.size),
            smaller_than_target=smaller,
            failed_photos=[str(sel.photos[j][1]) for j in failed[:_MAX_LISTED_FAILURES]],
            metrics=metrics,
        ))

    result: dict[str, Any] = {
        "faces_dir": str(folder),
        "eye_px": sizes,
        "embedders": embedders,
        "colour_only": bool(args.colour_only),
        "exclude": list(args.exclude),
        "max_identities": args.max_identities,
        "seed": args.seed,
        "protocol": {
            "reference_detection_max_side_px": DETECT_MAX_SIDE_PX,
            "shrink": "INTER_AREA, whole photo, by target / reference eye distance",
            "head_roi_side_per_eye_distance": HEAD_ROI_SIDE_PER_EYE_DISTANCE,
            "roi_input_size_px": ROI_INPUT_PX,
            "scores": {"dlib": "-L2", "sface": "cosine", "both": "z(dlib) + z(sface), per size over all pairs"},
            "scored_photos": "enrolled at every size",
            "fars": list(FARS),
            "fpir": FPIR,
            "one_photo_gallery_repeats": GALLERY_REPEATS,
        },
        "counts": {
            "identities_listed": sel.n_identities_listed,
            "photos_listed": sel.n_photos_listed,
            "ignored_non_image": sel.ignored_non_image,
            "excluded_photos": sel.excluded_photos,
            "excluded_identities": sel.excluded_identities,
            "grey_photos": sel.grey_photos,
            "grey_identities": sel.grey_identities,
            "unreadable": unreadable,
            "identities_evaluated": len(sel.identities),
            "photos_evaluated": n,
            "no_face": no_face,
            "identities_scored": int(scored_ids.size),
            "photos_scored": int(keep.size),
        },
        "open_set": {"gallery": int(split.gallery.size), "known_probes": int(split.known.size),
                     "unknown_probes": int(split.unknown.size)},
        "sizes": [asdict(r) for r in reports],
        "photos_computed": runner.computed,
        "photos_from_cache": n - runner.computed,
        "run_time_s": time.perf_counter() - started,
    }
    return result, render_markdown(result, reports, embedders)


def _json_safe(value: Any) -> Any:
    """NaN / inf -> None (strict JSON), recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def main(argv: Sequence[str] | None = None) -> int:
    from face_reid_camera.common.errors import ModelLoadError

    args = build_parser().parse_args(None if argv is None else list(argv))
    try:
        result, report = run(args)
    except (_UsageError, ValueError, FileNotFoundError, ModelLoadError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    print(report, end="")
    if args.json is not None:
        try:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(_json_safe(result), indent=2, allow_nan=False) + "\n", encoding="utf-8")
        except OSError as exc:
            print(f"{PROG}: error: cannot write {args.json}: {exc}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
