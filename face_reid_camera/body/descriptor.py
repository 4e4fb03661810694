"""Body descriptor of one person crop: HSV and multi-scale SILTP histograms per horizontal body part.

Parts are bands of the crop's height (head and shoulders, torso, upper legs, lower legs by default), so a
descriptor compares like with like whatever the person's distance; only the pixels of the mask (the
person, not the background) count. Each feature is square-rooted (Hellinger: histograms then compare by
their overlap rather than by their largest bins) and L2-normalised.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from face_reid_camera.body.hsv_histogram import hsv_histogram
from face_reid_camera.body.siltp import siltp_histogram

__all__ = ["BodyDescriptor", "BodyDescriptorConfig", "body_descriptor"]


@dataclass(frozen=True)
class BodyDescriptorConfig:
    """``part_edges``: band limits as fractions of the crop height from the top (increasing, 0 .. 1).
    ``hsv_bins``: (h, s, v) bins of the colour histogram. ``siltp_tau``, ``siltp_radius`` (px): the texture
    code's tolerance and neighbour distance. ``siltp_scales``: the crop is also shrunk by these factors
    (0 < f <= 1) and textured again, so coarse patterns count too."""

    part_edges: tuple[float, ...] = (0.0, 0.2, 0.5, 0.75, 1.0)
    hsv_bins: tuple[int, int, int] = (8, 8, 8)
    siltp_tau: float = 0.3
    siltp_radius: int = 3
    siltp_scales: tuple[float, ...] = (1.0, 0.5)

    def __post_init__(self) -> None:
        e = self.part_edges
        if len(e) < 2 or e[0] != 0.0 or e[-1] != 1.0 or any(b <= a for a, b in itertools.pairwise(e)):
            raise ValueError(f"part_edges must increase from 0.0 to 1.0, got {e}")
        if not self.siltp_scales or any(not 0.0 < f <= 1.0 for f in self.siltp_scales):
            raise ValueError(f"siltp_scales must be factors in (0, 1], got {self.siltp_scales}")
        if not 0.0 <= self.siltp_tau < 1.0:
            raise ValueError(f"siltp_tau must be in [0, 1), got {self.siltp_tau}")
        if self.siltp_radius < 1:
            raise ValueError(f"siltp_radius must be >= 1, got {self.siltp_radius}")

    @property
    def parts(self) -> int:
        return len(self.part_edges) - 1


@dataclass(frozen=True)
class BodyDescriptor:
    """``hsv`` (parts x prod(hsv_bins)) and ``siltp`` (parts x 81 x scales), each unit length;
    ``visible_fraction``: mask pixels / crop pixels."""

    hsv: npt.NDArray[np.float32]
    siltp: npt.NDArray[np.float32]
    visible_fraction: float


def _normalised(v: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    v = np.sqrt(v)
    n = float(np.linalg.norm(v))
    return (v / n if n > 0 else v).astype(np.float32)


def body_descriptor(bgr: npt.ArrayLike, mask: npt.ArrayLike | None = None,
                    config: BodyDescriptorConfig = BodyDescriptorConfig()) -> BodyDescriptor:
    """The descriptor of a BGR uint8 crop (``mask``: the person's pixels, None = all)."""
    img = np.asarray(bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or min(img.shape[:2]) < 2:
        raise ValueError(f"bgr must be an (H >= 2, W >= 2, 3) uint8 crop, got {img.shape} {img.dtype}")
    h = img.shape[0]
    m = np.ones(img.shape[:2], dtype=bool) if mask is None else np.asarray(mask).astype(bool)
    if m.shape != img.shape[:2]:
        raise ValueError(f"mask must have the crop's shape {img.shape[:2]}, got {m.shape}")
    rows = [round(f * h) for f in config.part_edges]
    hsv = [hsv_histogram(img[a:b], m[a:b], config.hsv_bins) for a, b in itertools.pairwise(rows)]
    gray = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2GRAY).astype(np.float32) + 1.0  # no zero centre
    texture = []
    for f in config.siltp_scales:
        if f == 1.0:
            g, mk = gray, m
        else:
            size = (max(2, round(gray.shape[1] * f)), max(2, round(gray.shape[0] * f)))
            g = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
            mk = cv2.resize(m.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
        r = [round(e * g.shape[0]) for e in config.part_edges]
        texture += [siltp_histogram(g[a:b], mk[a:b], config.siltp_tau, config.siltp_radius)
                    for a, b in itertools.pairwise(r)]
    return BodyDescriptor(_normalised(np.concatenate(hsv)), _normalised(np.concatenate(texture)),
                          float(m.mean()))
