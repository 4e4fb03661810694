"""The confidence map: a decision's raw posterior -> how often such decisions were right on development data."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from face_reid_camera.common.errors import ModelLoadError
from face_reid_master.identity.confidence_map import (
    ConfidenceMap,
    default_confidence_map,
    load_confidence_map,
    save_confidence_map,
)
from face_reid_master.tools.fit_confidence import fit_confidence_map

EDGES = [0.0, 0.5, 0.9, 0.99, 1.0]


def _result(face: list[tuple[int, int]], body: list[tuple[int, int]], new: list[tuple[int, int]] | None = None
            ) -> dict:
    """A face-reid-eval result's calibration block: per kind of decision, (count, wrong) per bin."""
    def block(rows: list[tuple[int, int]]) -> dict:
        return {"decisions": sum(n for n, _ in rows),
                "bins": [{"lo": a, "hi": b, "count": n, "wrong": w} for (a, b), (n, w) in
                         zip(itertools.pairwise(EDGES), rows, strict=True)]}
    by = {"face_known": block(face), "body": block(body)}
    if new is not None:
        by["face_new"] = block(new)
    return {"calibration": {"bin_edges": EDGES, "by_decision": by}}


def test_the_fit_is_the_smoothed_accuracy_per_bin_made_non_decreasing() -> None:
    # face: 10 decisions at 0.9-0.99 with 1 wrong, 30 at >= 0.99 with 6 wrong (worse: pooled with the bin below)
    a = _result([(0, 0), (0, 0), (10, 1), (20, 4)], [(0, 0), (0, 0), (0, 0), (8, 2)])
    b = _result([(0, 0), (0, 0), (0, 0), (10, 2)], [(0, 0), (0, 0), (0, 0), (0, 0)],
                new=[(0, 0), (2, 1), (0, 0), (6, 2)])
    cmap = fit_confidence_map([a, b], identities=["p2", "p1", "p1"], sources=["a.json", "b.json"])
    pooled = (9 + 24 + 1) / (40 + 2)  # (right + 1) / (count + 2) of bins 2 and 3 together
    assert cmap.values["face_known"][2] == cmap.values["face_known"][3] == pytest.approx(pooled, abs=1e-6)
    assert cmap.values["face_known"][0] == cmap.values["face_known"][1] == cmap.values["face_known"][2]
    assert cmap.values["face_new"][1] == pytest.approx((1 + 1) / (2 + 2), abs=1e-6)  # each kind on its own
    assert cmap.values["face_new"][3] == pytest.approx((4 + 1) / (6 + 2), abs=1e-6)
    assert cmap.values["body"] == pytest.approx([(6 + 1) / (8 + 2)] * 4)  # empty bins take the filled one's value
    assert cmap.decisions["face_known"] == (0, 0, 10, 30) and cmap.metadata["identities"] == ["p1", "p2"]
    assert cmap.metadata["right"] == {"face_known": 33, "face_new": 5, "body": 6}
    assert list(np.diff(cmap.values["body"])) == [0.0, 0.0, 0.0]


def test_a_decision_is_looked_up_by_its_kind_and_posterior() -> None:
    cmap = ConfidenceMap(tuple(EDGES), {"face_known": (0.1, 0.2, 0.7, 0.9), "face_new": (0.1, 0.2, 0.4, 0.5),
                                        "body": (0.05, 0.1, 0.3, 0.6)})
    assert cmap("face", 0.995) == 0.9 and cmap("both", 0.995) == 0.9 and cmap("body", 0.995) == 0.6
    assert cmap("face", 0.995, new_face=True) == 0.5 and cmap("body", 0.995, new_face=True) == 0.6
    assert cmap("face", 0.95) == 0.7 and cmap("face", 0.0) == 0.1 and cmap("face", 1.0) == 0.9
    raw = ConfidenceMap.identity()
    assert raw("face", 0.951) == 0.951 and raw("body", 0.999) == 0.999 and raw.metadata["identities"] == []


def test_invalid_maps_and_files_are_refused_with_their_reason(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="edges must rise"):
        ConfidenceMap((0.0, 0.9, 0.5, 1.0), {"face_known": (1, 1, 1), "face_new": (1, 1, 1), "body": (1, 1, 1)})
    with pytest.raises(ValueError, match=r"values\['body'\]"):
        ConfidenceMap((0.0, 1.0), {"face_known": (0.5,), "face_new": (0.5,), "body": (1.5,)})
    with pytest.raises(ValueError, match=r"values\['face_new'\]"):
        ConfidenceMap((0.0, 1.0), {"face_known": (0.5,), "body": (0.5,)})
    with pytest.raises(FileNotFoundError, match="No such file"):
        load_confidence_map(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(ModelLoadError, match=f"{bad}.*not a face-reid-confidence-map"):
        load_confidence_map(bad)
    with pytest.raises(ValueError, match="other bin edges"):
        fit_confidence_map([_result([(1, 0)] * 4, [(1, 0)] * 4),
                            {"calibration": {"bin_edges": [0.0, 1.0], "by_decision": {}}}])
    with pytest.raises(ValueError, match="by_decision"):
        fit_confidence_map([{"calibration": {"bin_edges": EDGES, "by_evidence": {}}}])


def test_a_saved_map_loads_back_equal(tmp_path: Path) -> None:
    cmap = fit_confidence_map([_result([(0, 0), (3, 1), (5, 0), (9, 1)], [(0, 0), (0, 0), (4, 1), (0, 0)])],
                              identities=["x"])
    save_confidence_map(cmap, tmp_path / "m.json")
    back = load_confidence_map(tmp_path / "m.json")
    assert back.values == cmap.values and back.edges == cmap.edges and back.metadata["identities"] == ["x"]


def test_the_shipped_map_is_non_decreasing_and_says_what_it_was_fitted_on() -> None:
    cmap = default_confidence_map()
    for kind in ("face_known", "face_new", "body"):
        assert all(b >= a for a, b in zip(cmap.values[kind], cmap.values[kind][1:], strict=False))
        assert all(0.0 < v < 1.0 for v in cmap.values[kind])
    assert cmap.metadata["identities"] and cmap.metadata["decisions"]["face_known"] > 100
