"""The fixed linear projection that makes a body descriptor compact on the wire (PCA per feature).

A :class:`~face_reid_camera.body.descriptor.BodyDescriptor` has thousands of values (2,048 HSV + 648
SILTP with the defaults); a camera sends, per feature block, its principal components fitted offline on
development crops (``face-reid-fit-body``): ``(x - mean) @ components`` for each block, concatenated in
block order. Euclidean distances in each block approximate the descriptor's own; the master's learned
metric (XQDA) works on these vectors. The file names its ``space``, which carries a digest of the numbers,
so a master never compares vectors of two different projections.

File format (``.npz``, no pickles): ``meta`` (a JSON string: ``format``, ``version``, ``space``,
``descriptor_config``, ``blocks`` [{name, input_dim, output_dim}], ``metadata``), and per block
``<name>_mean`` (input_dim,) and ``<name>_components`` (input_dim, output_dim), float32.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.body.descriptor import BodyDescriptor, BodyDescriptorConfig
from face_reid_camera.common.atomic_file import write_npz
from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.common.resources import model_path

__all__ = [
    "BODY_PROJECTION_FILE",
    "FEATURES",
    "BodyProjection",
    "ProjectionBlock",
    "descriptor_features",
    "fit_pca_block",
    "load_body_projection",
    "save_body_projection",
]

FORMAT_NAME = "face-reid-body-projection"
FORMAT_VERSION = 1
BODY_PROJECTION_FILE = "body_projection.npz"  # the shipped projection, in the models directory
FEATURES = ("hsv", "siltp")  # the descriptor's feature blocks, in wire order


def descriptor_features(descriptor: BodyDescriptor) -> dict[str, NDArray[np.float32]]:
    """The descriptor's feature vectors by block name (``FEATURES``)."""
    return {"hsv": descriptor.hsv, "siltp": descriptor.siltp}


@dataclass(frozen=True, eq=False)
class ProjectionBlock:
    """One feature's projection: ``mean`` (d,) and ``components`` (d, k), float32, read-only."""

    name: str
    mean: NDArray[np.float32]
    components: NDArray[np.float32]

    def __post_init__(self) -> None:
        if self.name not in FEATURES:
            raise ValueError(f"block name must be one of {FEATURES}, got {self.name!r}")
        mean = np.array(self.mean, dtype=np.float32).reshape(-1)
        comps = np.array(self.components, dtype=np.float32)
        if comps.ndim != 2 or comps.shape[0] != mean.size or comps.shape[1] < 1:
            raise ValueError(f"block {self.name}: components must be ({mean.size}, k >= 1), got {comps.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(comps))):
            raise ValueError(f"block {self.name}: mean / components contain NaN or Inf")
        mean.setflags(write=False)
        comps.setflags(write=False)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "components", comps)

    @property
    def input_dim(self) -> int:
        return int(self.components.shape[0])

    @property
    def output_dim(self) -> int:
        return int(self.components.shape[1])


@dataclass(frozen=True, eq=False)
class BodyProjection:
    """Blocks in wire order, the descriptor configuration they were fitted for, and free-form metadata.

    ``space`` is derived: ``body_pca_<name><k>_..._<sha256[:8] of the numbers and the configuration>``.
    """

    blocks: tuple[ProjectionBlock, ...]
    descriptor_config: BodyDescriptorConfig = field(default_factory=BodyDescriptorConfig)
    metadata: Mapping[str, Any] = field(default_factory=dict)
    space: str = field(init=False)

    def __post_init__(self) -> None:
        blocks = tuple(self.blocks)
        names = [b.name for b in blocks]
        if not blocks or len(set(names)) != len(names) or any(not isinstance(b, ProjectionBlock) for b in blocks):
            raise ValueError(f"blocks must be distinct ProjectionBlocks, at least one, got {names}")
        expected = {"hsv": self.descriptor_config.hsv_length, "siltp": self.descriptor_config.siltp_length}
        for b in blocks:
            if b.input_dim != expected[b.name]:
                raise ValueError(f"block {b.name} expects {b.input_dim} values, the descriptor configuration "
                                 f"gives {expected[b.name]}")
        object.__setattr__(self, "blocks", blocks)
        digest = hashlib.sha256(json.dumps(_config_json(self.descriptor_config), sort_keys=True).encode())
        for b in blocks:
            digest.update(b.name.encode())
            digest.update(b.mean.tobytes())
            digest.update(b.components.tobytes())
        label = "_".join(f"{b.name}{b.output_dim}" for b in blocks)
        object.__setattr__(self, "space", f"body_pca_{label}_{digest.hexdigest()[:8]}")

    @property
    def length(self) -> int:
        """Values of a projected descriptor (the sum of the blocks' output dimensions)."""
        return sum(b.output_dim for b in self.blocks)

    def slices(self) -> dict[str, slice]:
        """Where each block's values lie in a projected vector."""
        out, start = {}, 0
        for b in self.blocks:
            out[b.name] = slice(start, start + b.output_dim)
            start += b.output_dim
        return out

    def project(self, descriptor: BodyDescriptor) -> NDArray[np.float32]:
        """The wire vector (``length``,) float32 of one descriptor."""
        feats = descriptor_features(descriptor)
        return np.concatenate([(feats[b.name] - b.mean) @ b.components for b in self.blocks]).astype(np.float32)

    def project_many(self, features: Mapping[str, NDArray[np.floating]]) -> NDArray[np.float32]:
        """(n, ``length``) wire vectors of n descriptors given as (n, d) arrays per block name."""
        parts = []
        for b in self.blocks:
            x = np.asarray(features[b.name], dtype=np.float32)
            if x.ndim != 2 or x.shape[1] != b.input_dim:
                raise ValueError(f"features[{b.name!r}] must be (n, {b.input_dim}), got {x.shape}")
            parts.append((x - b.mean) @ b.components)
        return np.concatenate(parts, axis=1).astype(np.float32)


def _config_json(config: BodyDescriptorConfig) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(config).items()}


def save_body_projection(projection: BodyProjection, path: str | Path) -> Path:
    """Write ``projection`` (byte-identical for identical numbers: fixed zip timestamps), atomically."""
    out = Path(path)
    meta = {
        "format": FORMAT_NAME, "version": FORMAT_VERSION, "space": projection.space,
        "descriptor_config": _config_json(projection.descriptor_config),
        "blocks": [{"name": b.name, "input_dim": b.input_dim, "output_dim": b.output_dim} for b in projection.blocks],
        "metadata": dict(projection.metadata),
    }
    arrays: dict[str, NDArray[Any]] = {"meta": np.array(json.dumps(meta, sort_keys=True))}
    for b in projection.blocks:
        arrays[f"{b.name}_mean"] = b.mean
        arrays[f"{b.name}_components"] = b.components
    write_npz(out, arrays, compress=True)
    return out


def load_body_projection(path: str | Path | None = None) -> BodyProjection:
    """Read a projection file (None or "": the installed ``BODY_PROJECTION_FILE``): FileNotFoundError when
    missing, :class:`ModelLoadError` (path and reason) when broken."""
    src = Path(path) if path else model_path(BODY_PROJECTION_FILE)
    if not src.is_file():
        raise FileNotFoundError(f"body projection file {src}: No such file (refit with face-reid-fit-body)")
    try:
        with np.load(src, allow_pickle=False) as data:
            meta = json.loads(data["meta"].item())
            if meta.get("format") != FORMAT_NAME or meta.get("version") != FORMAT_VERSION:
                raise ValueError(f"not a {FORMAT_NAME} version {FORMAT_VERSION} file")
            config = BodyDescriptorConfig(**meta["descriptor_config"])
            blocks = tuple(ProjectionBlock(b["name"], data[f"{b['name']}_mean"], data[f"{b['name']}_components"])
                           for b in meta["blocks"])
            projection = BodyProjection(blocks, config, meta.get("metadata", {}))
    except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:
        raise ModelLoadError(f"body projection file {src} is unusable: {exc}") from exc
    if meta.get("space") != projection.space:
        raise ModelLoadError(f"body projection file {src}: its numbers do not match its recorded space "
                             f"{meta.get('space')!r} (damaged?)")
    return projection


def fit_pca_block(name: str, features: NDArray[np.floating], dims: int) -> ProjectionBlock:
    """A block of the ``dims`` leading principal components of ``features`` (n, d) (the fit tool's PCA)."""
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise ValueError(f"features must be (n >= 2, d), got {x.shape}")
    if not 1 <= dims <= min(x.shape):
        raise ValueError(f"dims must be in [1, {min(x.shape)}] for {x.shape[0]} samples of {x.shape[1]} values, "
                         f"got {dims}")
    mean = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - mean, full_matrices=False)
    comps = vt[:dims].T
    # a deterministic sign per component (largest-magnitude entry positive): refits give identical files
    signs = np.sign(comps[np.argmax(np.abs(comps), axis=0), np.arange(dims)])
    return ProjectionBlock(name, mean, comps * np.where(signs == 0, 1.0, signs))

