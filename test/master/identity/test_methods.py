"""Tests of the identity method factory."""

from __future__ import annotations

import pytest

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.methods import make_identity_manager
from face_reid_master.identity.threshold import ThresholdIdentityManager


def test_factory() -> None:
    assert isinstance(make_identity_manager("bayes"), BayesIdentityManager)
    assert isinstance(make_identity_manager("threshold", n_votes=3), ThresholdIdentityManager)
    with pytest.raises(ValueError):
        make_identity_manager("svm")
    with pytest.raises(ValueError):
        ThresholdIdentityManager(distance_threshold=0.0)
