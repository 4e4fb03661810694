"""The figures a robot feels: re-identification cases that showed a face and their recover rate, and the face id
shown on each published detection (another person's, or none yet), on hand-made logs; and the runner's record of
which detections were on a published track (docs/evaluation.md, "What is counted")."""

from __future__ import annotations

import numpy as np

from face_reid_master.core import MasterConfig
from face_reid_master.evaluation.metrics import evaluate_run, face_persons, identity_per_detection
from face_reid_master.evaluation.runner import RunLog, TrackLog, run_master
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.tracking.config import TrackerConfig


def _track(tid: int, person: int, birth: float, *, faces: int, assigned: tuple[float, int, str] | None = None,
           face_gt: list[tuple[float, int]] | None = None) -> TrackLog:
    t = TrackLog(tid, birth, birth + 5.0, gt_counts={person: 10}, confirmed=True)
    t.face_gt = face_gt if face_gt is not None else [(birth + 0.5, person)] * faces
    t.face_detections = faces
    t.first_face_s = birth + 0.5 if faces else None
    if assigned is not None:
        t.assignments.append(assigned)
    return t


def test_reid_cases_that_showed_a_face_need_three_face_detections() -> None:
    tracks = [
        _track(1, 0, 0.0, faces=3, assigned=(1.0, 1, "new")),  # first appearance: not a case
        _track(2, 0, 10.0, faces=3, assigned=(11.0, 1, "known")),  # case with a face, recovered
        _track(3, 0, 20.0, faces=2, assigned=(21.0, 1, "known")),  # recovered but only 2 faces: not counted
        _track(4, 0, 30.0, faces=5),  # showed a face, never decided: counted, not recovered
        _track(5, 0, 40.0, faces=0),  # no face at all: not counted
        _track(6, 0, 50.0, faces=4, assigned=(51.0, 7, "new")),  # a known person given a new id: failure
    ]
    z = np.zeros(0)
    log = RunLog("bayes", {t.track_id: t for t in tracks}, {1: (1.0, 1), 7: (51.0, 6)}, z, z, z, z, z,
                 days=((1, 0.0, 100.0, (0,)),))
    reid = evaluate_run(log, with_mot=False)["reidentification"]
    assert (reid["tracks"], reid["success"]) == (5, 2)
    face = reid["with_face"]
    assert face["min_face_detections"] == 3
    assert (face["tracks"], face["success"], face["failure"], face["none"]) == (3, 1, 1, 1)
    assert face["recover_rate"] == round(1 / 3, 4)


def _detection_log(published: list[bool]) -> RunLog:
    # face 1 was learned by track 1 from person 0; face 3 by track 3, which is mostly person 1 (7 of 10
    # detections) but had shown only person 0's face when it created face 3: face 3 is person 0's
    t1 = _track(1, 0, 0.0, faces=3, assigned=(1.0, 1, "new"))
    t3 = _track(3, 1, 0.0, faces=4, assigned=(2.0, 3, "new"),
                face_gt=[(0.5, 0), (1.0, 0), (3.0, 1), (3.5, 1)])
    t3.gt_counts = {0: 3, 1: 7}
    #            det: 0  1  2  3  4   5  6  7  8
    det_gt = [0, 1, 0, 1, -1, 0, 1, 1, 0]
    det_track = [1, 1, 1, 3, 3, -1, 3, 1, 1]
    det_face = [1, 1, 0, 3, 3, 0, 0, 1, 1]
    z = np.zeros(len(det_gt))
    return RunLog("bayes", {1: t1, 3: t3}, {1: (1.0, 1), 3: (2.0, 3)}, np.arange(len(det_gt)), z, det_gt,
                  det_track, det_face, days=((1, 0.0, 100.0, (0, 1)),), det_published=published)


def test_identity_per_published_detection_judges_each_detection_by_its_own_person() -> None:
    # detections 7 and 8 are on track 1 before it was published (tentative): not what a robot reads
    log = _detection_log([True] * 7 + [False, False])
    assert face_persons(log) == {1: 0, 3: 0}
    per = identity_per_detection(log, face_persons(log))
    # counted: 0 (person 0, face 1: right), 1 (person 1 shown person 0's face 1: wrong), 2 (undecided),
    # 3 (person 1 shown face 3, learned from person 0: wrong), 6 (undecided); 4 is a false positive, 5 untracked
    assert per["published_detections"] == 5
    assert (per["right"], per["wrong_identity"], per["undecided"]) == (1, 2, 2)
    assert (per["wrong_identity_rate"], per["undecided_rate"], per["wrong_of_decided_rate"]) == (0.4, 0.4, 0.6667)
    assert evaluate_run(log, with_mot=False)["per_detection"] == per
    # without the published flags (a log made from published messages) every tracked detection counts
    everything = identity_per_detection(_detection_log([]), face_persons(log))
    assert (everything["published_detections"], everything["right"], everything["wrong_identity"]) == (7, 2, 3)


def test_the_runner_records_which_detections_were_on_a_published_track() -> None:
    frames, gts = [], []
    for k in range(30):  # one person walking, 10 Hz: the track is tentative for its first few frames
        t = k / 10.0
        frames.append(CameraFrameRecord("cam_a", t, (PersonRecord(np.array([0.5 * t, 0.0, 0.0]), 0.05, 1.75, None,
                                                                   0.9, 0.8),)))
        gts.append(np.array([0], dtype=np.int32))
    cfg = MasterConfig(method="bayes", embedding_space="dlib_resnet_v1",
                       tracker=TrackerConfig(lost_after_s=0.5, delete_after_s=1.0))
    log = run_master(frames, gts, cfg, days=[(1, 0.0, 3.0, (0,))])
    assert log.det_published.shape == log.det_gt.shape
    first = int(np.argmax(log.det_published))
    assert 0 < first < 10 and log.det_published[first:].all()  # tentative first, then published to the end
    (track,) = log.tracks.values()
    assert track.published_s == log.det_stamp_s[first]
    per = evaluate_run(log, with_mot=False)["per_detection"]
    assert per["published_detections"] == 30 - first and per["undecided"] == 30 - first  # no face: undecided


def test_oracle_separation_of_people_means_and_observations() -> None:
    from face_reid_master.evaluation.oracle_check import separation

    rows = {0: np.array([[0.0, 0.0], [0.0, 0.2]]), 1: np.array([[3.0, 0.1], [2.0, 0.1]]), 2: np.array([[0.0, 10.0]])}
    sep = separation(rows)
    assert sep["people"] == 3
    assert sep["min_between_person_distance"] == 2.5 and sep["closest_people"] == [0, 1]  # means (0, .1), (2.5, .1)
    assert sep["min_between_observations_distance"] == round(float(np.hypot(2.0, 0.1)), 4)
    assert sep["closest_observations_people"] == [0, 1]
    assert sep["median_within_person_distance"] == 0.1  # each row of 0 is 0.1 from its mean, of 1: 0.5, of 2: 0


def test_a_wrong_person_decision_on_the_person_the_track_followed_from_then_on_is_told_apart() -> None:
    # face 1 is Bob's (person 1, learned by track 1), face 2 Alice's (person 0, track 4). Track 2 follows Alice,
    # undecided, then the tracker moves it to Bob, who shows his face: decided Bob, right from then to its end,
    # yet Alice is its majority person. Track 3 is decided Bob on Bob and then carries him onto Alice.
    rows = [(1, 1, t) for t in (0.0, 0.5, 1.0)] + [(4, 0, t) for t in (2.0, 2.5, 3.0)]
    rows += [(2, 0, 10.0 + k) for k in range(5)] + [(2, 1, 15.0 + k) for k in range(3)]
    rows += [(3, 1, 20.0)] + [(3, 0, 21.0 + k) for k in range(5)]
    tracks = {1: _track(1, 1, 0.0, faces=3, assigned=(1.0, 1, "new")),
              4: _track(4, 0, 2.0, faces=3, assigned=(3.0, 2, "new")),
              2: _track(2, 0, 10.0, faces=3, assigned=(15.0, 1, "known"), face_gt=[(15.0 + k, 1) for k in range(3)]),
              3: _track(3, 0, 20.0, faces=3, assigned=(20.0, 1, "known"), face_gt=[(20.0, 1)] * 3)}
    tracks[2].gt_counts, tracks[3].gt_counts = {0: 5, 1: 3}, {1: 1, 0: 5}
    track, gt, stamp = (np.array(c) for c in zip(*rows, strict=True))
    log = RunLog("bayes", tracks, {1: (1.0, 1), 2: (3.0, 4)}, np.arange(len(rows)), stamp, gt, track,
                 np.zeros(len(rows)), days=((1, 0.0, 100.0, (0, 1)),))
    result = evaluate_run(log, with_mot=False)
    reid = result["reidentification"]
    assert (reid["failure_wrong_person"], reid["failure_wrong_person_after_switch"]) == (2, 1)
    assert (result["table_ii"]["failure"], result["table_ii"]["failure_after_switch"]) == (2, 1)


def test_wrong_ids_a_track_carried_from_a_person_it_followed_before_are_told_apart() -> None:
    # face 1 is Bob's (person 1), face 2 Alice's (person 0). Track 3 is decided Bob on Bob, then the tracker moves
    # it to Alice: it carries Bob's id onto her (5 detections). Track 5 follows only Alice and shows Bob's id (3
    # detections): a wrong decision, nothing carried. Track 2 follows Alice undecided, then Bob shown as Bob: right.
    rows = [(1, 1, t, f) for t, f in ((0.0, 0), (0.5, 0), (1.0, 1))] + [(4, 0, t, f) for t, f in ((2.0, 0), (3.0, 2))]
    rows += [(2, 0, 10.0 + k, 0) for k in range(5)] + [(2, 1, 15.0 + k, 1) for k in range(3)]
    rows += [(3, 1, 20.0, 1)] + [(3, 0, 21.0 + k, 1) for k in range(5)]
    rows += [(5, 0, 30.0 + k, 1) for k in range(3)]
    tracks = {1: _track(1, 1, 0.0, faces=3, assigned=(1.0, 1, "new")),
              4: _track(4, 0, 2.0, faces=3, assigned=(3.0, 2, "new"))}
    track, gt, stamp, face = (np.array(c) for c in zip(*rows, strict=True))
    log = RunLog("bayes", tracks, {1: (1.0, 1), 2: (3.0, 4)}, np.arange(len(rows)), stamp, gt, track, face,
                 days=((1, 0.0, 100.0, (0, 1)),))
    per = identity_per_detection(log, face_persons(log))
    assert (per["wrong_identity"], per["wrong_identity_carried"]) == (8, 5)
    assert per["wrong_identity_carried_rate"] == round(5 / len(rows), 4)
