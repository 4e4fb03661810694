"""Body descriptors of labelled crops, computed by the camera's own code: one way for every offline tool.

Dataset crops are cut from the top of the head to the feet, so the descriptor's default row bands are the
parts (the camera uses metric heights instead). They have no depth mask: the central ``CROP_SILHOUETTE``
share of the columns stands in for it (the camera cuts the person out by depth, so the background beside
them must not count when the projection and the metric are fitted on crops, nor in the simulator).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
import numpy.typing as npt

from face_reid_camera.body.descriptor import BodyDescriptorConfig, body_descriptor
from face_reid_camera.body.projection import FEATURES, descriptor_features
from face_reid_camera.faces.photos import PhotoError, progress_bar, read_photo
from face_reid_master.training.body.crops import Crop

__all__ = ["CROP_SILHOUETTE", "CropDescriptors", "crop_person_mask", "describe_crops"]

CROP_SILHOUETTE = 0.5  # central share of a dataset crop's columns taken as the person


def crop_person_mask(height: int, width: int, silhouette: float = CROP_SILHOUETTE) -> npt.NDArray[np.bool_]:
    """(height, width) mask of a crop's central ``silhouette`` share of columns (in (0, 1]; 1 = every pixel)."""
    if not 0.0 < silhouette <= 1.0:
        raise ValueError(f"silhouette must be in (0, 1], got {silhouette!r}")
    half = max(1, round(silhouette * width / 2.0))
    cols = np.zeros(width, dtype=bool)
    cols[max(0, width // 2 - half): width // 2 + half] = True
    return np.broadcast_to(cols, (height, width))


@dataclass(frozen=True)
class CropDescriptors:
    """The readable ``crops`` (in the given order), their descriptors per block of ``FEATURES`` ((n, d) float32,
    as the camera makes them), the unreadable files and the mean descriptor time per crop (ms)."""

    crops: list[Crop]
    features: dict[str, npt.NDArray[np.float32]]
    skipped: list[Path]
    ms_per_crop: float
    config: BodyDescriptorConfig

    @property
    def labels(self) -> npt.NDArray[np.str_]:
        """The identity of every crop."""
        return np.array([c.identity for c in self.crops])

    @property
    def cameras(self) -> list[str]:
        """The camera of every crop ("" = unknown)."""
        return [c.camera for c in self.crops]


def describe_crops(crops: Sequence[Crop], config: BodyDescriptorConfig | None = None,
                   log: TextIO | None = None, silhouette: float = CROP_SILHOUETTE) -> CropDescriptors:
    """Describe every crop with :func:`body_descriptor` (row-band parts, the central ``silhouette`` of the
    columns; ``config`` None = the default); unreadable files are skipped (named on ``log``, which also gets a
    progress bar). ValueError if no crop can be read."""
    config = BodyDescriptorConfig() if config is None else config
    bar = progress_bar(len(crops), "describing crops", log) if log else None
    rows: dict[str, list[npt.NDArray[np.float32]]] = {b: [] for b in FEATURES}
    kept: list[Crop] = []
    skipped: list[Path] = []
    spent = 0.0
    for k, crop in enumerate(crops, 1):
        try:
            image = read_photo(crop.path)
        except PhotoError as exc:
            skipped.append(crop.path)
            if log:
                print(f"skipped: {exc}", file=log)
            if bar:
                bar(k)
            continue
        t0 = time.perf_counter()
        d = body_descriptor(image, crop_person_mask(*image.shape[:2], silhouette), config)
        spent += time.perf_counter() - t0
        for name, vector in descriptor_features(d).items():
            rows[name].append(vector)
        kept.append(crop)
        if bar:
            bar(k)
    if not kept:
        raise ValueError("no crop could be read")
    features = {b: np.asarray(rows[b], dtype=np.float32) for b in FEATURES}
    return CropDescriptors(kept, features, skipped, 1e3 * spent / len(kept), config)
