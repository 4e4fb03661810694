"""Embedding spaces: names, lengths, and taking one component out of a joint embedding."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_camera.common.embedding_spaces import (
    DLIB_SPACE,
    SFACE_SPACE,
    embedder_for_space,
    embedder_space,
    extract_space,
    parse_space,
    space_dim,
)

JOINT = f"{DLIB_SPACE}+{SFACE_SPACE}"


def test_embedder_choices_name_their_spaces() -> None:
    assert embedder_space("dlib") == DLIB_SPACE
    assert embedder_space("sface") == SFACE_SPACE
    assert embedder_space("both") == JOINT
    assert [embedder_for_space(embedder_space(c)) for c in ("dlib", "sface", "both")] == ["dlib", "sface", "both"]
    assert space_dim(JOINT) == 256 and space_dim(SFACE_SPACE) == 128
    with pytest.raises(ValueError, match="embedder must be one of"):
        embedder_space("openface")
    with pytest.raises(ValueError, match="no embedder produces"):
        embedder_for_space(f"{SFACE_SPACE}+{DLIB_SPACE}")


def test_unknown_or_repeated_components_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown embedding space 'openface_v1'"):
        parse_space(f"{DLIB_SPACE}+openface_v1")
    with pytest.raises(ValueError, match="repeats"):
        parse_space(f"{DLIB_SPACE}+{DLIB_SPACE}")
    with pytest.raises(ValueError, match="non-empty"):
        parse_space("")


def test_extract_takes_the_wanted_component_of_a_joint_embedding() -> None:
    joint = np.arange(256, dtype=np.float32)
    np.testing.assert_array_equal(extract_space(joint, JOINT, DLIB_SPACE), joint[:128])
    np.testing.assert_array_equal(extract_space(joint, JOINT, SFACE_SPACE), joint[128:])
    assert extract_space(joint, JOINT, JOINT) is joint
    rows = np.stack([joint, joint + 1])
    assert extract_space(rows, JOINT, SFACE_SPACE).shape == (2, 128)  # type: ignore[union-attr]
    # a single-network embedding cannot give another network's values, nor the joint space
    assert extract_space(joint[:128], DLIB_SPACE, SFACE_SPACE) is None
    assert extract_space(joint[:128], DLIB_SPACE, JOINT) is None


def test_plausible_norms_checks_each_component_of_a_joint_space() -> None:
    from face_reid_camera.common.embedding_spaces import plausible_norms

    rng = np.random.default_rng(0)
    dlib = rng.normal(size=128)
    dlib *= 1.4 / np.linalg.norm(dlib)
    sface = rng.normal(size=128)
    sface /= np.linalg.norm(sface)
    rows = np.stack([np.concatenate([dlib, sface]), np.concatenate([dlib * 100, sface]),
                     np.concatenate([dlib, sface * 0.5]), np.zeros(256)])
    assert plausible_norms(rows, JOINT).tolist() == [True, False, False, False]
    assert plausible_norms(rows[:, :128], DLIB_SPACE).tolist() == [True, False, True, False]
    assert plausible_norms(rows[:, :200], JOINT).tolist() == [False] * 4  # not the space's length: none plausible
    assert plausible_norms(rows.astype(np.float32), JOINT).tolist() == [True, False, False, False]
