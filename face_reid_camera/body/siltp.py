"""SILTP (Liao et al., CVPR 2010): a texture code that ignores intensity scale and small noise.

Each of 4 neighbours at ``radius`` pixels (right, up, left, down) is compared with the centre I_c within a
tolerance relative to I_c: digit 1 if brighter than (1 + tau) I_c, 2 if darker than (1 - tau) I_c, else 0;
the code sum_k digit_k 3^k has 81 values. Multiplying the image by a constant changes no code, unlike LBP's
absolute comparisons, so shadows and exposure changes leave the texture histogram alone.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real

__all__ = ["SILTP_CODES", "siltp_codes", "siltp_histogram"]

SILTP_CODES = 81  # 3 ** 4
_OFFSETS = ((0, 1), (-1, 0), (0, -1), (1, 0))  # (row, col) unit steps: right, up, left, down


def _as_gray(gray: npt.ArrayLike) -> npt.NDArray[np.float32]:
    g = np.asarray(gray)
    if g.ndim != 2 or g.size == 0:
        raise ValueError(f"gray must be a non-empty 2-D image, got shape {g.shape}")
    return g.astype(np.float32, copy=False)


def siltp_codes(gray: npt.ArrayLike, tau: float = 0.3, radius: int = 3) -> npt.NDArray[np.uint8]:
    """SILTP code (0..80) of every pixel; neighbours beyond the border take the nearest edge pixel.

    ``tau``: tolerance relative to the centre's intensity, in [0, 1). ``radius``: neighbour distance (px, >= 1).
    """
    t = check_real("tau", tau, 0.0, 1.0, high_open=True)
    r = check_int("radius", radius, 1)
    g = _as_gray(gray)
    padded = np.pad(g, r, mode="edge")
    h, w = g.shape
    hi, lo = (1.0 + t) * g, (1.0 - t) * g
    codes = np.zeros(g.shape, dtype=np.uint8)
    for k, (dr, dc) in enumerate(_OFFSETS):
        nb = padded[r + dr * r: r + dr * r + h, r + dc * r: r + dc * r + w]
        digit = np.where(nb > hi, 1, np.where(nb < lo, 2, 0)).astype(np.uint8)
        codes += digit * np.uint8(3**k)
    return codes


def siltp_histogram(gray: npt.ArrayLike, mask: npt.ArrayLike | None = None, tau: float = 0.3, radius: int = 3
                    ) -> npt.NDArray[np.float32]:
    """Histogram (81 bins, sum 1; all 0 without pixels) of the SILTP codes of the pixels where ``mask``."""
    codes = siltp_codes(gray, tau, radius)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != codes.shape:
            raise ValueError(f"mask must have the image's shape {codes.shape}, got {m.shape}")
        codes = codes[m.astype(bool)]
    hist = np.bincount(codes.ravel(), minlength=SILTP_CODES).astype(np.float32)
    total = hist.sum()
    return hist / total if total > 0 else hist
