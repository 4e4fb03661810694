"""The body metric file the master loads: per feature a learned metric on the cameras' projected vectors, its
distance likelihoods N_p / N_n and the decision distance, tied to the projection space the cameras send.

A camera sends one wire vector per person (``face_reid_camera.body.projection``: the blocks' principal
components side by side); feature ``hsv`` / ``siltp`` reads its block's columns, ``fused`` both. Distances
are in units of the metric's median different-person distance on its training crops (so the likelihoods'
skew-normals live on the same scale as the face ones).

Format (JSON, written by ``face-reid-fit-body``): ``format`` / ``version``, ``space`` and ``length`` of the
projection, ``blocks`` [{name, start, stop}] (its columns), ``features`` {name: {blocks, method,
parameters, W (input x r), M (r x r), positive / negative {alpha, xi, omega}, decision_distance}},
``metadata`` (provenance).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.model_files import read_model_json, unusable_model
from face_reid_master.body.features import METRIC_FEATURES, feature_blocks, feature_columns
from face_reid_master.body.linear_metric import LinearMetric
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal

__all__ = ["BODY_METRIC_FILE", "BodyFeatureMetric", "BodyMetricModel", "default_body_metric", "load_body_metric",
           "save_body_metric"]

FORMAT_NAME = "face-reid-body-metric"
FORMAT_VERSION = 1
BODY_METRIC_FILE = "body_metric.json"  # the shipped metric, in the models directory
_DIGITS = 9  # significant digits of W and M in the file (float32 needs 9 to round-trip)


@dataclass(frozen=True, eq=False)
class BodyFeatureMetric:
    """One feature's metric: the wire ``columns`` it reads, W and M (``metric``), N_p / N_n (``likelihood``)
    and the parameters it was fitted with (free-form: regularisation, subspace cap, distance scale)."""

    name: str
    columns: npt.NDArray[np.intp]
    metric: LinearMetric
    likelihood: LikelihoodModel
    parameters: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in METRIC_FEATURES:
            raise ValueError(f"feature name must be one of {METRIC_FEATURES}, got {self.name!r}")
        cols = np.asarray(self.columns, dtype=np.intp).reshape(-1)
        if cols.size != self.metric.input_dim or (cols.size and cols.min() < 0):
            raise ValueError(f"feature {self.name}: {cols.size} columns for a metric of {self.metric.input_dim} "
                             "inputs (or a negative column)")
        cols.setflags(write=False)
        object.__setattr__(self, "columns", cols)
        object.__setattr__(self, "parameters", dict(self.parameters))

    @property
    def decision_distance(self) -> float:
        """The distance where N_p = N_n: below it a pair is more likely the same person."""
        return self.likelihood.decision_distance

    def distances(self, a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """(na, nb) distances between wire vectors (rows of ``a`` and ``b``)."""
        x, y = np.atleast_2d(np.asarray(a, dtype=np.float64)), np.atleast_2d(np.asarray(b, dtype=np.float64))
        return self.metric.distances(x[:, self.columns], y[:, self.columns])

    @cached_property
    def embedding_factor(self) -> npt.NDArray[np.float64]:
        """(r, r) L with M = L L^T (M's negative eigenvalues, rounding noise of a positive semi-definite
        matrix, clipped to 0): a subspace vector z = W^T x embeds as z L."""
        values, vectors = np.linalg.eigh(self.metric.metric)
        return vectors * np.sqrt(np.maximum(values, 0.0))

    @cached_property
    def _embedding_matrix(self) -> npt.NDArray[np.float64]:
        """(input, r) matrix E = W L with ||E^T (x - y)|| = the metric distance."""
        return self.metric.projection @ self.embedding_factor

    def embed(self, wire: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """(n, r) embeddings of wire vectors whose Euclidean distances are this metric's distances (compare
        many pairs with one GEMM, or keep a track's appearance small)."""
        x = np.atleast_2d(np.asarray(wire, dtype=np.float64))
        return (x[:, self.columns] @ self._embedding_matrix).astype(np.float32)


@dataclass(frozen=True, eq=False)
class BodyMetricModel:
    """The metrics of every feature of ``METRIC_FEATURES`` for wire vectors of projection ``space`` (``length``
    values; ``blocks``: (name, start, stop) of each projection block), with provenance ``metadata``."""

    space: str
    length: int
    blocks: tuple[tuple[str, int, int], ...]
    features: Mapping[str, BodyFeatureMetric]
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.space, str) or not self.space:
            raise ValueError(f"space must be a non-empty string, got {self.space!r}")
        if isinstance(self.length, bool) or not isinstance(self.length, int) or self.length < 1:
            raise ValueError(f"length must be an int >= 1, got {self.length!r}")
        blocks = tuple((str(n), int(a), int(b)) for n, a, b in self.blocks)
        if not blocks or any(not 0 <= a < b <= self.length for _, a, b in blocks):
            raise ValueError(f"blocks must be (name, start, stop) within the {self.length} wire values, got {blocks}")
        object.__setattr__(self, "blocks", blocks)
        features = dict(self.features)
        if set(features) != set(METRIC_FEATURES):
            raise ValueError(f"features must be {METRIC_FEATURES}, got {sorted(features)}")
        for name, f in features.items():
            if not isinstance(f, BodyFeatureMetric) or f.name != name:
                raise ValueError(f"features[{name!r}] must be the BodyFeatureMetric named {name!r}")
            expected = feature_columns(self.slices(), name)
            if not np.array_equal(f.columns, expected):
                raise ValueError(f"feature {name} reads columns that are not its blocks' {feature_blocks(name)}")
        object.__setattr__(self, "features", {n: features[n] for n in METRIC_FEATURES})
        object.__setattr__(self, "metadata", dict(self.metadata))

    def slices(self) -> dict[str, slice]:
        """Where each projection block lies in a wire vector."""
        return {n: slice(a, b) for n, a, b in self.blocks}


def _matrix(a: npt.NDArray[np.float64]) -> list[list[float]]:
    return [[float(f"{v:.{_DIGITS}g}") for v in row] for row in np.asarray(a, dtype=np.float64)]


def _feature_doc(f: BodyFeatureMetric) -> dict[str, Any]:
    return {
        "blocks": list(feature_blocks(f.name)),
        "method": f.metric.name,
        "parameters": dict(f.parameters),
        "W": _matrix(f.metric.projection),
        "M": _matrix(f.metric.metric),
        "positive": f.likelihood.positive.to_dict(),
        "negative": f.likelihood.negative.to_dict(),
        "decision_distance": f.decision_distance,
    }


def _dumps(doc: dict[str, Any]) -> str:
    """Indented JSON with each matrix row on one line (readable metadata, a short file)."""
    rows: dict[str, str] = {}

    def mark(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: mark(v) for k, v in value.items()}
        if isinstance(value, list) and value and all(isinstance(r, list) for r in value):
            keys = []
            for row in value:
                key = f"@row{len(rows)}@"
                rows[key] = json.dumps(row, separators=(", ", ": "))
                keys.append(key)
            return keys
        return value

    return re.sub(r'"(@row\d+@)"', lambda m: rows[m.group(1)], json.dumps(mark(doc), indent=1)) + "\n"


def save_body_metric(model: BodyMetricModel, path: str | Path) -> Path:
    """Write ``model`` (W and M to 9 significant digits; same model, same bytes), atomically."""
    out = Path(path)
    doc = {
        "format": FORMAT_NAME, "version": FORMAT_VERSION, "space": model.space, "length": model.length,
        "blocks": [{"name": n, "start": a, "stop": b} for n, a, b in model.blocks],
        "features": {n: _feature_doc(f) for n, f in model.features.items()},
        "metadata": dict(model.metadata),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(_dumps(doc), encoding="utf-8")
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return out


def _feature_from(name: str, doc: Mapping[str, Any], slices: dict[str, slice]) -> BodyFeatureMetric:
    if list(doc["blocks"]) != list(feature_blocks(name)):
        raise ValueError(f"feature {name} must read the blocks {list(feature_blocks(name))}, got {doc['blocks']}")
    metric = LinearMetric(np.array(doc["W"], dtype=np.float64), np.array(doc["M"], dtype=np.float64),
                          str(doc["method"]))
    likelihood = LikelihoodModel(SkewNormal.from_dict(doc["positive"]), SkewNormal.from_dict(doc["negative"]))
    stored = float(doc["decision_distance"])
    if not math.isclose(stored, likelihood.decision_distance, rel_tol=1e-6, abs_tol=1e-9):
        raise ValueError(f"feature {name}: decision_distance {stored} is not where its N_p = N_n "
                         f"({likelihood.decision_distance}): damaged?")
    return BodyFeatureMetric(name, feature_columns(slices, name), metric, likelihood, doc.get("parameters", {}))


def load_body_metric(path: str | Path) -> BodyMetricModel:
    """Read a body metric file: FileNotFoundError when missing, :class:`ModelLoadError` (path and reason) when
    unusable (not JSON, another format or version, missing or inconsistent values)."""
    doc = read_model_json(path, FORMAT_NAME, FORMAT_VERSION, "body metric file", "fit one with face-reid-fit-body")
    with unusable_model("body metric file", path):
        blocks = tuple((str(b["name"]), int(b["start"]), int(b["stop"])) for b in doc["blocks"])
        slices = {n: slice(a, b) for n, a, b in blocks}
        features = {n: _feature_from(n, doc["features"][n], slices) for n in METRIC_FEATURES}
        return BodyMetricModel(str(doc["space"]), int(doc["length"]), blocks, features, doc.get("metadata", {}))


def default_body_metric() -> BodyMetricModel:
    """The shipped body metric (``models/body_metric.json``)."""
    from face_reid_camera.common.resources import model_path

    return load_body_metric(model_path(BODY_METRIC_FILE))
