"""Body descriptor: layout and normalisation, distance and clothes, parts, the mask, config checks."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from face_reid_camera.body.descriptor import BodyDescriptorConfig, body_descriptor

_RED, _BLUE = (0, 0, 255), (255, 0, 0)  # BGR; HSV bins (8, 8, 8): red 63, blue 383 (see test_hsv_histogram)


def _person(height: int, shirt: tuple[int, int, int], trousers: tuple[int, int, int], *, stripes: bool,
            seed: int = 0) -> np.ndarray:
    """A (height, height / 2) crop: skin head (top fifth), shirt (white stripes height / 16 px thick every
    height / 8 px from a row divisible by 4, or plain), trousers (bottom half); sensor noise of sigma 5."""
    img = np.empty((height, height // 2, 3), np.uint8)
    img[: height // 5] = (110, 150, 200)
    img[height // 5: height // 2] = shirt
    if stripes:
        period = height // 8
        for row in range((height // 5 + 3) // 4 * 4, height // 2, period):
            img[row: row + period // 2] = (240, 240, 240)
    img[height // 2:] = trousers
    noise = np.random.default_rng(seed).normal(0.0, 5.0, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def test_lengths_and_unit_vectors() -> None:
    crop = _person(128, (30, 30, 200), (140, 50, 20), stripes=True)
    d = body_descriptor(crop)
    assert d.hsv.dtype == np.float32 and d.hsv.shape == (4 * 512,) and d.siltp.shape == (4 * 81 * 2,)
    assert np.linalg.norm(d.hsv) == pytest.approx(1.0) and np.linalg.norm(d.siltp) == pytest.approx(1.0)
    assert d.visible_fraction == 1.0
    config = BodyDescriptorConfig(part_edges=[0.0, 0.5, 1.0], hsv_bins=(4, 2, 2), siltp_scales=[1.0, 0.5, 0.25])
    d = body_descriptor(crop, config=config)
    assert d.hsv.shape == (2 * 16,) == (config.hsv_length,)
    assert d.siltp.shape == (2 * 81 * 3,) == (config.siltp_length,)
    assert config.part_edges == (0.0, 0.5, 1.0) and config.siltp_scales == (1.0, 0.5, 0.25)  # stored as tuples
    with pytest.raises(ValueError):  # the descriptor is frozen, its arrays too
        d.hsv[0] = 1.0


def test_square_root_then_l2_on_a_hand_made_crop() -> None:
    crop = np.empty((8, 4, 3), np.uint8)
    crop[:6], crop[6:] = _RED, _BLUE
    one_part = BodyDescriptorConfig(part_edges=(0.0, 1.0), siltp_scales=(1.0,), siltp_height=None)
    d = body_descriptor(crop, config=one_part)
    # Histogram 0.75 red, 0.25 blue -> sqrt: 0.866, 0.5 (already unit length). Plain L2 would give 0.949, 0.316.
    assert d.hsv[63] == pytest.approx(np.sqrt(0.75)) and d.hsv[383] == pytest.approx(0.5)
    assert np.count_nonzero(d.hsv) == 2
    # Four parts: each part's histogram sums to 1 before the square root, so every part weighs the same.
    four = body_descriptor(crop, config=BodyDescriptorConfig(siltp_height=None))
    # Rows 0-1, 2-3, 4-5 red; 6-7 blue: one bin per part, each 1 -> 1 / sqrt(4) after the L2 norm.
    assert four.hsv[[63, 512 + 63, 1024 + 63, 1536 + 383]].tolist() == [0.5] * 4
    flat = body_descriptor(np.full((8, 4, 3), 90, np.uint8), config=BodyDescriptorConfig(siltp_height=None))
    # A flat crop: only code 0, in each of the 4 parts x 2 scales blocks -> 1 / sqrt(8) at every block start.
    assert np.allclose(flat.siltp[::81], 1 / np.sqrt(8)) and np.count_nonzero(flat.siltp) == 8


def test_siltp_is_laid_out_scale_major_then_part() -> None:
    crop = np.full((64, 32, 3), 120, np.uint8)
    crop[32:] = np.where((np.add.outer(np.arange(32), np.arange(32)) % 2 == 0)[:, :, None], 60, 180)
    config = BodyDescriptorConfig(part_edges=(0.0, 0.5, 1.0), siltp_scales=(1.0, 0.5), siltp_height=None)
    s = body_descriptor(crop, config=config).siltp.reshape(2, 2, 81)  # (scale, part, code)
    # Full scale: every pixel of the 1-px checkerboard (bottom part) has a neighbour 3 px away of the other
    # shade, so code 0 never occurs there; the flat top part is mostly code 0.
    assert s[0, 1, 0] == 0.0 and s[0, 0, 0] > 0.3
    # Half scale: each 2x2 block averages to 120 = the top's grey: one flat image, code 0 only.
    assert s[1, 0, 0] == s[1, 1, 0] > 0 and np.count_nonzero(s[1]) == 2


@pytest.mark.parametrize("height", [256, 128])
def test_a_person_far_away_keeps_the_descriptor_other_clothes_change_it(height: int) -> None:
    near = _person(height, (30, 30, 200), (140, 50, 20), stripes=True)
    far = cv2.resize(near, (height // 4, height // 2), interpolation=cv2.INTER_AREA)  # twice the distance
    other = _person(height, (40, 160, 40), (25, 25, 25), stripes=False, seed=1)
    dn, df, do = body_descriptor(near), body_descriptor(far), body_descriptor(other)
    assert dn.hsv @ df.hsv > 0.9 and dn.hsv @ do.hsv < 0.5
    # 256 -> 128: both are textured at siltp_height 128 (near shrunk, far as is); 128 -> 64: far enlarged.
    assert dn.siltp @ df.siltp > 0.95
    assert dn.siltp @ df.siltp > max(dn.siltp @ do.siltp, df.siltp @ do.siltp) + 0.05
    # Without the common texture height the far crop's stripes are half as thick for the same radius.
    raw = BodyDescriptorConfig(siltp_height=None)
    assert body_descriptor(near, config=raw).siltp @ body_descriptor(far, config=raw).siltp < dn.siltp @ df.siltp


def test_parts_tell_a_red_shirt_over_blue_trousers_from_the_reverse() -> None:
    a = _person(128, _RED, _BLUE, stripes=False)
    b = _person(128, _BLUE, _RED, stripes=False)
    assert body_descriptor(a).hsv @ body_descriptor(b).hsv < 0.5
    whole = BodyDescriptorConfig(part_edges=(0.0, 1.0))  # one part: nearly the same colours overall
    assert body_descriptor(a, config=whole).hsv @ body_descriptor(b, config=whole).hsv > 0.85


def test_the_mask_keeps_occluders_out() -> None:
    person = _person(128, (30, 30, 200), (140, 50, 20), stripes=True)
    occluded = person.copy()
    occluded[:, :32] = (0, 200, 0)  # something green in front of the left half
    mask = np.zeros(person.shape[:2], bool)
    mask[:, 32:] = True
    seen = body_descriptor(occluded, mask)
    right_half = body_descriptor(np.ascontiguousarray(person[:, 32:]))
    assert np.array_equal(seen.hsv, right_half.hsv)  # the same pixels in the same parts
    # Only the codes within the radius (3 px) of the mask's edge see the occluder: ~10 % of the pixels at
    # full scale, ~20 % at half scale.
    assert seen.siltp @ right_half.siltp > 0.9
    assert body_descriptor(occluded).hsv @ right_half.hsv < 0.9  # without the mask the green counts
    assert seen.visible_fraction == 0.5
    legs_hidden = mask.copy()
    legs_hidden[96:] = False  # the lower legs part (rows 96..127) has no person pixel: its block is zero
    d = body_descriptor(occluded, legs_hidden.astype(np.uint8))
    assert not d.hsv[3 * 512:].any() and d.hsv[: 3 * 512].any() and d.visible_fraction == 0.375


def test_bad_arguments_name_themselves() -> None:
    for kwargs, why in (
        ({"part_edges": (0.0, 0.6, 0.5, 1.0)}, "part_edges must be strictly increasing"),
        ({"part_edges": (0.0,)}, "part_edges must have at least 2"),
        ({"part_edges": (0.0, 1.5)}, r"part_edges\[1\]"),
        ({"part_edges": "01"}, "part_edges must be a sequence"),
        ({"hsv_bins": (8, 0, 8)}, r"hsv_bins\[1\]"),
        ({"siltp_tau": 1.0}, "siltp_tau"),
        ({"siltp_radius": 0}, "siltp_radius"),
        ({"siltp_scales": ()}, "siltp_scales must have at least one"),
        ({"siltp_scales": (1.0, 1.5)}, r"siltp_scales\[1\]"),
        ({"siltp_scales": (0.0,)}, r"siltp_scales\[0\]"),
        ({"siltp_height": 0}, "siltp_height"),
    ):
        with pytest.raises(ValueError, match=why):
            BodyDescriptorConfig(**kwargs)
    crop = np.zeros((8, 4, 3), np.uint8)
    for call, why in (
        (lambda: body_descriptor(crop[:, :, 0]), "bgr must be a .H, W, 3. colour image"),
        (lambda: body_descriptor(crop.astype(np.float32)), "bgr must be uint8"),
        (lambda: body_descriptor(crop, np.ones((8, 5), bool)), "mask must have the image's shape"),
        (lambda: body_descriptor(crop, None, {"siltp_tau": 0.3}), "config must be a BodyDescriptorConfig"),
    ):
        with pytest.raises(ValueError, match=why):
            call()


def test_a_mask_that_selects_nothing_gives_empty_histograms() -> None:
    d = body_descriptor(np.full((16, 8, 3), 90, np.uint8), np.zeros((16, 8), bool),
                        BodyDescriptorConfig(siltp_height=None))
    assert not d.hsv.any() and not d.siltp.any() and d.visible_fraction == 0.0
