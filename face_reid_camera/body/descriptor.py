"""Body appearance descriptor of a person crop: per-part HSV colour + multi-scale SILTP texture histograms.

The crop is split into horizontal parts (head/shoulders, torso, upper and lower legs) so that a red
shirt over blue trousers differs from a blue shirt over red trousers: by fractions of the crop height for
a dataset crop (top of the head to the feet), or by each pixel's metric height above the floor for the
camera (``part_labels``, :mod:`face_reid_camera.body.person_body`). Each part gets a joint HSV
histogram and, at each of a few image scales (as in LOMO, Liao et al. 2015), a SILTP histogram. Every
part histogram sums to 1, so parts weigh the same whatever their size, visible area or crop resolution.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.body.hsv_histogram import check_hsv_bins, hsv_bin_index, hsv_soft_bins
from face_reid_camera.body.siltp import SILTP_CODES, siltp_codes_unchecked
from face_reid_camera.common.checks import check_colour_image, check_int, check_mask, check_real

__all__ = ["BodyDescriptor", "BodyDescriptorConfig", "body_descriptor"]


@dataclass(frozen=True)
class BodyDescriptorConfig:
    """How a crop is split and described; lists given for the tuple fields are stored as tuples."""

    # Fractions of the person's height from the top of the head, strictly increasing in [0, 1]: part p is
    # what lies from part_edges[p] to part_edges[p + 1] below the top (rows of a crop; metric heights at the
    # camera). Default: head/shoulders, torso, upper legs, lower legs.
    part_edges: tuple[float, ...] = (0.0, 0.2, 0.5, 0.75, 1.0)
    # Joint (h, s, v) bins of each part's colour histogram.
    hsv_bins: tuple[int, int, int] = (8, 8, 8)
    # Share saturation and value linearly between the two nearest bins (hue stays hard): brightness changes
    # of a few levels (distance to the light, camera gain) then move weight gradually, not whole pixels.
    hsv_soft: bool = True
    # SILTP relative tolerance in [0, 1) and neighbour distance (pixels, >= 1) at every scale.
    siltp_tau: float = 0.3
    siltp_radius: int = 3
    # Resize factors in (0, 1] of the crop (INTER_AREA) at which SILTP is taken: the same radius at a
    # smaller scale sees coarser texture (LOMO's multi-scale).
    siltp_scales: tuple[float, ...] = (1.0, 0.5)
    # Height (px) the grey crop is resized to (aspect kept) before the SILTP scales, None = as it comes:
    # the radius is in pixels, so without this a texture's codes would change with the person's distance.
    # 128 is the usual re-id crop (Market-1501's 128x64 crops are used as they are). Colour is not
    # resized: its part histograms are already independent of the resolution.
    siltp_height: int | None = 128

    def __post_init__(self) -> None:
        edges = _as_tuple("part_edges", self.part_edges)
        if len(edges) < 2:
            raise ValueError(f"part_edges must have at least 2 values (1 part), got {self.part_edges!r}")
        edges = tuple(check_real(f"part_edges[{i}]", e, 0.0, 1.0) for i, e in enumerate(edges))
        if any(b <= a for a, b in pairwise(edges)):
            raise ValueError(f"part_edges must be strictly increasing, got {self.part_edges!r}")
        scales = _as_tuple("siltp_scales", self.siltp_scales)
        if not scales:
            raise ValueError("siltp_scales must have at least one scale, got ()")
        scales = tuple(check_real(f"siltp_scales[{i}]", s, 0.0, 1.0, low_open=True) for i, s in enumerate(scales))
        object.__setattr__(self, "part_edges", edges)
        object.__setattr__(self, "hsv_bins", check_hsv_bins(self.hsv_bins, "hsv_bins"))
        if not isinstance(self.hsv_soft, bool):
            raise ValueError(f"hsv_soft must be a bool, got {self.hsv_soft!r}")
        object.__setattr__(self, "siltp_tau", check_real("siltp_tau", self.siltp_tau, 0.0, 1.0, high_open=True))
        object.__setattr__(self, "siltp_radius", check_int("siltp_radius", self.siltp_radius, 1))
        object.__setattr__(self, "siltp_scales", scales)
        if self.siltp_height is not None:
            object.__setattr__(self, "siltp_height", check_int("siltp_height", self.siltp_height, 1))

    @property
    def parts(self) -> int:
        """Number of horizontal parts (len(part_edges) - 1)."""
        return len(self.part_edges) - 1

    @property
    def hsv_length(self) -> int:
        """Length of :attr:`BodyDescriptor.hsv`: parts x bins[0] x bins[1] x bins[2]."""
        return self.parts * self.hsv_bins[0] * self.hsv_bins[1] * self.hsv_bins[2]

    @property
    def siltp_length(self) -> int:
        """Length of :attr:`BodyDescriptor.siltp`: parts x 81 x scales."""
        return self.parts * SILTP_CODES * len(self.siltp_scales)


@dataclass(frozen=True, eq=False)
class BodyDescriptor:
    """The descriptor of one crop; ``hsv`` and ``siltp`` are unit (or all-zero) vectors, read-only.

    ``hsv``: the part histograms one after the other (part-major). ``siltp``: for each scale in
    ``siltp_scales`` order, the part histograms one after the other (scale-major, then part).
    The cosine similarity of two descriptors' vectors is their dot product.
    """

    hsv: NDArray[np.float32]
    siltp: NDArray[np.float32]
    visible_fraction: float  # mask pixels / crop pixels (1.0 without a mask)


def _as_tuple(name: str, value: object) -> tuple:
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ValueError(f"{name} must be a sequence of numbers, got {value!r}")
    return tuple(value)


def _row_labels(height: int, edges: tuple[float, ...]) -> NDArray[np.int16]:
    """(height, 1) part of every row by the fractions ``edges`` (-1 outside [edges[0], edges[-1]))."""
    row_edges = np.round(np.asarray(edges) * height).astype(np.intp)
    part = np.searchsorted(row_edges, np.arange(height), side="right") - 1
    part[(np.arange(height) < row_edges[0]) | (np.arange(height) >= row_edges[-1])] = -1
    return part.astype(np.int16)[:, None]


def _labelled_histograms(
    index: NDArray[np.integer], labels: NDArray[np.integer], n_parts: int, n_bins: int,
    weights: NDArray[np.floating] | None = None,
) -> NDArray[np.float32]:
    """(parts, n_bins) histograms of the per-pixel bins ``index`` per part label (-1 = no part), rows summing
    to 1; empty parts stay all zeros. ``index`` (H, W), or (K, H, W) with ``weights`` of that shape (soft bins:
    K bins per pixel). ``labels`` broadcasts against (H, W). One bincount over (part, bin) keys."""
    # pixels of no part go to one extra trash part (cheaper than selecting the others), dropped after
    part = np.where(labels >= 0, labels, n_parts).astype(np.int32) * n_bins
    keys = (part + index).ravel()
    size = (n_parts + 1) * n_bins
    hist = np.bincount(keys, minlength=size) if weights is None else \
        np.bincount(keys, weights=weights.ravel(), minlength=size)
    hist = hist[: n_parts * n_bins]
    hist = hist.astype(np.float32).reshape(n_parts, n_bins)
    sums = hist.sum(axis=1, keepdims=True)
    np.divide(hist, sums, out=hist, where=sums > 0)
    return hist


def _resized(
    gray: NDArray[np.float32], inside: NDArray[np.bool_] | None, size: tuple[int, int],
) -> tuple[NDArray[np.float32], NDArray[np.bool_] | None]:
    """``gray`` and ``inside`` at ``size`` (w, h): pixel-area averaging when shrinking, bilinear when enlarging.

    A resized pixel is inside the mask when at least half of what it is interpolated from is.
    """
    interpolation = cv2.INTER_AREA if size[1] <= gray.shape[0] else cv2.INTER_LINEAR
    out = cv2.resize(gray, size, interpolation=interpolation)
    if inside is None:
        return out, None
    return out, cv2.resize(inside.astype(np.float32), size, interpolation=interpolation) >= 0.5


def _hellinger_unit(hists: NDArray[np.float32]) -> NDArray[np.float32]:
    """sqrt of the concatenated histograms, then L2-normalised (all zeros stay zeros), read-only.

    With the square root, the dot product of two sum-1 histograms is their Bhattacharyya coefficient
    (Hellinger kernel): frequent bins no longer dominate, which matches histograms better than raw L2
    or cosine does. The L2 normalisation then gives unit vectors for the cosine similarity.
    """
    vector = np.sqrt(hists.ravel())
    norm = float(np.linalg.norm(vector))
    if norm > 0.0:
        vector /= np.float32(norm)
    vector.setflags(write=False)
    return vector


def body_descriptor(
    bgr: NDArray[np.uint8], mask: NDArray | None = None, config: BodyDescriptorConfig = BodyDescriptorConfig(),
    part_labels: NDArray | None = None,
) -> BodyDescriptor:
    """The :class:`BodyDescriptor` of a person crop ``bgr`` ((H, W, 3) uint8, OpenCV BGR).

    ``mask`` (None = all pixels), bool/integer of shape (H, W), selects the person's pixels (e.g. from
    depth) so background and occluders are left out. ``part_labels`` (None = rows by ``part_edges``), an
    integer (H, W) array, gives each pixel's part (0 .. parts - 1; -1 = none), e.g. from its height above
    the floor. With ``part_labels`` the crop is taken at the scale it comes in (nothing is resized: give it
    the person's full height in ``siltp_height`` rows, as the camera does, or SILTP's pixel radius means
    something else). Each part uses its masked pixels.
    """
    check_colour_image(bgr, "bgr")
    if not isinstance(config, BodyDescriptorConfig):
        raise ValueError(f"config must be a BodyDescriptorConfig, got {type(config).__name__}")
    height, width = bgr.shape[:2]
    inside = check_mask(mask, (height, width))
    given = part_labels is not None

    def labels_at(rows: int, inside_now: NDArray[np.bool_] | None) -> NDArray[np.int16]:
        """Row-band labels of a crop of ``rows`` rows, masked (broadcasts as (rows, 1) without a mask)."""
        labels = _row_labels(rows, config.part_edges)
        return labels if inside_now is None else np.where(inside_now, labels, np.int16(-1))

    if given:
        labels = _check_part_labels(part_labels, (height, width), config)
        if inside is not None:
            labels = np.where(inside, labels, np.int16(-1))
    else:
        labels = labels_at(height, inside)
    hsv = _hsv_histograms(bgr, labels, config)

    gray, inside_g, labels_g = cv2.cvtColor(bgr.astype(np.float32), cv2.COLOR_BGR2GRAY), inside, labels
    if not given and config.siltp_height is not None and config.siltp_height != height:
        factor = config.siltp_height / height
        gray, inside_g = _resized(gray, inside, (max(1, round(width * factor)), config.siltp_height))
        labels_g = labels_at(config.siltp_height, inside_g)
    siltp = []
    for scale in config.siltp_scales:
        if scale == 1.0:
            gray_s, labels_s = gray, labels_g
        else:
            size = (max(1, round(gray.shape[1] * scale)), max(1, round(gray.shape[0] * scale)))
            if given:
                gray_s = _resized(gray, None, size)[0]
                labels_s = cv2.resize(labels_g, size, interpolation=cv2.INTER_NEAREST)
            else:
                gray_s, inside_s = _resized(gray, inside_g, size)
                labels_s = labels_at(size[1], inside_s)
        codes = siltp_codes_unchecked(gray_s, config.siltp_tau, config.siltp_radius)
        siltp.append(_labelled_histograms(codes, labels_s, config.parts, SILTP_CODES))

    visible = 1.0 if inside is None else float(np.count_nonzero(inside)) / inside.size
    return BodyDescriptor(_hellinger_unit(hsv), _hellinger_unit(np.concatenate(siltp)), visible)


def _hsv_histograms(bgr: NDArray[np.uint8], labels: NDArray[np.int16], config: BodyDescriptorConfig) -> NDArray:
    """Per part, the HSV histogram of its pixels (soft or hard binning as configured)."""
    bins = config.hsv_bins
    n_bins = bins[0] * bins[1] * bins[2]
    if config.hsv_soft:
        index, weights = hsv_soft_bins(bgr, bins)
        return _labelled_histograms(index, labels, config.parts, n_bins, weights)
    return _labelled_histograms(hsv_bin_index(bgr, bins), labels, config.parts, n_bins)


def _check_part_labels(labels: object, shape: tuple[int, int], config: BodyDescriptorConfig) -> NDArray[np.int16]:
    """Integer (H, W) part labels in [-1, parts) as int16."""
    if not isinstance(labels, np.ndarray) or labels.shape != shape or not np.issubdtype(labels.dtype, np.integer):
        got = f"{labels.dtype} {labels.shape}" if isinstance(labels, np.ndarray) else type(labels).__name__
        raise ValueError(f"part_labels must be an integer array of shape {shape}, got {got}")
    if labels.size and (int(labels.min()) < -1 or int(labels.max()) >= config.parts):
        raise ValueError(f"part_labels must be in [-1, {config.parts - 1}], "
                         f"got {int(labels.min())}..{int(labels.max())}")
    return labels.astype(np.int16, copy=False)
