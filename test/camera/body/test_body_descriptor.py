"""SILTP and HSV histograms against hand-computed values; the body descriptor across distance and clothes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from face_reid_camera.body.descriptor import BodyDescriptorConfig, body_descriptor
from face_reid_camera.body.hsv_histogram import hsv_histogram
from face_reid_camera.body.siltp import siltp_codes, siltp_histogram


def test_siltp_codes_by_hand() -> None:
    g = np.array([[10, 20, 10],
                  [5, 10, 10.5],
                  [10, 9, 30]], dtype=np.float32)
    codes = siltp_codes(g, tau=0.1, radius=1)
    # centre 10, band [9, 11]: right 10.5 -> 0, up 20 -> 1 (x 3), left 5 -> 2 (x 9), down 9 -> 0 (x 27)
    assert codes[1, 1] == 0 + 1 * 3 + 2 * 9 + 0 * 27 == 21
    # corner (0, 0) = 10, edge replicated: right 20 -> 1, up (itself) 10 -> 0, left (itself) -> 0, down 5 -> 2
    assert codes[0, 0] == 1 + 0 + 0 + 2 * 27 == 55
    np.testing.assert_array_equal(siltp_codes(2.0 * g, 0.1, 1), codes)  # intensity scale does not matter
    assert siltp_histogram(np.full((5, 5), 7.0))[0] == 1.0  # flat: all code 0
    mask = np.zeros((3, 3), bool)
    mask[1, 1] = True
    h = siltp_histogram(g, mask, tau=0.1, radius=1)
    assert h[21] == 1.0 and h.sum() == pytest.approx(1.0) and h.size == 81
    assert not siltp_histogram(g, np.zeros((3, 3), bool)).any()
    with pytest.raises(ValueError, match="tau"):
        siltp_codes(g, tau=1.0)
    with pytest.raises(ValueError, match="radius"):
        siltp_codes(g, radius=0)
    with pytest.raises(ValueError, match="mask"):
        siltp_histogram(g, np.ones((2, 2), bool))


def test_hsv_histogram_by_hand() -> None:
    # BGR: pure red -> H 0, S 255, V 255; pure blue -> H 120; white -> S 0, V 255; black -> V 0
    img = np.array([[[0, 0, 255], [255, 0, 0]], [[255, 255, 255], [0, 0, 0]]], dtype=np.uint8)
    h = hsv_histogram(img)  # 8 x 8 x 8: bin = value * 8 / range; index (h * 8 + s) * 8 + v
    red, blue, white, black = (0 * 8 + 7) * 8 + 7, (5 * 8 + 7) * 8 + 7, (0 * 8 + 0) * 8 + 7, 0
    assert set(np.flatnonzero(h)) == {red, blue, white, black}
    assert h[[red, blue, white, black]].tolist() == [0.25] * 4
    masked = hsv_histogram(img, np.array([[True, False], [False, False]]))
    assert masked[red] == 1.0 and masked.sum() == 1.0
    assert hsv_histogram(img, bins=(2, 1, 1)).tolist() == [0.75, 0.25]  # H 120 of 180 is the upper half
    with pytest.raises(ValueError, match="bgr"):
        hsv_histogram(img.astype(np.float32))
    with pytest.raises(ValueError, match="bins"):
        hsv_histogram(img, bins=(0, 8, 8))


def _person(shirt: tuple[int, int, int], trousers: tuple[int, int, int], stripes: bool) -> np.ndarray:
    """A 256 x 128 crop: skin head, shirt (striped or plain), trousers, on a mid-grey background."""
    rng = np.random.default_rng(0)
    img = np.full((256, 128, 3), 128, np.uint8)
    img[:50, 40:88] = (120, 160, 210)
    img[50:130, 20:108] = shirt
    if stripes:
        img[50:130:12, 20:108] = (255, 255, 255)
        img[51:130:12, 20:108] = (255, 255, 255)
    img[130:, 30:98] = trousers
    noise = rng.normal(0, 4, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def _cos(a: np.ndarray, b: np.ndarray) -> float:
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_a_person_far_away_keeps_the_descriptor_other_clothes_change_it() -> None:
    near = _person((30, 30, 200), (120, 40, 20), stripes=True)
    far = cv2.resize(near, (64, 128), interpolation=cv2.INTER_AREA)  # twice the distance
    other = _person((40, 160, 40), (20, 20, 20), stripes=False)
    dn, df, do = body_descriptor(near), body_descriptor(far), body_descriptor(other)
    config = BodyDescriptorConfig()
    assert dn.hsv.shape == (config.parts * 512,) and dn.siltp.shape == (config.parts * 81 * 2,)
    assert np.linalg.norm(dn.hsv) == pytest.approx(1.0) and np.linalg.norm(dn.siltp) == pytest.approx(1.0)
    assert _cos(dn.hsv, df.hsv) > 0.9 > _cos(dn.hsv, do.hsv) + 0.3
    assert _cos(dn.siltp, df.siltp) > _cos(dn.siltp, do.siltp)
    assert dn.visible_fraction == 1.0


def test_the_mask_keeps_the_background_out() -> None:
    person = _person((30, 30, 200), (120, 40, 20), stripes=False)
    mask = np.zeros(person.shape[:2], bool)
    mask[:50, 40:88] = mask[50:130, 20:108] = mask[130:, 30:98] = True
    on_green = person.copy()
    on_green[~mask] = (0, 200, 0)
    a, b = body_descriptor(person, mask), body_descriptor(on_green, mask)
    assert _cos(a.hsv, b.hsv) > 0.999  # the background never counts
    assert _cos(body_descriptor(person).hsv, body_descriptor(on_green).hsv) < 0.95  # without the mask it does
    assert 0.4 < a.visible_fraction < 0.7
    with pytest.raises(ValueError, match="part_edges"):
        BodyDescriptorConfig(part_edges=(0.0, 0.6, 0.5, 1.0))
    with pytest.raises(ValueError, match="mask"):
        body_descriptor(person, mask[:10])
