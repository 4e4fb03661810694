"""Decode raw ``sensor_msgs/Image`` fields into numpy arrays (no cv_bridge, no rclpy).

The node passes the message fields in; everything here is plain numpy so it is unit-tested
directly and shared by the node, the replay tool and the tests' publishers.
"""

from __future__ import annotations

import sys

import numpy as np
from numpy.typing import NDArray

# encoding -> (numpy dtype, channels)
_ENCODINGS: dict[str, tuple[np.dtype, int]] = {
    "bgr8": (np.dtype(np.uint8), 3),
    "rgb8": (np.dtype(np.uint8), 3),
    "bgra8": (np.dtype(np.uint8), 4),
    "rgba8": (np.dtype(np.uint8), 4),
    "mono8": (np.dtype(np.uint8), 1),
    "8UC1": (np.dtype(np.uint8), 1),
    "8UC3": (np.dtype(np.uint8), 3),
    "mono16": (np.dtype(np.uint16), 1),
    "16UC1": (np.dtype(np.uint16), 1),
    "32FC1": (np.dtype(np.float32), 1),
}

COLOR_ENCODINGS = frozenset({"bgr8", "rgb8", "bgra8", "rgba8", "mono8", "8UC1", "8UC3"})
DEPTH_ENCODINGS = frozenset({"16UC1", "mono16", "32FC1"})


class ImageDecodeError(ValueError):
    """The image fields are inconsistent or the encoding is not supported."""


def decode_image(
    encoding: str, height: int, width: int, step: int, data: bytes | bytearray | memoryview,
    is_bigendian: bool = False,
) -> NDArray:
    """Return an (H, W) or (H, W, C) array viewing ``data`` as described by the message fields."""
    if encoding not in _ENCODINGS:
        raise ImageDecodeError(f"unsupported image encoding {encoding!r}; supported: {sorted(_ENCODINGS)}")
    if height <= 0 or width <= 0:
        raise ImageDecodeError(f"image has no pixels ({width}x{height})")
    dtype, channels = _ENCODINGS[encoding]
    row_bytes = width * channels * dtype.itemsize
    if step < row_bytes:
        raise ImageDecodeError(f"step {step} B is smaller than one row of {width} px {encoding} ({row_bytes} B)")
    buf = np.frombuffer(data, dtype=np.uint8)
    if buf.size < step * height:
        raise ImageDecodeError(f"image data has {buf.size} B, expected step*height = {step * height} B")
    rows = buf[: step * height].reshape(height, step)[:, :row_bytes]
    big = is_bigendian and dtype.itemsize > 1
    typed_dtype = dtype.newbyteorder(">") if big else dtype
    array = np.ascontiguousarray(rows).view(typed_dtype)
    if big and sys.byteorder == "little":
        array = array.astype(dtype)
    shape = (height, width) if channels == 1 else (height, width, channels)
    return array.reshape(shape)


def to_bgr(image: NDArray, encoding: str) -> NDArray[np.uint8]:
    """Convert a decoded colour image to contiguous BGR uint8 (grey images are replicated)."""
    if encoding not in COLOR_ENCODINGS:
        raise ImageDecodeError(
            f"colour image has encoding {encoding!r}; expected one of {sorted(COLOR_ENCODINGS)}"
        )
    if image.ndim == 2:
        return np.ascontiguousarray(np.repeat(image[:, :, None], 3, axis=2))
    if encoding in ("rgb8", "rgba8"):
        return np.ascontiguousarray(image[:, :, 2::-1])
    return np.ascontiguousarray(image[:, :, :3])


def depth_to_metres(image: NDArray, encoding: str) -> NDArray[np.float32]:
    """Convert a decoded depth image to float32 metres; invalid pixels become NaN.

    16UC1 / mono16 are millimetres with 0 = no return (the ROS convention); 32FC1 is metres.
    """
    if encoding not in DEPTH_ENCODINGS:
        raise ImageDecodeError(f"depth image has encoding {encoding!r}; expected 16UC1 (mm) or 32FC1 (m)")
    if encoding == "32FC1":
        depth = image.astype(np.float32, copy=True)
        depth[~np.isfinite(depth) | (depth <= 0)] = np.nan
        return depth
    depth = image.astype(np.float32) * np.float32(0.001)
    depth[image == 0] = np.nan
    return depth


def encode_image(image: NDArray, encoding: str) -> tuple[int, int, int, bytes]:
    """Inverse of :func:`decode_image` for publishers: returns (height, width, step, data)."""
    if encoding not in _ENCODINGS:
        raise ImageDecodeError(f"unsupported image encoding {encoding!r}")
    dtype, channels = _ENCODINGS[encoding]
    array = np.ascontiguousarray(image, dtype=dtype)
    if (channels == 1 and array.ndim != 2) or (channels > 1 and (array.ndim != 3 or array.shape[2] != channels)):
        raise ImageDecodeError(f"array of shape {image.shape} does not match encoding {encoding}")
    height, width = array.shape[:2]
    return height, width, width * channels * dtype.itemsize, array.tobytes()
