"""Argument validators shared by every core constructor: one style, the argument named in each ValueError."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["check_bgr_image", "check_colour_image", "check_int", "check_mask", "check_real", "check_stamp",
           "is_finite_number"]


def shown(text: object, max_chars: int = 80) -> str:
    """``text`` quoted for a log line or a terminal: escaped (no newlines or terminal escapes) and cut to
    ``max_chars`` characters ("..." marks the cut)."""
    value = text if isinstance(text, str) else str(text)
    return repr(value[:max_chars]) + ("..." if len(value) > max_chars else "")


def is_finite_number(value: object) -> bool:
    """True for a finite int/float (numpy scalars included), False for bools, NaN, Inf and anything else."""
    return (
        isinstance(value, int | float | np.integer | np.floating)
        and not isinstance(value, bool | np.bool_)
        and math.isfinite(float(value))
    )


def check_int(name: str, value: Any, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an int within [minimum, maximum] (None = unbounded); ValueError naming ``name``."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name} must be an int, got {value!r}")
    v = int(value)
    if (minimum is not None and v < minimum) or (maximum is not None and v > maximum):
        low = "-inf" if minimum is None else minimum
        high = "inf" if maximum is None else maximum
        raise ValueError(f"{name} must be in [{low}, {high}], got {v}")
    return v


def check_real(
    name: str, value: Any, low: float = -math.inf, high: float = math.inf, *,
    low_open: bool = False, high_open: bool = False, allow_inf: bool = False,
) -> float:
    """``value`` as a float within the interval (``low_open`` / ``high_open``: exclusive ends).

    NaN is always refused, +-inf only with ``allow_inf``; ValueError names ``name`` and the interval.
    """
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name} must be a number, got {value!r}")
    v = float(value)
    ok = not math.isnan(v) and (allow_inf or math.isfinite(v))
    ok = ok and (v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not ok:
        lb, rb = ("(" if low_open else "["), (")" if high_open else "]")
        raise ValueError(f"{name} must be a {'' if allow_inf else 'finite '}number in {lb}{low}, {high}{rb}, "
                         f"got {value!r}")
    return v


def check_stamp(value: Any, name: str = "stamp_s") -> float:
    """A finite time in seconds."""
    return check_real(name, value)


def check_colour_image(image: object, name: str = "image") -> np.ndarray:
    """:func:`check_bgr_image` that also refuses grey images: a non-empty (H, W, 3) uint8 BGR image."""
    out = check_bgr_image(image, name)
    if out.ndim != 3:
        raise ValueError(f"{name} must be a (H, W, 3) colour image, got shape {out.shape}")
    return out


def check_bgr_image(image: object, name: str = "image", *, allow_bgra: bool = False) -> np.ndarray:
    """A non-empty uint8 (H, W) grey or (H, W, 3) BGR image ((H, W, 1) is squeezed; (H, W, 4) with ``allow_bgra``)."""
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ValueError(f"{name} must be uint8 (bgr8 or mono8), got dtype {image.dtype}")
    out = image[:, :, 0] if image.ndim == 3 and image.shape[2] == 1 else image
    channels = (3, 4) if allow_bgra else (3,)
    if not (out.ndim == 2 or (out.ndim == 3 and out.shape[2] in channels)):
        shapes = "(H, W), (H, W, 1) or (H, W, 3)" + (" or (H, W, 4)" if allow_bgra else "")
        raise ValueError(f"{name} must have shape {shapes}, got {image.shape}")
    if out.shape[0] == 0 or out.shape[1] == 0:
        raise ValueError(f"{name} must not be empty, got shape {image.shape}")
    return out


def check_mask(mask: object, shape: tuple[int, ...], name: str = "mask") -> npt.NDArray[np.bool_] | None:
    """``mask`` as a bool array of ``shape`` (None stays None); bool or integer dtype, nonzero = inside."""
    if mask is None:
        return None
    if not isinstance(mask, np.ndarray):
        raise ValueError(f"{name} must be a numpy array or None, got {type(mask).__name__}")
    if mask.shape != shape:
        raise ValueError(f"{name} must have the image's shape {shape}, got {mask.shape}")
    if mask.dtype != np.bool_ and not np.issubdtype(mask.dtype, np.integer):
        raise ValueError(f"{name} must be bool or integer (nonzero = inside), got dtype {mask.dtype}")
    return mask.astype(np.bool_, copy=False)
