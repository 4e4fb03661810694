"""The per-frame embedding budget: best faces first, every person refreshed in turn."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_camera.faces.embedding_schedule import EmbeddingScheduler


def _heads(n: int) -> np.ndarray:
    return np.array([[x, 0.0, 3.0] for x in np.linspace(-2.0, 2.0, n)])


def test_no_budget_embeds_every_face_in_order() -> None:
    sched = EmbeddingScheduler(0.0)
    assert sched.choose(0.0, _heads(5), np.full(5, 0.5)) == [0, 1, 2, 3, 4]


def test_budget_refreshes_every_face_in_turn_best_quality_first() -> None:
    sched = EmbeddingScheduler(budget_ms=30.0)
    heads, quality = _heads(5), np.array([0.2, 0.9, 0.5, 0.7, 0.1])
    first = sched.choose(0.0, heads[:1], quality[:1])  # one person in the first frame
    assert first == [0]  # cost unknown: everything (measured)
    sched.embedded(0.0, first, 14.0)  # 14 ms per face -> two faces fit in 30 ms
    heads, quality = heads[[1, 0, 2, 3, 4]], quality[[1, 0, 2, 3, 4]]  # then five, the first one in row 1
    last_embedded = {1: 0.0}
    for frame in range(1, 11):
        t = frame * 0.1
        chosen = sched.choose(t, heads + 0.01 * frame, quality)  # people move a little between frames
        assert len(chosen) == 2
        sched.embedded(t, chosen, 28.0)
        for i in chosen:
            last_embedded[i] = t
        if frame == 1:
            assert chosen == [0, 3]  # never embedded yet: best quality first (0.9, 0.7)
        if frame >= 3:
            assert set(last_embedded) == {0, 1, 2, 3, 4}
            assert t - min(last_embedded.values()) <= 0.3  # nobody waits more than 3 frames
    assert sched.cost_ms_per_face == pytest.approx(14.0)


def test_a_new_person_is_served_before_known_ones_and_gone_heads_are_forgotten() -> None:
    sched = EmbeddingScheduler(budget_ms=10.0, forget_after_s=1.0)
    sched.embedded(0.0, sched.choose(0.0, _heads(2), np.array([0.9, 0.8])), 20.0)  # 10 ms per face: 1 fits
    sched.embedded(0.1, sched.choose(0.1, _heads(2), np.array([0.9, 0.8])), 10.0)
    newcomer = np.vstack([_heads(2), [[0.0, 0.0, 1.5]]])
    assert sched.choose(0.2, newcomer, np.array([0.9, 0.8, 0.1])) == [2]
    sched.choose(5.0, np.zeros((0, 3)), np.zeros(0))
    assert sched.choose(5.1, _heads(1), np.array([0.5])) == [0]


def test_bad_arguments_are_named() -> None:
    with pytest.raises(ValueError, match="budget_ms"):
        EmbeddingScheduler(-1.0)
    with pytest.raises(ValueError, match="match_radius_m"):
        EmbeddingScheduler(10.0, match_radius_m=0.0)
