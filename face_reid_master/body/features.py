"""The body features the master compares: HSV, SILTP and both side by side ("fused"), raw or projected.

A camera sends, per descriptor block, the block's principal components (``face_reid_camera.body.projection``)
concatenated into one wire vector; a metric of one feature reads that feature's columns of it. Raw
descriptors (the evaluation's baseline) fuse the same way, each block scaled by 1 / sqrt(2) so that the
fused vector stays unit length.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.body.descriptor import BodyDescriptorConfig
from face_reid_camera.body.projection import FEATURES, BodyProjection, fit_pca_block

__all__ = ["FUSED", "METRIC_FEATURES", "feature_blocks", "feature_columns", "fit_projection", "parse_pca_dims",
           "raw_feature"]

FUSED = "fused"
METRIC_FEATURES = (*FEATURES, FUSED)  # what a metric file holds a metric for, in this order


def feature_blocks(feature: str) -> tuple[str, ...]:
    """The projection blocks a feature reads, in wire order."""
    if feature == FUSED:
        return FEATURES
    if feature in FEATURES:
        return (feature,)
    raise ValueError(f"feature must be one of {METRIC_FEATURES}, got {feature!r}")


def feature_columns(slices: Mapping[str, slice], feature: str) -> npt.NDArray[np.intp]:
    """Columns of the wire vector that ``feature`` reads, given each block's slice (``BodyProjection.slices()``)."""
    parts = []
    for block in feature_blocks(feature):
        if block not in slices:
            raise ValueError(f"feature {feature} needs the projection block {block!r}, the projection has "
                             f"{sorted(slices)}")
        s = slices[block]
        parts.append(np.arange(s.start, s.stop, dtype=np.intp))
    return np.concatenate(parts)


def raw_feature(features: Mapping[str, npt.ArrayLike], feature: str) -> npt.NDArray[np.float64]:
    """(n, d) raw descriptors of ``feature`` from the per-block arrays; fused blocks scaled by 1 / sqrt(2)."""
    blocks = [np.asarray(features[b], dtype=np.float64) for b in feature_blocks(feature)]
    return blocks[0] if len(blocks) == 1 else np.hstack(blocks) / np.sqrt(len(blocks))


def fit_projection(features: Mapping[str, npt.ArrayLike], dims: Mapping[str, int],
                   config: BodyDescriptorConfig | None = None,
                   metadata: Mapping[str, Any] | None = None) -> BodyProjection:
    """The PCA projection of every block of ``FEATURES`` (:func:`fit_pca_block`) with ``dims[block]`` components,
    for descriptors made with ``config`` (None: the default)."""
    if set(dims) != set(FEATURES):
        raise ValueError(f"dims must give a dimension for each of {FEATURES}, got {dict(dims)}")
    blocks = tuple(fit_pca_block(b, np.asarray(features[b]), dims[b]) for b in FEATURES)
    return BodyProjection(blocks, BodyDescriptorConfig() if config is None else config, dict(metadata or {}))


def parse_pca_dims(text: str) -> dict[str, int]:
    """``hsv=64,siltp=64`` -> {"hsv": 64, "siltp": 64} (every block once, each >= 1); ValueError naming the fault."""
    out: dict[str, int] = {}
    for item in str(text).split(","):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or name not in FEATURES or name in out:
            raise ValueError(f"pca dims must be like hsv=64,siltp=64 (each of {FEATURES} once), got {text!r}")
        try:
            out[name] = int(value)
        except ValueError:
            raise ValueError(f"pca dims of {name} must be an integer, got {value.strip()!r}") from None
        if out[name] < 1:
            raise ValueError(f"pca dims of {name} must be >= 1, got {out[name]}")
    if set(out) != set(FEATURES):
        raise ValueError(f"pca dims must give each of {FEATURES}, got {text!r}")
    return out
