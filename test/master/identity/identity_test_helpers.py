"""Shared helpers of the identity tests: hand-built embeddings with dlib-like geometry."""

from __future__ import annotations

import math

import numpy as np

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.records import IdentityEvent, IdentityEventKind, LearnedFace

DIM = 128

ASSIGNED = IdentityEventKind.ASSIGNED_KNOWN
NEW = IdentityEventKind.NEW_FACE
RELEASED = IdentityEventKind.RELEASED
SWAPPED = IdentityEventKind.SWAPPED


def unit_vector(i: int, scale: float = 1.0) -> np.ndarray:
    """``scale`` times the i-th basis vector of the embedding space (float32)."""
    v = np.zeros(DIM, dtype=np.float32)
    v[i] = scale
    return v


def event_kinds(events: list[IdentityEvent]) -> list[tuple[IdentityEventKind, int, int]]:
    """(kind, track id, face id) of each event, for comparisons."""
    return [(e.kind, e.track_id, e.face_id) for e in events]


CENTRES = [unit_vector(i, 0.7) for i in range(8)]  # different people ~0.99 apart
NOISE = 0.3 / math.sqrt(2 * DIM)  # same person ~0.3 apart


def person_obs(p: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """n noisy embeddings of person p (around CENTRES[p])."""
    return (CENTRES[p] + rng.normal(0.0, NOISE, (n, DIM))).astype(np.float32)


def manager_with_faces(n_faces: int, rng: np.random.Generator, **kw: object) -> BayesIdentityManager:
    """A Bayes manager that already learned persons 0..n_faces-1 as faces 1..n_faces (5 features each)."""
    m = BayesIdentityManager(**kw)  # type: ignore[arg-type]
    m.faces.import_faces([LearnedFace(j + 1, person_obs(j, 5, rng)) for j in range(n_faces)])
    return m


def feed_one(m: BayesIdentityManager, track: int, person: int, rng: np.random.Generator, t: float) -> list:
    """One observation of ``person`` on ``track`` at t, then one step; returns the step's events."""
    m.add_observations(track, person_obs(person, 1, rng), t)
    return m.step(t)
