"""Joint HSV colour histogram of a person's pixels: hue and saturation carry the clothes' colour, value
their brightness, and a coarse joint binning tolerates the light changing between cameras."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

__all__ = ["hsv_histogram"]

_RANGES = (180, 256, 256)  # OpenCV's 8-bit HSV: H in 0..179, S and V in 0..255


def hsv_histogram(bgr: npt.ArrayLike, mask: npt.ArrayLike | None = None, bins: tuple[int, int, int] = (8, 8, 8)
                  ) -> npt.NDArray[np.float32]:
    """Histogram (prod(bins) values in (h, s, v) order, sum 1; all 0 without pixels) of the pixels of a BGR
    uint8 image where ``mask``; channel value v falls in bin v * bins / range."""
    img = np.asarray(bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or img.size == 0:
        raise ValueError(f"bgr must be a non-empty (H, W, 3) uint8 image, got {img.shape} {img.dtype}")
    if len(bins) != 3 or any(int(b) < 1 or int(b) > r for b, r in zip(bins, _RANGES, strict=True)):
        raise ValueError(f"bins must be 3 counts within 1..(180, 256, 256), got {bins}")
    hsv = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2HSV).reshape(-1, 3).astype(np.int32)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != img.shape[:2]:
            raise ValueError(f"mask must have the image's shape {img.shape[:2]}, got {m.shape}")
        hsv = hsv[m.reshape(-1).astype(bool)]
    b = np.array(bins, dtype=np.int32)
    idx = hsv * b // np.array(_RANGES, dtype=np.int32)
    flat = (idx[:, 0] * b[1] + idx[:, 1]) * b[2] + idx[:, 2]
    hist = np.bincount(flat, minlength=int(np.prod(b))).astype(np.float32)
    total = hist.sum()
    return hist / total if total > 0 else hist
