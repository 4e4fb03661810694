"""Tests of the calibration of identity decisions (face_reid_master.evaluation.calibration) on hand-made
decisions and run logs with known reliability bins, ECE, error at the thresholds and frontier."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.evaluation.calibration import (
    Decision,
    calibration_report,
    expected_calibration_error,
    frontier,
    reliability_bins,
    run_decisions,
)
from face_reid_master.evaluation.metrics import evaluate_run, track_outcomes
from face_reid_master.evaluation.runner import RunLog, TrackLog

# 4 decisions at 0.96 (3 right) and 6 at 0.9995 (all right)
MIXED_CONF = [0.96] * 4 + [0.9995] * 6
MIXED_RIGHT = [True, True, True, False] + [True] * 6
MIXED_ECE = (4 * abs(0.75 - 0.96) + 6 * abs(1.0 - 0.9995)) / 10  # 0.0843


def test_all_right_at_0_9_has_ece_0_1_in_one_bin() -> None:
    assert expected_calibration_error([0.9] * 7, [True] * 7) == pytest.approx(0.1)
    bins = reliability_bins([0.9] * 7, [True] * 7)
    full = [b for b in bins if b["count"]]
    assert len(full) == 1 and (full[0]["lo"], full[0]["hi"]) == (0.9, 0.95)
    assert full[0]["count"] == 7 and full[0]["accuracy"] == 1.0 and full[0]["mean_confidence"] == pytest.approx(0.9)
    assert all(b["accuracy"] is None for b in bins if not b["count"])
    assert expected_calibration_error([0.9] * 10, [True] * 9 + [False]) == pytest.approx(0.0)  # right 90 %
    assert expected_calibration_error([], []) is None


def test_mixed_decisions_bins_and_ece() -> None:
    assert expected_calibration_error(MIXED_CONF, MIXED_RIGHT) == pytest.approx(MIXED_ECE)
    bins = {(b["lo"], b["hi"]): b for b in reliability_bins(MIXED_CONF, MIXED_RIGHT)}
    assert bins[(0.95, 0.97)]["count"] == 4 and bins[(0.95, 0.97)]["accuracy"] == 0.75
    assert bins[(0.95, 0.97)]["wrong"] == 1
    assert bins[(0.999, 0.9999)]["count"] == 6 and bins[(0.999, 0.9999)]["accuracy"] == 1.0
    assert sum(b["count"] for b in bins.values()) == 10
    # bins are [lo, hi): an edge value goes up; 1.0 is in the last bin
    edges = reliability_bins([0.95, 1.0], [True, True], edges=(0.0, 0.95, 1.0))
    assert [b["count"] for b in edges] == [0, 2]
    # a single bin [0, 1]: ECE = |accuracy - mean confidence| over everything
    assert expected_calibration_error(MIXED_CONF, MIXED_RIGHT, edges=(0.0, 1.0)) == pytest.approx(
        abs(0.9 - float(np.mean(MIXED_CONF))))


def test_frontier_keeps_the_decisions_at_or_above_each_threshold() -> None:
    recovers = [True, False, False, False] + [True] * 3 + [False] * 3
    rows = frontier(MIXED_CONF, MIXED_RIGHT, (0.0, 0.96, 0.97, 0.9996), recovers=recovers, reid_tracks=8)
    got = [(r["threshold"], r["decisions"], r["right"], r["wrong"], r["error_rate"], r["recover_rate"]) for r in rows]
    assert got == [(0.0, 10, 9, 1, 0.1, 0.5), (0.96, 10, 9, 1, 0.1, 0.5), (0.97, 6, 6, 0, 0.0, 0.375),
                   (0.9996, 0, 0, 0, None, 0.0)]
    assert "recover_rate" not in frontier(MIXED_CONF, MIXED_RIGHT, (0.5,))[0]


def test_bad_input_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="differ in length"):
        reliability_bins([0.9, 0.9], [True])
    with pytest.raises(ValueError, match=r"in \[0, 1\]"):
        expected_calibration_error([1.2], [True])
    with pytest.raises(ValueError, match="bin edges"):
        reliability_bins([0.9], [True], edges=(0.1, 1.0))
    with pytest.raises(ValueError, match="one flag per decision"):
        frontier([0.9], [True], recovers=[True, False])


def _decision(conf: float, right: bool, evidence: str = "face", kind: str = "known", *, first: bool = True,
              reid: bool = True) -> Decision:
    return Decision(1, 0.0, 1, kind, conf, evidence, right, "" if right else "wrong_person", first, reid)


def test_report_by_evidence_at_thresholds_and_unrecorded_posteriors() -> None:
    ds = [_decision(c, r) for c, r in zip(MIXED_CONF, MIXED_RIGHT, strict=True)]
    ds += [_decision(0.9999, True, "body"), _decision(0.9995, False, "body"), _decision(math.nan, False)]
    rep = calibration_report(ds, thresholds={"face": 0.95, "body": 0.999}, reid_tracks=12)
    assert rep["decisions"] == 12 and rep["decisions_without_confidence"] == 1 and rep["wrong"] == 2
    face, body = rep["by_evidence"]["face"], rep["by_evidence"]["body"]
    assert face["decisions"] == 10 and face["ece"] == pytest.approx(MIXED_ECE, abs=1e-6)
    assert body["decisions"] == 2 and body["error_rate"] == 0.5 and rep["by_evidence"]["both"]["decisions"] == 0
    assert rep["at_thresholds"]["face"] == {"threshold": 0.95, "promised_max_error": 0.05, "decisions": 10,
                                            "wrong": 1, "error_rate": 0.1, "decisions_below_threshold": 0}
    assert rep["at_thresholds"]["body"]["error_rate"] == 0.5
    assert rep["frontier"][0]["decisions"] == 12 and rep["frontier"][0]["recover_rate"] == pytest.approx(10 / 12)
    kinds = rep["by_decision"]
    assert (kinds["face_known"]["decisions"], kinds["face_new"]["decisions"], kinds["body"]["decisions"]) == (10, 0, 2)
    new = calibration_report([_decision(0.999, False, kind="new"), _decision(0.999, True, kind="new")])
    assert new["by_decision"]["face_new"]["decisions"] == 2 and new["by_decision"]["face_new"]["error_rate"] == 0.5
    assert new["by_decision"]["face_known"]["decisions"] == 0


def _track(tid: int, person: int, birth: float, end: float, assignments: list[tuple[float, int, str]],
           confidence: list[float], evidence: list[str] | None = None) -> TrackLog:
    t = TrackLog(tid, birth, end, gt_counts={person: 10}, confirmed=True)
    t.face_gt = [(birth + 0.5, person)] * 3
    t.assignments = list(assignments)
    t.confidence = list(confidence)
    t.evidence = evidence or ["face"] * len(assignments)
    return t


def test_run_decisions_take_the_table_ii_verdict_and_judge_a_later_decision() -> None:
    swapped = _track(4, 1, 20.0, 30.0, [(21.0, 1, "known"), (26.0, 2, "known")], [0.97, 0.999])
    swapped.face_gt = [(20.5, 1)] * 3 + [(25.0, 1)] * 3  # person 1 all along: the first face id (0's) is wrong
    tracks = [
        _track(1, 0, 0.0, 8.0, [(2.0, 1, "new")], [0.96]),  # first appearance: right
        _track(2, 1, 1.0, 9.0, [(4.0, 2, "new")], [0.99]),  # first appearance: right
        _track(3, 0, 10.0, 18.0, [(13.5, 1, "known")], [0.9999], ["body"]),  # re-identified by body: right
        swapped,  # wrong known face, then (its face taken while lost) given its own: right
        _track(5, 0, 40.0, 45.0, [(41.0, 3, "new")], [0.98]),  # known person given a new id: wrong
        _track(6, 1, 50.0, 55.0, [], []),  # never decided
    ]
    log = RunLog("bayes", {t.track_id: t for t in tracks}, {1: (2.0, 1), 2: (4.0, 2), 3: (41.0, 5)},
                 *(np.zeros(0),) * 5, decision_thresholds={"face": 0.95, "body": 0.999})
    ds = run_decisions(log)
    assert [(d.track_id, d.confidence, d.right, d.first) for d in ds] == [
        (1, 0.96, True, True), (2, 0.99, True, True), (3, 0.9999, True, True), (4, 0.97, False, True),
        (4, 0.999, True, False), (5, 0.98, False, True)]
    assert ds[3].failure_kind == "wrong_person" and ds[5].failure_kind == "new_id" and ds[2].evidence == "body"
    outcomes = {o.track_id: o for o in track_outcomes(log)}
    assert all((d.right == (outcomes[d.track_id].outcome == "success")) for d in ds if d.first)
    cal = evaluate_run(log, with_mot=False)["calibration"]
    assert (cal["decisions"], cal["first_decisions"], cal["decisions_after_release"], cal["wrong"]) == (6, 5, 1, 2)
    assert cal["at_thresholds"]["face"]["decisions"] == 5 and cal["at_thresholds"]["face"]["wrong"] == 2
    assert cal["at_thresholds"]["body"]["decisions"] == 1 and cal["at_thresholds"]["body"]["wrong"] == 0
    # re-identification cases: tracks 3, 4, 5, 6; right first decisions among them: track 3 -> recover rate 1/4
    assert cal["frontier"][0]["recover_rate"] == 0.25
    assert evaluate_run(log, with_mot=False)["reidentification"]["recover_rate"] == 0.25
