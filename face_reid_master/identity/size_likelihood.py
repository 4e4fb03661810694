"""Face likelihoods that know the embedder space and the face size of each observation (our extension).

A 10-pixel face's embedding is far noisier than a 40-pixel one's, so the pair likelihoods N_p / N_n of
:mod:`~face_reid_master.identity.likelihood` are fitted per eye-distance bucket of the *observation* (the
stored features a face is compared with are whatever the cameras saw). Observations of unknown size use
the pooled fit. A joint space (``dlib_resnet_v1+sface_2021dec``) compares the concatenation of its
components, each scaled by its ``component_weights`` entry so that both networks count alike.

File ``face_reid_likelihood/2`` (JSON): the space, bucket edges, pooled and per-bucket skew-normals, the
weights, and the thresholds derived on the same development data (predefined-people naming, threshold
method). Version-1 files (one pooled fit of the dlib space) still load.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_real
from face_reid_camera.common.embedding_spaces import DLIB_SPACE, parse_space
from face_reid_master.identity.likelihood import FORMAT_TAG as FORMAT_V1
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal, load_likelihood_model

__all__ = [
    "FORMAT_V2",
    "FaceLikelihood",
    "default_face_likelihood",
    "default_likelihood_file",
    "load_face_likelihood",
    "save_face_likelihood",
]

FORMAT_V2 = "face_reid_likelihood/2"


def default_likelihood_file(space: str) -> str:
    """File name of the shipped fit of ``space`` in the models folder."""
    return f"face_likelihood_{space}.json"


def _model_dict(model: LikelihoodModel) -> dict[str, Any]:
    return {"positive": model.positive.to_dict(), "negative": model.negative.to_dict()}


@dataclass(frozen=True)
class FaceLikelihood:
    """N_p / N_n of one embedder space: pooled, and per eye-distance bucket of the observation.

    ``eye_px_edges``: increasing bucket edges (px); bucket b holds eye distances in
    [edge[b-1], edge[b]) (bucket 0 from 0, the last to infinity); ``by_size`` has one model per bucket
    (empty: the pooled model for every size). ``component_weights``: one scale per component of
    ``space`` (empty = all 1). ``name_threshold`` / ``threshold_distance``: distances derived on the
    development data for naming predefined people / the threshold method (None: not derived).
    """

    pooled: LikelihoodModel
    space: str = DLIB_SPACE
    eye_px_edges: tuple[float, ...] = ()
    by_size: tuple[LikelihoodModel, ...] = ()
    component_weights: tuple[float, ...] = ()
    name_threshold: float | None = None
    threshold_distance: float | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict, compare=False, hash=False)
    _edges: npt.NDArray[np.float64] = field(init=False, repr=False, compare=False, hash=False)
    _scale: npt.NDArray[np.float32] | None = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        if not isinstance(self.pooled, LikelihoodModel):
            raise ValueError(f"pooled must be a LikelihoodModel, got {type(self.pooled).__name__}")
        parts = parse_space(self.space)
        edges = tuple(check_real("eye_px_edges", e, 0.0, 1e4, low_open=True) for e in self.eye_px_edges)
        if any(b <= a for a, b in itertools.pairwise(edges)):
            raise ValueError(f"eye_px_edges must increase, got {edges}")
        if self.by_size and len(self.by_size) != len(edges) + 1:
            raise ValueError(f"by_size needs {len(edges) + 1} models for edges {edges}, got {len(self.by_size)}")
        if not all(isinstance(m, LikelihoodModel) for m in self.by_size):
            raise ValueError("by_size must hold LikelihoodModel instances")
        weights = tuple(check_real("component_weights", w, 0.0, 1e6, low_open=True) for w in self.component_weights)
        if weights and len(weights) != len(parts):
            raise ValueError(f"component_weights needs {len(parts)} values for space {self.space!r}, got {weights}")
        for name in ("name_threshold", "threshold_distance"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, check_real(name, value, 0.0, 10.0, low_open=True))
        object.__setattr__(self, "eye_px_edges", edges)
        object.__setattr__(self, "component_weights", weights)
        object.__setattr__(self, "metadata", dict(self.metadata))
        object.__setattr__(self, "_edges", np.asarray(edges, dtype=np.float64))
        dims = [p.dim for p in parts]
        scale = np.concatenate([np.full(d, w, dtype=np.float32) for d, w in zip(dims, weights, strict=True)]) \
            if weights else None
        object.__setattr__(self, "_scale", scale)

    # ------------------------------------------------------------------ what the table uses
    @property
    def new_person_scale_c(self) -> float:
        return self.pooled.new_person_scale_c

    @property
    def decision_distance(self) -> float:
        """Pooled distance where N_p = N_n (the feature gate of identified tracks)."""
        return self.pooled.decision_distance

    @property
    def conditioned(self) -> bool:
        return bool(self.by_size)

    def with_new_person_scale(self, c: float) -> FaceLikelihood:
        return dataclasses.replace(
            self, pooled=self.pooled.with_new_person_scale(c),
            by_size=tuple(m.with_new_person_scale(c) for m in self.by_size))

    def pooled_only(self) -> FaceLikelihood:
        """The same fit without the size buckets (every observation judged by the pooled model)."""
        return dataclasses.replace(self, eye_px_edges=(), by_size=())

    def bucket_of(self, eye_px: npt.ArrayLike) -> npt.NDArray[np.intp]:
        """Bucket index per eye distance (px); -1 for unknown (<= 0 or not finite) or without buckets."""
        e = np.asarray(eye_px, dtype=np.float64)
        if not self.by_size:
            return np.full(e.shape, -1, dtype=np.intp)
        out = np.searchsorted(self._edges, e, side="right").astype(np.intp)
        out[~(np.isfinite(e) & (e > 0))] = -1
        return out

    def log_ratio_rows(self, d: npt.NDArray[np.float64], n_features: npt.NDArray[np.float64],
                       buckets: npt.NDArray[np.intp] | None) -> npt.NDArray[np.float64]:
        """log N_p/N_n of distances ``d`` (Q, M), each row judged by its observation's bucket (-1: pooled)."""
        if buckets is None or not self.by_size or np.all(buckets < 0):
            return self.pooled.log_ratio_trusted(d, n_features)
        out = np.empty(d.shape, dtype=np.float64)
        n_b = np.broadcast_to(n_features, d.shape)
        for b in np.unique(buckets):
            rows = buckets == b
            model = self.pooled if b < 0 else self.by_size[int(b)]
            out[rows] = model.log_ratio_trusted(d[rows], n_b[rows])
        return out

    def scale(self, embeddings: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        """Embeddings of this space with the component weights applied (what the feature bank stores)."""
        if self._scale is None:
            return embeddings
        return (embeddings * self._scale).astype(np.float32)


def save_face_likelihood(model: FaceLikelihood, path: str | Path) -> None:
    """Write ``model`` as a ``face_reid_likelihood/2`` JSON file."""
    pooled = model.pooled
    doc = {
        "format": FORMAT_V2,
        "space": model.space,
        "component_weights": list(model.component_weights),
        "eye_px_edges": list(model.eye_px_edges),
        "pooled": _model_dict(pooled),
        "by_size": [_model_dict(m) for m in model.by_size],
        "new_person_scale_c": pooled.new_person_scale_c,
        "k_exponent_positive": pooled.k_exponent_positive,
        "k_exponent_negative": pooled.k_exponent_negative,
        "name_threshold": model.name_threshold,
        "threshold_distance": model.threshold_distance,
        "metadata": dict(model.metadata),
    }
    Path(path).write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")


def _model_from(doc: Mapping[str, Any], c: float) -> LikelihoodModel:
    return LikelihoodModel(SkewNormal.from_dict(doc["positive"]), SkewNormal.from_dict(doc["negative"]), c)


def load_face_likelihood(path: str | Path) -> FaceLikelihood:
    """Read a version-2 file, or a version-1 file (a pooled dlib fit); ValueError on anything else."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"likelihood model {p}: No such file (refit with face-reid-fit-likelihood)")
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{p}: not valid JSON ({exc})") from None
    fmt = doc.get("format") if isinstance(doc, dict) else None
    if fmt == FORMAT_V1:
        model = load_likelihood_model(p)
        return FaceLikelihood(model, DLIB_SPACE, metadata=model.metadata)
    if fmt != FORMAT_V2:
        raise ValueError(f"{p}: not a face likelihood model (expected format {FORMAT_V2!r} or {FORMAT_V1!r})")
    try:
        c = float(doc.get("new_person_scale_c", 1.0))
        pooled = _model_from(doc["pooled"], c)
        pooled = LikelihoodModel(pooled.positive, pooled.negative, c, float(doc.get("k_exponent_positive", 0.0)),
                                 float(doc.get("k_exponent_negative", 0.0)), metadata=doc.get("metadata", {}))
        return FaceLikelihood(
            pooled, str(doc["space"]), tuple(doc.get("eye_px_edges", ())),
            tuple(_model_from(m, c) for m in doc.get("by_size", ())), tuple(doc.get("component_weights", ())),
            doc.get("name_threshold"), doc.get("threshold_distance"), doc.get("metadata", {}),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{p}: malformed likelihood model ({exc})") from None


def default_face_likelihood(space: str = DLIB_SPACE) -> FaceLikelihood:
    """The shipped fit of ``space`` (models/face_likelihood_<space>.json)."""
    from face_reid_camera.common.resources import model_path

    return load_face_likelihood(model_path(default_likelihood_file(space)))
