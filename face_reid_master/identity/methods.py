"""The face classification methods selectable by name (``MasterConfig.method``: "bayes" or "threshold")."""

from __future__ import annotations

from typing import Any

from face_reid_master.identity.algorithm1 import IdentityManagerBase
from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.threshold import ThresholdIdentityManager

__all__ = ["make_identity_manager"]


def make_identity_manager(method: str = "bayes", **params: Any) -> IdentityManagerBase:
    """Factory for the node: ``method="bayes"`` (paper) or ``"threshold"`` (baseline)."""
    if method == "bayes":
        return BayesIdentityManager(**params)
    if method == "threshold":
        return ThresholdIdentityManager(**params)
    raise ValueError(f"method must be 'bayes' or 'threshold', got {method!r}")
