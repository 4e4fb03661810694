"""SILTP codes and histograms: hand-computed codes, replicate padding, scale invariance, masks, checks."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_camera.body.siltp import SILTP_CODES, siltp_codes, siltp_histogram

# Rows of a 3x3 grey image used by the hand-computed cases below.
_IMAGE = np.array([[5.0, 30.0, 12.0],
                   [40.0, 20.0, 21.0],
                   [9.0, 10.0, 50.0]])


def _reference_codes(gray: np.ndarray, tau: float, radius: int) -> np.ndarray:
    """Pixel-by-pixel SILTP straight from the definition (clamped neighbour coordinates = replicate)."""
    h, w = gray.shape
    out = np.zeros((h, w), np.int64)
    for r in range(h):
        for c in range(w):
            centre = gray[r, c]
            for k, (dr, dc) in enumerate(((0, radius), (-radius, 0), (0, -radius), (radius, 0))):
                neighbour = gray[min(max(r + dr, 0), h - 1), min(max(c + dc, 0), w - 1)]
                if neighbour > (1 + tau) * centre:
                    out[r, c] += 3**k
                elif neighbour < (1 - tau) * centre:
                    out[r, c] += 2 * 3**k
    return out


def test_codes_computed_by_hand_with_replicate_padding() -> None:
    codes = siltp_codes(_IMAGE, tau=0.1, radius=1)
    assert codes.dtype == np.uint8 and codes.shape == (3, 3)
    # Centre, I_c = 20, band [18, 22]: right 21 -> 0; up 30 -> 1 * 3; left 40 -> 1 * 9; down 10 -> 2 * 27.
    assert codes[1, 1] == 0 + 3 + 9 + 54
    # Top-left corner, I_c = 5, band [4.5, 5.5]: right 30 -> 1 * 1; up and left are outside the image and
    # replicate the pixel itself (5) -> 0; down 40 -> 1 * 27.
    assert codes[0, 0] == 1 + 0 + 0 + 27
    # Bottom-right corner, I_c = 50, band [45, 55]: right and down replicate itself -> 0; up 21 -> 2 * 3;
    # left 10 -> 2 * 9.
    assert codes[2, 2] == 0 + 6 + 18 + 0
    # Top-right, I_c = 12, band [10.8, 13.2]: right, up itself -> 0; left 30 -> 1 * 9; down 21 -> 1 * 27.
    assert codes[0, 2] == 0 + 0 + 9 + 27


def test_a_radius_beyond_the_border_takes_the_edge_pixel() -> None:
    codes = siltp_codes(_IMAGE, tau=0.1, radius=2)
    # Centre with R = 2: every neighbour lies outside and clamps onto the same pixels as R = 1.
    assert codes[1, 1] == 66
    # Top-left with R = 2, I_c = 5: right (0, 2) = 12 -> 1; up, left itself -> 0; down (2, 0) = 9 -> 1 * 27.
    assert codes[0, 0] == 1 + 27


@pytest.mark.parametrize(("tau", "radius"), [(0.0, 1), (0.1, 1), (0.3, 2), (0.5, 4)])
def test_codes_match_the_definition_on_a_random_image(tau: float, radius: int) -> None:
    gray = np.random.default_rng(radius).integers(0, 256, (7, 9)).astype(np.float32)
    assert np.array_equal(siltp_codes(gray, tau, radius), _reference_codes(gray, tau, radius))


def test_codes_are_invariant_to_an_intensity_gain() -> None:
    gray = np.random.default_rng(0).uniform(0.0, 200.0, (20, 30)).astype(np.float32)
    codes = siltp_codes(gray)
    assert len(np.unique(codes)) > 10  # a textured image, not a trivial all-zero case
    assert np.array_equal(siltp_codes(gray * 2), codes)
    assert np.array_equal(siltp_codes(gray.astype(np.float64) * 0.25), codes)


def test_histogram_of_a_constant_image_is_all_code_zero() -> None:
    hist = siltp_histogram(np.full((10, 12), 77, np.uint8))
    assert hist.dtype == np.float32 and hist.shape == (SILTP_CODES,)
    assert hist[0] == 1.0 and hist[1:].sum() == 0.0


def test_histogram_counts_only_the_masked_pixels() -> None:
    mask = np.zeros((3, 3), bool)
    mask[1, 1] = True
    hist = siltp_histogram(_IMAGE, mask, tau=0.1, radius=1)
    assert hist[66] == 1.0 and hist.sum() == 1.0
    mask[0, 0] = True  # an OpenCV-style 0/255 mask works the same
    hist = siltp_histogram(_IMAGE, mask.astype(np.uint8) * 255, tau=0.1, radius=1)
    assert hist[66] == 0.5 and hist[28] == 0.5
    full = siltp_histogram(_IMAGE, None, tau=0.1, radius=1)
    assert np.allclose(full * 9, np.bincount(_reference_codes(_IMAGE, 0.1, 1).ravel(), minlength=SILTP_CODES))
    assert not siltp_histogram(_IMAGE, np.zeros((3, 3), bool)).any()


def test_bad_arguments_name_themselves() -> None:
    for call, why in (
        (lambda: siltp_codes(_IMAGE, tau=1.0), "tau"),
        (lambda: siltp_codes(_IMAGE, tau=-0.1), "tau"),
        (lambda: siltp_codes(_IMAGE, radius=0), "radius"),
        (lambda: siltp_codes(_IMAGE, radius=1.5), "radius"),
        (lambda: siltp_codes(np.zeros((3, 3, 3))), "gray must be a non-empty 2-D"),
        (lambda: siltp_codes(np.zeros((0, 3))), "gray must be a non-empty 2-D"),
        (lambda: siltp_codes(-_IMAGE), "non-negative"),
        (lambda: siltp_codes(np.full((2, 2), np.nan)), "finite"),
        (lambda: siltp_codes(np.ones((2, 2), bool)), "dtype"),
        (lambda: siltp_codes([[1.0]]), "numpy array"),
        (lambda: siltp_histogram(_IMAGE, np.ones((3, 4), bool)), "mask must have the image's shape"),
        (lambda: siltp_histogram(_IMAGE, np.ones((3, 3), np.float32)), "mask must be bool or integer"),
    ):
        with pytest.raises(ValueError, match=why):
            call()
