"""Joint HSV colour histogram of an image region: the colour part of a body appearance descriptor.

Hue and saturation describe the clothes' colour largely independently of the brightness, which varies
between cameras and with the distance to the lights; a joint (h, s, v) histogram keeps which hue goes
with which saturation and brightness, which three separate channel histograms would lose.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import check_colour_image, check_int, check_mask

__all__ = ["HSV_RANGES", "check_hsv_bins", "hsv_bin_index", "hsv_histogram", "hsv_soft_bins"]

HSV_RANGES = (180, 256, 256)  # OpenCV 8-bit HSV: H in 0..179 (degrees / 2), S and V in 0..255


def check_hsv_bins(bins: Sequence[int], name: str = "bins") -> tuple[int, int, int]:
    """``bins`` as three ints, each in [1, that channel's number of values] (180 for H, 256 for S, V)."""
    if isinstance(bins, str) or not isinstance(bins, Sequence) or len(bins) != 3:
        raise ValueError(f"{name} must be three bin counts (h, s, v), got {bins!r}")
    h, s, v = (check_int(f"{name}[{i}]", b, 1, high) for i, (b, high) in enumerate(zip(bins, HSV_RANGES, strict=True)))
    return h, s, v


@lru_cache(maxsize=8)
def _bin_tables(bins: tuple[int, int, int]) -> tuple[NDArray[np.int32], ...]:
    """Per channel, value (0..255) -> that channel's share of the flat bin index, read-only."""
    values = np.arange(256)
    strides = (bins[1] * bins[2], bins[2], 1)
    tables = []
    for b, n, stride in zip(bins, HSV_RANGES, strides, strict=True):
        table = (np.minimum(values, n - 1) * b // n * stride).astype(np.int32)
        table.setflags(write=False)
        tables.append(table)
    return tuple(tables)


def hsv_bin_index(bgr: NDArray[np.uint8], bins: tuple[int, int, int]) -> NDArray[np.int32]:
    """The flat (h, s, v) C-order bin of every pixel of a valid ``bgr`` image, shape (H, W); no checks.

    Bin of a channel value x with range n split into b bins: x * b // n (looked up in 256-entry tables).
    """
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    h_table, s_table, v_table = _bin_tables(bins)
    index = np.take(h_table, hsv[:, :, 0])
    index += np.take(s_table, hsv[:, :, 1])
    index += np.take(v_table, hsv[:, :, 2])
    return index


@lru_cache(maxsize=8)
def _soft_tables(bins: tuple[int, int, int]) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.float32], ...]:
    """For S and V: value -> (lower bin share of the flat index, upper bin share, weight of the upper bin).

    Linear interpolation between bin centres: a value at a centre goes to its bin alone, one halfway between
    two centres half to each; values beyond the outer centres stay in the outer bin.
    """
    values = np.arange(256, dtype=np.float64)
    out: list[NDArray] = []
    for b, n, stride in ((bins[1], HSV_RANGES[1], bins[2]), (bins[2], HSV_RANGES[2], 1)):
        t = (values + 0.5) * b / n - 0.5  # position in bin units, 0 = the first bin's centre
        low = np.clip(np.floor(t), 0, b - 1)
        frac = np.clip(t - low, 0.0, 1.0)
        high = np.minimum(low + 1, b - 1)
        for table in ((low * stride).astype(np.int32), (high * stride).astype(np.int32), frac.astype(np.float32)):
            table.setflags(write=False)
            out.append(table)
    return tuple(out)


def hsv_soft_bins(bgr: NDArray[np.uint8], bins: tuple[int, int, int]) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
    """Soft (h, s, v) bins of every pixel of a valid ``bgr`` image: indices and weights, each (4, H, W).

    Hue is binned hard (:func:`hsv_bin_index`); saturation and value are shared linearly between the two
    nearest bins, so a brightness change of a few levels (another distance to the light, another camera's
    gain) moves weight gradually instead of flipping pixels into the next bin. The 4 weights sum to 1.
    """
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    h_table = _bin_tables(bins)[0]
    s_low, s_high, s_frac, v_low, v_high, v_frac = _soft_tables(bins)
    hue = np.take(h_table, hsv[:, :, 0])
    s, v = hsv[:, :, 1], hsv[:, :, 2]
    ws, wv = np.take(s_frac, s), np.take(v_frac, v)
    sl, sh, vl, vh = np.take(s_low, s), np.take(s_high, s), np.take(v_low, v), np.take(v_high, v)
    index = np.stack([hue + sl + vl, hue + sl + vh, hue + sh + vl, hue + sh + vh])
    weights = np.stack([(1 - ws) * (1 - wv), (1 - ws) * wv, ws * (1 - wv), ws * wv])
    return index, weights


def hsv_histogram(
    bgr: NDArray[np.uint8], mask: NDArray | None = None, bins: Sequence[int] = (8, 8, 8),
) -> NDArray[np.float32]:
    """Joint HSV histogram (bins[0] * bins[1] * bins[2] values, (h, s, v) C order) of the masked pixels.

    ``bgr`` is an (H, W, 3) uint8 OpenCV image, ``mask`` (None = all pixels) bool/integer of shape
    (H, W). Normalised to sum 1; all zeros when no pixel is selected.
    """
    image = check_colour_image(bgr, "bgr")
    counts = check_hsv_bins(bins)
    inside = check_mask(mask, image.shape[:2])
    index = hsv_bin_index(image, counts)
    selected = index.ravel() if inside is None else index[inside]
    hist = np.bincount(selected, minlength=counts[0] * counts[1] * counts[2]).astype(np.float32)
    total = float(hist.sum())
    return hist / np.float32(total) if total > 0 else hist
