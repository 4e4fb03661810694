"""Scale Invariant Local Ternary Pattern, SILTP_{N=4,R}^tau (Liao et al., CVPR 2010).

Each pixel compares its 4 neighbours at distance R against a band of +-tau * I_c around its own grey
value I_c, so the code is unchanged when the image is scaled by a constant (a global illumination
gain) and robust to noise inside the band: the texture part of the LOMO re-identification descriptor.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import check_int, check_mask, check_real

__all__ = ["SILTP_CODES", "siltp_codes", "siltp_codes_unchecked", "siltp_histogram"]

SILTP_CODES = 81  # 3 ** 4: four ternary digits
# (row, col) direction of neighbour k = 0..3 (right, up, left, down); digit k has weight 3 ** k.
_DIRECTIONS = ((0, 1), (-1, 0), (0, -1), (1, 0))


def _check_gray(gray: object) -> NDArray[np.float32]:
    """A non-empty, finite, non-negative 2-D real image as float32."""
    if not isinstance(gray, np.ndarray):
        raise ValueError(f"gray must be a numpy array, got {type(gray).__name__}")
    if gray.ndim != 2 or gray.size == 0:
        raise ValueError(f"gray must be a non-empty 2-D image, got shape {gray.shape}")
    if gray.dtype == np.bool_ or not (np.issubdtype(gray.dtype, np.integer) or np.issubdtype(gray.dtype, np.floating)):
        raise ValueError(f"gray must have an integer or float dtype, got {gray.dtype}")
    out = gray.astype(np.float32, copy=False)
    if not np.all(np.isfinite(out)) or float(out.min()) < 0.0:
        raise ValueError("gray must be finite and non-negative (an intensity image)")
    return out


def _check_params(tau: float, radius: int) -> tuple[float, int]:
    return check_real("tau", tau, 0.0, 1.0, high_open=True), check_int("radius", radius, 1)


def siltp_codes_unchecked(gray: NDArray[np.float32], tau: float, radius: int) -> NDArray[np.uint8]:
    """:func:`siltp_codes` without the argument checks (``gray`` already a valid float32 image)."""
    h, w = gray.shape
    padded = cv2.copyMakeBorder(gray, radius, radius, radius, radius, cv2.BORDER_REPLICATE)
    centre = padded[radius:radius + h, radius:radius + w]
    upper = centre * np.float32(1.0 + tau)
    lower = centre * np.float32(1.0 - tau)
    codes = np.zeros((h, w), np.uint8)
    for k, (dr, dc) in enumerate(_DIRECTIONS):
        r0, c0 = radius + dr * radius, radius + dc * radius
        neighbour = padded[r0:r0 + h, c0:c0 + w]
        codes += (neighbour > upper).view(np.uint8) * np.uint8(3**k)
        codes += (neighbour < lower).view(np.uint8) * np.uint8(2 * 3**k)
    return codes


def siltp_codes(gray: NDArray, tau: float = 0.3, radius: int = 3) -> NDArray[np.uint8]:
    """The SILTP code (0..80) of every pixel of the grey image ``gray`` (same shape).

    ``tau`` in [0, 1) is the relative tolerance: a neighbour counts as brighter only above
    (1 + tau) * I_c and as darker only below (1 - tau) * I_c; 0 compares exactly, LOMO uses 0.3.
    ``radius`` >= 1 is the neighbour distance in pixels (LOMO uses 3 and 5 on 128x48 persons); a few
    pixels, well under the image's smaller side, or most neighbours fall on the replicated border.
    Neighbour k = 0..3 (right, up, left, down) adds 1 * 3**k when brighter and 2 * 3**k when darker;
    neighbours outside the image take the nearest edge pixel (replicate padding). ``gray`` is any
    non-negative real 2-D image (converted to float32).
    """
    tau, radius = _check_params(tau, radius)
    return siltp_codes_unchecked(_check_gray(gray), tau, radius)


def siltp_histogram(
    gray: NDArray, mask: NDArray | None = None, tau: float = 0.3, radius: int = 3,
) -> NDArray[np.float32]:
    """The 81-bin histogram of the SILTP codes over the pixels where ``mask`` is true, summing to 1.

    ``mask`` (None = all pixels) has the image's shape; all zeros when no pixel is selected.
    ``tau`` and ``radius`` as in :func:`siltp_codes`.
    """
    tau, radius = _check_params(tau, radius)
    image = _check_gray(gray)
    inside = check_mask(mask, image.shape)
    codes = siltp_codes_unchecked(image, tau, radius)
    selected = codes.ravel() if inside is None else codes[inside]
    hist = np.bincount(selected, minlength=SILTP_CODES).astype(np.float32)
    total = float(hist.sum())
    return hist / np.float32(total) if total > 0 else hist
