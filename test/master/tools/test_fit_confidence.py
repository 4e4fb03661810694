"""face_reid_master.tools.fit_confidence: a confidence map from face-reid-eval results of development scenarios."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from face_reid_master.identity.confidence_map import load_confidence_map
from face_reid_master.sim.scenario_files import FORMAT_NAME, FORMAT_VERSION
from face_reid_master.tools.fit_confidence import main

EDGES = [0.0, 0.9, 0.999, 1.0]


def _write_result(tmp: Path, name: str, face: list[tuple[int, int]], body: list[tuple[int, int]],
                  people: dict[str, str], confidence_map: str | None = "raw", record: bool = False) -> Path:
    scenario = tmp / name
    scenario.mkdir()
    (scenario / "scenario.json").write_text(json.dumps(
        {"format": FORMAT_NAME, "version": FORMAT_VERSION,
         "identities": [{"gt_id": k, "name": face_id, "clothes": {"1": crop}}
                        for k, (face_id, crop) in enumerate(people.items())]}))
    def block(rows: list[tuple[int, int]]) -> dict:
        return {"bins": [{"count": n, "wrong": w} for n, w in rows]}
    res = {"scenario": {"directory": str(scenario)},
           "calibration": {"bin_edges": EDGES, "by_decision": {"face_known": block(face), "body": block(body)}}}
    if confidence_map is not None:
        res["confidence_map"] = confidence_map
    path = tmp / f"{name}.json"
    path.write_text(json.dumps({"name": name, "result": res} if record else res))
    return path


def test_the_map_pools_the_results_and_records_their_people(tmp_path: Path, capsys) -> None:
    a = _write_result(tmp_path, "a", [(0, 0), (4, 2), (40, 4)], [(0, 0), (0, 0), (10, 3)],
                      {"celeba_1": "market_1", "celeba_2": "market_2"})
    b = _write_result(tmp_path, "b", [(0, 0), (0, 0), (20, 2)], [(0, 0), (0, 0), (0, 0)],
                      {"celeba_3": "market_1"}, confidence_map=None, record=True)
    out = tmp_path / "map.json"
    assert main([str(a), str(b), "--out", str(out)]) == 0
    cmap = load_confidence_map(out)
    assert cmap.values["face_known"][2] == pytest.approx((54 + 1) / (60 + 2))  # both results' decisions >= 0.999
    assert cmap.values["face_known"][1] == pytest.approx((2 + 1) / (4 + 2))
    assert cmap.values["face_new"] == pytest.approx([0.5] * 3)  # no decision of the kind: no information
    assert cmap.values["body"] == pytest.approx([(7 + 1) / (10 + 2)] * 3)
    assert cmap.metadata["identities"] == ["celeba_1", "celeba_2", "celeba_3", "market_1", "market_2"]
    assert json.loads(capsys.readouterr().out)["people"] == 5


def test_results_evaluated_through_a_map_or_not_results_are_refused(tmp_path: Path, capsys) -> None:
    mapped = _write_result(tmp_path, "m", [(1, 0)] * 3, [(1, 0)] * 3, {"x": "y"}, confidence_map="shipped")
    assert main([str(mapped), "--out", str(tmp_path / "map.json")]) == 2
    assert "--confidence-map raw" in capsys.readouterr().err and not (tmp_path / "map.json").exists()
    (tmp_path / "junk.json").write_text(json.dumps({"table_ii": {}}))
    assert main([str(tmp_path / "junk.json"), "--out", str(tmp_path / "map.json")]) == 2
    assert "not a face-reid-eval result" in capsys.readouterr().err
