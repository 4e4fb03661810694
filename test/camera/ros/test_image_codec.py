"""Decoding sensor_msgs/Image fields: every supported encoding, strides, endianness, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_camera.ros.image_codec import (
    ImageDecodeError,
    decode_image,
    depth_to_metres,
    encode_image,
    to_bgr,
)


@pytest.mark.parametrize("encoding,shape,dtype", [
    ("bgr8", (4, 5, 3), np.uint8), ("rgb8", (4, 5, 3), np.uint8), ("mono8", (4, 5), np.uint8),
    ("bgra8", (4, 5, 4), np.uint8), ("16UC1", (4, 5), np.uint16), ("32FC1", (4, 5), np.float32),
])
def test_round_trip(encoding: str, shape: tuple[int, ...], dtype: type) -> None:
    rng = np.random.default_rng(0)
    image = (rng.random(shape) * 200).astype(dtype)
    h, w, step, data = encode_image(image, encoding)
    assert np.array_equal(decode_image(encoding, h, w, step, data), image)


def test_row_padding_is_skipped() -> None:
    image = np.arange(12, dtype=np.uint8).reshape(3, 4)
    padded = np.zeros((3, 8), dtype=np.uint8)
    padded[:, :4] = image
    assert np.array_equal(decode_image("mono8", 3, 4, 8, padded.tobytes()), image)


def test_big_endian_depth() -> None:
    depth = np.array([[1000, 2500], [0, 65535]], dtype=np.uint16)
    data = depth.astype(">u2").tobytes()
    assert np.array_equal(decode_image("16UC1", 2, 2, 4, data, is_bigendian=True), depth)


def test_rgb_becomes_bgr_and_grey_is_replicated() -> None:
    rgb = np.zeros((2, 2, 3), dtype=np.uint8)
    rgb[..., 0] = 255  # red
    bgr = to_bgr(rgb, "rgb8")
    assert bgr[0, 0].tolist() == [0, 0, 255]
    grey = np.full((2, 2), 7, dtype=np.uint8)
    assert to_bgr(grey, "mono8").shape == (2, 2, 3)


def test_depth_units_and_invalid_pixels() -> None:
    mm = np.array([[0, 1500]], dtype=np.uint16)
    metres = depth_to_metres(mm, "16UC1")
    assert np.isnan(metres[0, 0]) and metres[0, 1] == pytest.approx(1.5)
    f = np.array([[np.nan, -1.0, 2.25, np.inf]], dtype=np.float32)
    out = depth_to_metres(f, "32FC1")
    assert np.isnan(out[0, :2]).all() and out[0, 2] == pytest.approx(2.25) and np.isnan(out[0, 3])


@pytest.mark.parametrize("args,match", [
    (("yuv422", 2, 2, 4, bytes(8)), "unsupported"),
    (("mono8", 2, 2, 1, bytes(4)), "step"),
    (("mono8", 2, 2, 2, bytes(3)), "expected"),
    (("mono8", 0, 2, 2, b""), "no pixels"),
])
def test_malformed_images_are_rejected(args: tuple, match: str) -> None:
    with pytest.raises(ImageDecodeError, match=match):
        decode_image(*args)


def test_wrong_kind_of_encoding_is_rejected() -> None:
    with pytest.raises(ImageDecodeError, match="depth image"):
        depth_to_metres(np.zeros((2, 2), np.uint8), "mono8")
    with pytest.raises(ImageDecodeError, match="colour image"):
        to_bgr(np.zeros((2, 2), np.uint16), "16UC1")
