"""Synthetic face embeddings for the benchmarks, sent as a camera would: each component at its embedder's
length (the master refuses others) and people spread to chosen distances in the master's weighted space."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from face_reid_camera.common.embedding_spaces import parse_space, space_dim
from face_reid_master.identity.size_likelihood import default_face_likelihood

__all__ = ["FaceSpace"]

@dataclass(frozen=True)
class FaceSpace:
    """The embeddings of one master space, sent as a camera would: each component of a person's embedding has
    the length its embedder gives (dlib ~1.4, SFace 1; the master refuses implausible lengths), people's
    directions spread to chosen mean distances in the master's weighted space (:meth:`of`)."""

    name: str
    dim: int
    weights: np.ndarray  # what the master multiplies camera embeddings by
    parts: tuple[tuple[int, int, float], ...]  # (start, stop, length) of each component
    base: np.ndarray  # the direction every person's component starts from (unit per component)
    spread: float  # people's directions around the base
    noise: float  # one person's embeddings around their direction

    @classmethod
    def of(cls, name: str, between: float = 1.33, within: float = 0.75) -> FaceSpace:
        """Different people ``between`` and one person's embeddings ``within`` times the decision distance
        apart (means)."""
        dim, model = space_dim(name), default_face_likelihood(name)
        parts, start = [], 0
        for part in parse_space(name):
            parts.append((start, start + part.dim, 1.0 if part.unit_norm else 1.4))
            start += part.dim
        rng = np.random.default_rng(1)
        base = rng.normal(size=dim)
        sp = cls(name, dim, model.scale(np.ones((1, dim), dtype=np.float32))[0], tuple(parts), base, 0.0, 0.0)
        sp = dataclasses.replace(sp, base=sp._on_spheres(base[None, :])[0])
        d = model.decision_distance
        spread = _bisect(lambda x: sp._spread_distance(x, 0.0, rng), between * d)
        noise = _bisect(lambda x: sp._spread_distance(spread, x, rng, same=True), within * d)
        return dataclasses.replace(sp, spread=spread, noise=noise)

    def _on_spheres(self, rows: np.ndarray) -> np.ndarray:
        out = np.empty_like(rows, dtype=np.float32)
        for a, b, length in self.parts:
            out[:, a:b] = rows[:, a:b] * (length / np.linalg.norm(rows[:, a:b], axis=1, keepdims=True))
        return out

    def people(self, n: int, rng: np.random.Generator, spread: float | None = None) -> np.ndarray:
        s = self.spread if spread is None else spread
        return self._on_spheres(self.base + s * rng.normal(size=(n, self.dim)) / np.sqrt(self.dim))

    def observe(self, centres: np.ndarray, rng: np.random.Generator, noise: float | None = None) -> np.ndarray:
        z = self.noise if noise is None else noise
        return self._on_spheres(centres + z * rng.normal(size=centres.shape) / np.sqrt(self.dim))

    def _spread_distance(self, spread: float, noise: float, rng: np.random.Generator, same: bool = False) -> float:
        """Mean weighted distance between two people (or two embeddings of one person when ``same``)."""
        c = self.people(200, rng, spread)
        a = self.observe(c, rng, noise)
        b = self.observe(c if same else c[::-1], rng, noise)
        return float(np.mean(np.linalg.norm((a - b) * self.weights, axis=1)))


def _bisect(f: Callable[[float], float], target: float, lo: float = 0.0, hi: float = 50.0) -> float:
    """x in [lo, hi] with f(x) ~ target, f increasing."""
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < target else (lo, mid)
    return 0.5 * (lo + hi)
