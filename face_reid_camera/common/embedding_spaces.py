"""Face embedding spaces: which network (and version) produced an embedding, and how long it is.

A camera names the space of every embedding it sends; the master compares embeddings of one space
only. A *joint* space is several component spaces joined by ``+`` with the values concatenated in
that order (what ``embedder: both`` sends), so a master of one component can still use its part.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "DLIB_SPACE",
    "EMBEDDER_CHOICES",
    "SFACE_SPACE",
    "SPACES",
    "EmbeddingSpace",
    "embedder_for_space",
    "embedder_space",
    "extract_space",
    "parse_space",
    "plausible_norms",
    "space_dim",
]


@dataclass(frozen=True)
class EmbeddingSpace:
    """One embedder's output space: ``space_id`` (network + version), length, whether rows are unit vectors,
    and the range of lengths (L2 norms) its rows can plausibly have (others are forged or broken)."""

    space_id: str
    dim: int
    unit_norm: bool
    description: str
    norm_range: tuple[float, float] = (0.0, math.inf)


DLIB_SPACE = "dlib_resnet_v1"
SFACE_SPACE = "sface_2021dec"
SPACES: dict[str, EmbeddingSpace] = {
    DLIB_SPACE: EmbeddingSpace(DLIB_SPACE, 128, False,
                               "dlib_face_recognition_resnet_model_v1, raw 128-d (same person: L2 < ~0.6)",
                               (0.5, 3.0)),  # real faces: 1.2-1.65 (test photos and simulated camera views)
    SFACE_SPACE: EmbeddingSpace(SFACE_SPACE, 128, True,
                                "OpenCV Zoo SFace 2021dec, 128-d scaled to unit length (L2 = sqrt(2 - 2 cos))",
                                (0.9, 1.1)),  # unit length; the simulator's noisy views: 0.98-1.04
}
# The camera's ``embedder`` parameter: which networks run, in the order their values are concatenated.
EMBEDDER_CHOICES: dict[str, tuple[str, ...]] = {
    "dlib": (DLIB_SPACE,),
    "sface": (SFACE_SPACE,),
    "both": (DLIB_SPACE, SFACE_SPACE),
}


def embedder_space(embedder: str) -> str:
    """The space id a camera with ``embedder`` (dlib | sface | both) sends."""
    try:
        return "+".join(EMBEDDER_CHOICES[embedder])
    except KeyError:
        raise ValueError(f"embedder must be one of {sorted(EMBEDDER_CHOICES)}, got {embedder!r}") from None


def embedder_for_space(space: str) -> str:
    """The camera ``embedder`` choice that produces exactly ``space`` (ValueError if none does)."""
    for choice, parts in EMBEDDER_CHOICES.items():
        if "+".join(parts) == space:
            return choice
    raise ValueError(f"no embedder produces space {space!r} (known: "
                     f"{sorted('+'.join(p) for p in EMBEDDER_CHOICES.values())})")


@lru_cache(maxsize=64)  # called per observation by the master; bounded against hostile space strings
def parse_space(space: str) -> tuple[EmbeddingSpace, ...]:
    """The components of a (possibly joint) space id; ValueError for unknown or repeated components."""
    if not isinstance(space, str) or not space:
        raise ValueError(f"embedding space must be a non-empty string, got {space!r}")
    names = space.split("+")
    unknown = [n for n in names if n not in SPACES]
    if unknown:
        raise ValueError(f"unknown embedding space {unknown[0][:64]!r} in {space[:128]!r} (known: {sorted(SPACES)})")
    if len(set(names)) != len(names):
        raise ValueError(f"embedding space {space[:128]!r} repeats a component")
    return tuple(SPACES[n] for n in names)


def plausible_norms(rows: NDArray[np.floating], space: str) -> NDArray[np.bool_]:
    """Per row of ``rows`` (n, dim) of ``space``: whether every component's length lies in its embedder's
    :attr:`EmbeddingSpace.norm_range` (False for all when ``dim`` is not the space's)."""
    starts, low, high = _norm_ranges(space)
    if rows.ndim != 2 or rows.shape[1] != space_dim(space):
        return np.zeros(rows.shape[0] if rows.ndim else 0, dtype=bool)
    norms = np.sqrt(np.add.reduceat(rows * rows, starts, axis=1))  # (n, components)
    return ((norms >= low) & (norms <= high)).all(axis=1)


@lru_cache(maxsize=64)
def _norm_ranges(space: str) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Where each component of ``space`` starts, and its norm range (low, high)."""
    parts = parse_space(space)
    starts = np.cumsum([0] + [p.dim for p in parts[:-1]]).astype(np.intp)
    return starts, np.array([p.norm_range[0] for p in parts]), np.array([p.norm_range[1] for p in parts])


def space_dim(space: str) -> int:
    """Number of values of an embedding of ``space`` (the sum over its components)."""
    return sum(c.dim for c in parse_space(space))


def extract_space(values: NDArray[np.float32], have: str, want: str) -> NDArray[np.float32] | None:
    """The part of an embedding of space ``have`` that is space ``want`` (concatenated in ``want``'s
    order), or None when ``have`` lacks a component of ``want``. ``values`` may be (dim,) or (n, dim)."""
    if have == want:
        return values
    have_parts = parse_space(have)
    offsets: dict[str, tuple[int, int]] = {}
    start = 0
    for part in have_parts:
        offsets[part.space_id] = (start, start + part.dim)
        start += part.dim
    pieces = []
    for part in parse_space(want):
        span = offsets.get(part.space_id)
        if span is None:
            return None
        pieces.append(values[..., span[0]: span[1]])
    return pieces[0] if len(pieces) == 1 else np.concatenate(pieces, axis=-1)
