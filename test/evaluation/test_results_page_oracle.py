"""bench/results_page.py: an oracle-evidence result sits beside the real one (evidence "oracle (...)", its
separation line), out of the pooled calibration and the README's table; the per-detection columns are '-' for
a result recorded before they existed."""

from __future__ import annotations

import copy
import importlib.util
import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def page_module():
    spec = importlib.util.spec_from_file_location("results_page_under_test", REPO / "bench" / "results_page.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _docs() -> tuple[dict, dict]:
    real = json.loads((REPO / "bench" / "results" / "eval_test6p_s302.json").read_text(encoding="utf-8"))
    for key in ("per_detection", "oracle"):  # a result recorded before these existed
        real["result"].pop(key, None)
    real["result"]["reidentification"].pop("with_face", None)
    oracle = copy.deepcopy(real)
    oracle["name"] = "test6p_s302_oracle"
    oracle["simulation"].update(oracle=True, oracle_noise_std=0.01)
    res = oracle["result"]
    res["reidentification"]["with_face"] = {"min_face_detections": 3, "tracks": 20, "success": 18, "failure": 1,
                                            "none": 1, "recover_rate": 0.9}
    res["per_detection"] = {"published_detections": 1000, "right": 700, "wrong_identity": 25, "undecided": 275,
                            "right_rate": 0.7, "wrong_identity_rate": 0.025, "undecided_rate": 0.275,
                            "wrong_of_decided_rate": 0.0345}
    res["oracle"] = {"oracle": True, "noise_std": 0.01, "space": "dlib_resnet_v1+sface_2021dec", "people": 6,
                     "min_between_person_distance": 1.25, "closest_people": [1, 3],
                     "min_between_observations_distance": 1.2, "closest_observations_people": [3, 4],
                     "median_within_person_distance": 0.17, "decision_distance": 1.1533,
                     "decision_distance_by_size": [], "name_distance": 0.949, "separated": True}
    return real, oracle


def test_oracle_rows_beside_real_ones_with_the_new_columns(page_module, monkeypatch, tmp_path: Path) -> None:
    real, oracle = _docs()
    for doc in (real, oracle):
        (tmp_path / f"eval_{doc['name']}.json").write_text(json.dumps(doc), encoding="utf-8")
    monkeypatch.setattr(page_module, "RESULTS", tmp_path)
    page = page_module.page()
    rows = {line.split(" | ")[0][2:]: line for line in page.splitlines() if line.startswith("| test6p")}
    cols = {name: line.split(" | ") for name, line in rows.items()}
    evidence = page_module._COLUMNS.index("evidence")
    assert cols["test6p_s302"][evidence] == "fused" and cols["test6p_s302_oracle"][evidence] == "oracle (fused)"
    face_cases = page_module._COLUMNS.index("face re-id cases recovered")
    assert cols["test6p_s302"][face_cases: face_cases + 3] == ["-", "-", "-"]  # recorded before they existed
    assert cols["test6p_s302_oracle"][face_cases: face_cases + 3] == ["18 of 20 (90.0 %)", "2.5 %", "27.5 %"]
    assert "`test6p_s302_oracle` (dlib_resnet_v1+sface_2021dec, noise 0.01): the closest two people's " \
           "observations 1.2 apart" in page
    assert "decision distance 1.1533 and the naming distance 0.949: no two people confusable" in page
    pooled = next(line for line in page.splitlines() if line.startswith("- fused evidence"))
    assert "test6p_s302_oracle" not in pooled and "test6p_s302" in pooled
    headline = page_module.headline()
    assert "| test6p_s302 |" in headline and "oracle" not in headline
