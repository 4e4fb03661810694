"""Joint HSV histogram: hand-computed bins of known colours, masks, bin layout, argument checks."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_camera.body.hsv_histogram import hsv_histogram, hsv_soft_bins

# BGR: pure blue, pure red / white, black.
_COLOURS = np.array([[[255, 0, 0], [0, 0, 255]],
                     [[255, 255, 255], [0, 0, 0]]], np.uint8)


def test_known_colours_fall_in_the_hand_computed_bins() -> None:
    hist = hsv_histogram(_COLOURS)
    assert hist.dtype == np.float32 and hist.shape == (512,)
    # OpenCV HSV: blue (120, 255, 255), red (0, 255, 255), white (0, 0, 255), black (0, 0, 0).
    # Bins of 8: h = H * 8 // 180, s = S * 8 // 256, v = V * 8 // 256; flat index (h * 8 + s) * 8 + v.
    blue = (5 * 8 + 7) * 8 + 7  # 120 * 8 // 180 = 5
    red = (0 * 8 + 7) * 8 + 7
    white = (0 * 8 + 0) * 8 + 7
    black = 0
    expected = np.zeros(512, np.float32)
    expected[[blue, red, white, black]] = 0.25
    assert np.array_equal(hist, expected)


def test_unequal_bin_counts_keep_the_h_s_v_c_order() -> None:
    hist = hsv_histogram(_COLOURS, bins=(6, 4, 2))
    assert hist.shape == (48,)
    # Blue: h = 120 * 6 // 180 = 4, s = 255 * 4 // 256 = 3, v = 255 * 2 // 256 = 1 -> (4 * 4 + 3) * 2 + 1.
    assert hist[39] == 0.25
    assert hist[(0 * 4 + 3) * 2 + 1] == 0.25  # red
    assert hist[1] == 0.25 and hist[0] == 0.25  # white (0, 0, 1), black (0, 0, 0)


def test_the_mask_excludes_pixels() -> None:
    mask = np.array([[True, True], [True, False]])  # no black
    hist = hsv_histogram(_COLOURS, mask)
    assert hist[0] == 0.0 and np.allclose(hist[[383, 63, 7]], 1 / 3) and np.isclose(hist.sum(), 1.0)
    assert np.array_equal(hsv_histogram(_COLOURS, mask.astype(np.uint8) * 255), hist)
    assert not hsv_histogram(_COLOURS, np.zeros((2, 2), bool)).any()


def test_bad_arguments_name_themselves() -> None:
    for call, why in (
        (lambda: hsv_histogram(_COLOURS.astype(np.float32)), "bgr must be uint8"),
        (lambda: hsv_histogram(_COLOURS[:, :, 0]), "bgr must be a .H, W, 3. colour image"),
        (lambda: hsv_histogram(np.zeros((2, 2, 4), np.uint8)), "bgr must have shape"),
        (lambda: hsv_histogram(np.zeros((0, 2, 3), np.uint8)), "bgr must not be empty"),
        (lambda: hsv_histogram(_COLOURS, bins=(0, 8, 8)), r"bins\[0\]"),
        (lambda: hsv_histogram(_COLOURS, bins=(8, 8, 257)), r"bins\[2\]"),
        (lambda: hsv_histogram(_COLOURS, bins=(8, 8)), "bins must be three"),
        (lambda: hsv_histogram(_COLOURS, np.ones((2, 3), bool)), "mask must have the image's shape"),
    ):
        with pytest.raises(ValueError, match=why):
            call()


def test_soft_bins_share_value_between_the_two_nearest_bin_centres() -> None:
    # grey pixels: hue 0, saturation 0 (all in s bin 0), value = the grey level. V bins are 32 levels wide with
    # centres at 15.5, 47.5, 79.5, ...: grey 96 lies 0.515625 bin widths past the centre of bin 2 (79.5).
    grey = np.array([[[96, 96, 96], [79, 79, 79], [250, 250, 250]]], np.uint8)
    index, weights = hsv_soft_bins(grey, (8, 8, 8))
    assert index.shape == weights.shape == (4, 1, 3)
    assert np.allclose(weights.sum(axis=0), 1.0)
    hist = np.bincount(index[:, 0, 0], weights=weights[:, 0, 0], minlength=512)
    assert hist[2] == pytest.approx(1 - 0.515625) and hist[3] == pytest.approx(0.515625)
    hist = np.bincount(index[:, 0, 1], weights=weights[:, 0, 1], minlength=512)
    assert hist[1] == pytest.approx(0.015625) and hist[2] == pytest.approx(0.984375)  # 79 is just below a centre
    hist = np.bincount(index[:, 0, 2], weights=weights[:, 0, 2], minlength=512)
    assert hist[7] == pytest.approx(1.0)  # beyond the last centre: the last bin only
