"""Tests of the offline evaluation (face_reid_master.evaluation: runner, metrics, gallery, cli and plots).

Metric definitions are checked on hand-made run logs with known answers (exact re-identification time,
success / failure / none, recover rates, names, IDF1 = 1 for a perfect run and < 1 with a swap); the
real MasterCore with real face embeddings of the fixture photos then produces the expected outcomes
(perfect stream, a confusable pair, swapped faces, a faceless return); the CLI runs on a tiny simulated
scenario.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import FACES_DIR, copy_fixture_faces

from face_reid_camera.faces.photos import PhotoEmbedder
from face_reid_master.core import MasterConfig
from face_reid_master.evaluation.cli import main
from face_reid_master.evaluation.gallery import default_gallery_people, scenario_gallery
from face_reid_master.evaluation.metrics import (
    evaluate_run,
    face_persons,
    mot_metrics,
    paired_reid_times,
    track_outcomes,
)
from face_reid_master.evaluation.runner import RunLog, TrackLog, run_master
from face_reid_master.identity.confidence_map import ConfidenceMap
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal, save_likelihood_model
from face_reid_master.identity.size_likelihood import FaceLikelihood, save_face_likelihood
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.tracking.config import TrackerConfig

IDS = ("lfw_Tony_Blair", "lfw_Colin_Powell", "lfw_Hugo_Chavez")


# ------------------------------------------------------------------------------------- hand-made logs
def _track(tid: int, person: int, birth: float, end: float, *, assigned: tuple[float, int, str] | None = None,
           confirmed: bool = True, names: dict[str, float] | None = None, n_det: int = 10) -> TrackLog:
    t = TrackLog(tid, birth, end, gt_counts={person: n_det}, confirmed=confirmed, names=names or {})
    t.face_gt = [(birth + 0.5, person)] * 3
    t.first_face_s = birth + 0.5
    t.face_detections = 3
    if assigned is not None:
        t.assignments.append(assigned)
    return t


def _empty_log(tracks: list[TrackLog], faces: dict[int, tuple[float, int]]) -> RunLog:
    z = np.zeros(0)
    return RunLog("bayes", {t.track_id: t for t in tracks}, faces, z, z, z, z, z,
                  days=((1, 0.0, 100.0, (0, 1)),))


def _timeline() -> RunLog:
    tracks = [
        _track(1, 0, 0.0, 8.0, assigned=(2.0, 1, "new"), names={"alice": 3.0}),  # first appearance, right
        _track(2, 1, 1.0, 9.0, assigned=(4.0, 2, "new")),  # first appearance, right
        _track(3, 0, 10.0, 18.0, assigned=(13.5, 1, "known"), names={"alice": 14.0}),  # re-id success 3.5 s
        _track(4, 1, 20.0, 25.0, assigned=(21.0, 1, "known"), names={"alice": 21.0}),  # re-id, wrong person
        _track(5, 0, 30.0, 35.0, assigned=(31.0, 3, "new")),  # known person given a new id: failure
        _track(6, 1, 40.0, 45.0),  # re-id case, never decided: none
        _track(7, 1, 50.0, 60.0, assigned=(56.5, 2, "known")),  # re-id success 6.5 s
        _track(8, 0, 61.0, 61.2, confirmed=False),  # tentative only: not evaluated
        _track(9, -1, 62.0, 64.0),  # false-positive track
    ]
    return _empty_log(tracks, {1: (2.0, 1), 2: (4.0, 2), 3: (31.0, 5)})


def test_outcomes_and_times_on_a_hand_made_timeline() -> None:
    log = _timeline()
    outcomes = {o.track_id: o for o in track_outcomes(log)}
    assert set(outcomes) == {1, 2, 3, 4, 5, 6, 7}
    assert [outcomes[t].reid_case for t in (1, 2, 3, 4, 5, 6, 7)] == [False, False, True, True, True, True, True]
    assert outcomes[4].failure_kind == "wrong_person" and outcomes[5].failure_kind == "new_id"
    assert outcomes[6].outcome == "none" and outcomes[3].outcome == outcomes[7].outcome == "success"
    r = evaluate_run(log, gallery_people={"alice": 0}, scenario_summary={"losses": 5}, with_mot=False)
    reid = r["reidentification"]
    assert (reid["tracks"], reid["success"], reid["failure"], reid["none"]) == (5, 2, 2, 1)
    assert (reid["failure_wrong_person"], reid["failure_new_id"]) == (1, 1)
    assert reid["mean_reid_time_s"] == pytest.approx(5.0)  # (3.5 + 6.5) / 2
    assert reid["mean_reid_time_from_first_face_s"] == pytest.approx(4.5)  # first faces 0.5 s after birth
    assert reid["recover_rate"] == pytest.approx(0.4)  # 2 / 5 re-identification tracks
    assert reid["recover_rate_all_tracks"] == pytest.approx(round(2 / 7, 4))
    assert reid["recover_rate_gt_opportunities"] == pytest.approx(0.4)  # 2 / 5 losses
    first = r["first_appearance"]
    assert (first["tracks"], first["new_id"], first["failure_wrong_person"]) == (2, 2, 0)
    assert first["mean_decision_time_s"] == pytest.approx(2.5)  # (2 + 3) / 2
    assert r["table_ii"] == {"success": 2, "failure": 2, "failure_after_switch": 0, "re_id_time_s": 5.0,
                             "recover_rate": 0.4, "recover_rate_paper": 0.4}  # no per-detection records: no switch
    assert r["tracker"]["false_positive_tracks"] == 1 and r["tracker"]["tracks_never_confirmed"] == 1
    assert r["tracker"]["tracks_per_person"] == {"0": 3, "1": 4}
    names = r["predefined_people"]
    assert (names["gallery_tracks"], names["right_name"], names["wrong_name"], names["no_name"]) == (3, 2, 0, 1)
    assert names["mean_time_to_name_s"] == pytest.approx(3.5)  # (3 + 4) / 2
    assert (names["other_tracks"], names["other_tracks_named"]) == (4, 1)  # track 4 shows "alice"


def test_first_appearance_given_a_known_face_is_a_failure() -> None:
    # the paper's only failure: a newly appeared person identified as an existing one
    log = _empty_log([_track(1, 0, 0.0, 5.0, assigned=(1.0, 1, "new")),
                      _track(2, 1, 10.0, 15.0, assigned=(12.0, 1, "known"))], {1: (1.0, 1)})
    r = evaluate_run(log, with_mot=False)
    assert r["first_appearance"]["failure_wrong_person"] == 1 and r["reidentification"]["tracks"] == 0
    assert r["table_ii"]["failure"] == 1 and r["table_ii"]["success"] == 0


def test_face_of_an_impure_track_belongs_to_the_person_whose_faces_it_saw() -> None:
    # track 1 has more detections of person 0, but all its face detections are of person 1
    t1 = _track(1, 0, 0.0, 5.0, assigned=(1.0, 1, "new"), n_det=20)
    t1.gt_counts = {0: 20, 1: 5}
    t1.face_gt = [(0.5, 1)] * 4
    log = _empty_log([t1, _track(2, 1, 10.0, 15.0, assigned=(12.0, 1, "known"))], {1: (1.0, 1)})
    outcomes = {o.track_id: o for o in track_outcomes(log)}
    assert outcomes[2].reid_case and outcomes[2].outcome == "success"
    assert evaluate_run(log, with_mot=False)["faces"]["faces_learned_from_another_person_than_their_track"] == 1


def test_a_face_belongs_to_the_person_it_was_created_from_not_to_whom_its_track_swapped() -> None:
    # track 1 made face 1 from person 1's faces at 1.0 s, then the tracker swapped it onto person 0 (whose
    # faces the consistency gate keeps out of face 1): person 1's next track getting face 1 is a success
    t1 = _track(1, 0, 0.0, 9.0, assigned=(1.0, 1, "new"), n_det=30)
    t1.gt_counts = {0: 25, 1: 5}
    t1.face_gt = [(0.5, 1)] * 3 + [(5.0, 0)] * 20
    log = _empty_log([t1, _track(2, 1, 10.0, 15.0, assigned=(12.0, 1, "known"))], {1: (1.0, 1)})
    outcomes = {o.track_id: o for o in track_outcomes(log)}
    assert face_persons(log) == {1: 1}
    assert outcomes[2].outcome == "success" and outcomes[1].failure_kind == "wrong_person"


def test_new_id_while_the_face_is_held_by_a_duplicate_track_is_flagged() -> None:
    log = _empty_log([_track(1, 0, 0.0, 20.0, assigned=(1.0, 1, "new")),
                      _track(2, 0, 5.0, 10.0, assigned=(6.0, 2, "new"))], {1: (1.0, 1), 2: (6.0, 2)})
    (o,) = [o for o in track_outcomes(log) if o.track_id == 2]
    assert o.failure_kind == "new_id" and o.face_busy


def _mot_log(tracks: list[list[int]], faces: list[list[int]]) -> RunLog:
    """10 frames with persons 0 and 1 detected in each; tracks[f] / faces[f] = hypotheses of frame f."""
    n = len(tracks)
    frame = np.repeat(np.arange(n), 2)
    return RunLog("bayes", {}, {}, frame, frame * 0.1, np.tile([0, 1], n), np.array(tracks).ravel(),
                  np.array(faces).ravel())


def test_motmetrics_idf1_is_one_on_a_perfect_run_and_lower_with_a_swap() -> None:
    perfect = _mot_log([[1, 2]] * 10, [[5, 6]] * 10)
    for kind in ("track", "face"):
        m = mot_metrics(perfect, kind)
        assert m["idf1"] == pytest.approx(1.0) and m["mota"] == pytest.approx(1.0) and m["num_switches"] == 0
    swapped = _mot_log([[1, 2]] * 5 + [[2, 1]] * 5, [[5, 6]] * 5 + [[6, 5]] * 5)
    m = mot_metrics(swapped, "track")
    assert m["idf1"] == pytest.approx(0.5) and m["num_switches"] == 2
    # identity decided only from frame 3: the first 3 frames have no face id (misses)
    late = _mot_log([[1, 2]] * 10, [[0, 0]] * 3 + [[5, 6]] * 7)
    m = mot_metrics(late, "face")
    assert m["idp"] == pytest.approx(1.0) and m["idr"] == pytest.approx(0.7) and m["num_misses"] == 6
    with pytest.raises(ValueError, match="hypothesis"):
        mot_metrics(perfect, "name")


def test_run_log_rejects_inconsistent_arrays() -> None:
    with pytest.raises(ValueError, match="one length"):
        RunLog("bayes", {}, {}, np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match="NaN"):
        RunLog("bayes", {}, {}, np.zeros(1), np.array([np.nan]), np.zeros(1), np.zeros(1), np.zeros(1))


# ------------------------------------------------------------------------------------- real master core
@pytest.fixture(scope="module")
def embedder() -> PhotoEmbedder:
    return PhotoEmbedder()


@pytest.fixture(scope="module")
def embeddings(embedder: PhotoEmbedder) -> dict[str, np.ndarray]:
    """identity -> (n, 128) real embeddings of the fixture photos (sorted by file name)."""
    out = {}
    for ident in IDS:
        rows = [e.embedding for p in sorted((FACES_DIR / ident).glob("*.jpg")) if (e := embedder.embed_photo(p))]
        out[ident] = np.stack(rows)
    return out


def _frames(visits: list[tuple[int, float, float, float, np.ndarray | None]], rate_hz: float = 10.0
            ) -> tuple[list[CameraFrameRecord], list[np.ndarray]]:
    """visits: (gt id, t0, t1, lane y, embedding rows or None); people walk +x at 0.5 m/s in their lane."""
    t_end = max(v[2] for v in visits)
    frames, gts = [], []
    for k in range(int(t_end * rate_hz) + 1):
        t = k / rate_hz
        people, ids = [], []
        for gt, t0, t1, lane, embs in visits:
            if t0 <= t < t1:
                emb = embs[k % len(embs)] if embs is not None else None
                people.append(PersonRecord(np.array([0.5 * (t - t0), lane, 0.0]), 0.05, 1.75, emb, 0.9, 0.8))
                ids.append(gt)
        frames.append(CameraFrameRecord(("cam_a", "cam_b")[k % 2], t, tuple(people)))
        gts.append(np.array(ids, dtype=np.int32))
    return frames, gts


def _config(method: str) -> MasterConfig:
    return MasterConfig(method=method, embedding_space="dlib_resnet_v1",  # the fixtures' embeddings
                        tracker=TrackerConfig(lost_after_s=0.5, delete_after_s=1.0))


@pytest.mark.parametrize("method", ["bayes", "threshold"])
def test_real_core_perfect_stream_all_successes(embeddings, method: str) -> None:
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]
    frames, gts = _frames([(0, 0.0, 4.0, 0.0, a[:5]), (1, 0.0, 4.0, 3.0, b[:5]),
                           (0, 7.0, 11.0, 0.0, a[5:]), (1, 7.0, 11.0, 3.0, b[5:])])
    log = run_master(frames, gts, _config(method), days=[(1, 0.0, 11.0, (0, 1))])
    r = evaluate_run(log, scenario_summary={"losses": 2})
    assert r["first_appearance"]["tracks"] == 2 and r["first_appearance"]["new_id"] == 2
    reid = r["reidentification"]
    assert (reid["tracks"], reid["success"], reid["failure"], reid["none"]) == (2, 2, 0, 0), r
    assert reid["recover_rate"] == 1.0 and reid["recover_rate_gt_opportunities"] == 1.0
    assert 0.0 < reid["mean_reid_time_s"] < 1.5
    assert r["faces"]["created"] == 2 and r["tracker"]["impure_tracks"] == 0
    tracker = r["mot"]["tracker"]
    assert tracker["num_switches"] == 2  # each person changes track once (left the room)
    assert tracker["num_misses"] == tracker["num_false_positives"] == 0
    assert tracker["mota"] == pytest.approx(1.0 - 2 / tracker["num_objects"], abs=1e-4)  # MOTA counts switches
    assert r["mot"]["identity"]["num_switches"] == 0 and r["mot"]["identity"]["idp"] == pytest.approx(1.0)
    assert r["mot"]["identity"]["idf1"] > r["mot"]["tracker"]["idf1"]  # face ids survive leaving the room


def test_real_core_confusable_pair_and_swapped_faces_are_failures(embeddings) -> None:
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]
    # person 1 shows person 0's face (a look-alike): at first appearance he gets person 0's face id
    frames, gts = _frames([(0, 0.0, 4.0, 0.0, a[:5]), (1, 7.0, 11.0, 3.0, a[5:])])
    r = evaluate_run(run_master(frames, gts, _config("bayes")), with_mot=False)
    assert r["first_appearance"]["failure_wrong_person"] == 1 and r["table_ii"]["failure"] == 1
    # both learned; then person 0 returns showing person 1's face: a wrong re-identification
    frames, gts = _frames([(0, 0.0, 4.0, 0.0, a[:5]), (1, 0.0, 4.0, 3.0, b[:5]), (0, 7.0, 11.0, 0.0, b[5:])])
    r = evaluate_run(run_master(frames, gts, _config("bayes")), with_mot=False)
    assert r["reidentification"]["failure_wrong_person"] == 1 and r["reidentification"]["success"] == 0


def test_real_core_run_reports_the_calibration_of_every_decision(embeddings) -> None:
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]
    # both learned; person 0 returns with his own face (right), person 1 returns showing person 0's (wrong)
    frames, gts = _frames([(0, 0.0, 4.0, 0.0, a[:5]), (1, 0.0, 4.0, 3.0, b[:5]), (0, 7.0, 11.0, 0.0, a[5:]),
                           (1, 14.0, 18.0, 3.0, a[5:])])
    cfg = _config("bayes")
    log = run_master(frames, gts, cfg, confidence_map=ConfidenceMap.identity())  # the raw decision posteriors
    r = evaluate_run(log, with_mot=False)
    cal = r["calibration"]
    outcomes = track_outcomes(log)
    decided = [o for o in outcomes if o.outcome != "none"]
    assert cal["first_decisions"] == len(decided) == 4 and cal["decisions_without_confidence"] == 0
    assert cal["decisions"] == sum(len(log.tracks[o.track_id].assignments) for o in outcomes)
    assert cal["wrong"] == sum(o.outcome == "failure" for o in decided) == r["table_ii"]["failure"] == 1
    # every face decision exceeded the master's threshold, at the posterior the track then published
    face = cal["at_thresholds"]["face"]
    assert face["threshold"] == cfg.posterior_threshold and face["decisions_below_threshold"] == 0
    assert face["decisions"] == cal["by_evidence"]["face"]["decisions"] == 4 and face["wrong"] == 1
    assert 0.95 < cal["mean_confidence"] <= 0.999  # the face table is clamped at 1 - 1e-3
    assert sum(b["count"] for b in cal["bins"]) == 4 and 0.0 <= cal["ece"] <= 1.0
    assert cal["frontier"][0]["recover_rate"] == r["reidentification"]["recover_rate"] == 0.5


def test_real_core_return_without_a_face_is_none_and_names_come_from_the_gallery(embeddings) -> None:
    a, c = embeddings[IDS[0]], embeddings[IDS[2]]
    frames, gts = _frames([(0, 0.0, 4.0, 0.0, a[:5]), (2, 0.0, 4.0, 3.0, c[:5]), (0, 7.0, 11.0, 0.0, None)])
    gallery = {"tony": a[7:]}  # photos the scenario did not show
    log = run_master(frames, gts, _config("bayes"), gallery=gallery)
    r = evaluate_run(log, gallery_people={"tony": 0}, with_mot=False)
    reid = r["reidentification"]
    assert (reid["tracks"], reid["none"], reid["success"]) == (1, 1, 0)
    assert reid["mean_reid_time_s"] is None and reid["recover_rate"] == 0.0
    names = r["predefined_people"]
    assert names["right_name"] == 1 and names["wrong_name"] == 0 and names["no_name"] == 1  # the faceless return
    assert names["other_tracks_named"] == 0


def test_run_master_rejects_bad_input(embeddings) -> None:
    frames, gts = _frames([(0, 0.0, 1.0, 0.0, None)])
    with pytest.raises(ValueError, match="differ in length"):
        run_master(frames, gts[:-1])
    with pytest.raises(ValueError, match="gt ids of shape"):
        run_master(frames, [np.zeros(5, dtype=np.int32)] * len(frames))
    with pytest.raises(ValueError, match="stamp order"):
        run_master(frames[::-1], gts[::-1])
    bad = [CameraFrameRecord("cam_a", float("nan"))]
    with pytest.raises(ValueError, match="finite"):
        run_master(bad, [np.zeros(0, dtype=np.int32)])
    with pytest.raises(ValueError, match="tick_period_s"):
        run_master(frames, gts, tick_period_s=0.0)
    empty = run_master([], [])
    assert evaluate_run(empty)["reidentification"]["tracks"] == 0


# ------------------------------------------------------------------------------------- gallery and CLI
def test_default_gallery_people_is_half_of_day_one_and_deterministic() -> None:
    doc = {"seed": 3, "days": [{"day": 1, "gt_ids": [0, 1, 2, 3, 4]}, {"day": 2, "gt_ids": [0, 5]}]}
    chosen = default_gallery_people(doc)
    assert len(chosen) == 2 and set(chosen) <= {0, 1, 2, 3, 4} and chosen == sorted(chosen)
    assert default_gallery_people(doc) == chosen and default_gallery_people(doc, 0) == []
    with pytest.raises(ValueError, match="within"):
        default_gallery_people(doc, 6)


def test_scenario_gallery_uses_unused_photos_else_one_scenario_photo(tmp_path: Path, embedder) -> None:
    for ident, n in ((IDS[0], 3), (IDS[1], 2)):
        (tmp_path / ident).mkdir()
        for p in sorted((FACES_DIR / ident).glob("*.jpg"))[:n]:
            shutil.copy(p, tmp_path / ident / p.name)
    files = {i: sorted(f.name for f in (tmp_path / i).iterdir()) for i in IDS[:2]}
    doc = {"faces_dir": str(tmp_path),
           "photos": [{"index": 0, "path": f"{IDS[0]}/{files[IDS[0]][0]}"},
                      {"index": 1, "path": f"{IDS[1]}/{files[IDS[1]][0]}"},
                      {"index": 2, "path": f"{IDS[1]}/{files[IDS[1]][1]}"}],
           "identities": [{"gt_id": 0, "name": IDS[0], "photos": {"1": [0]}},
                          {"gt_id": 1, "name": IDS[1], "photos": {"1": [1], "2": [2]}}]}
    info = scenario_gallery(doc, tmp_path, [0, 1], embedder=embedder)
    assert info.photos == {IDS[0]: 2, IDS[1]: 1} and info.from_scenario_photo == [IDS[1]]
    assert info.gt_of_name == {IDS[0]: 0, IDS[1]: 1} and info.people[IDS[0]].shape == (2, 128)
    missing = scenario_gallery({**doc, "faces_dir": str(tmp_path / "nope")}, tmp_path / "x", [0])
    assert missing.skipped and not missing.people


@pytest.fixture(scope="module")
def scenario_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from face_reid_master.sim.scenario_files import write_scenario
    from face_reid_master.sim.simulate import SimConfig, simulate

    faces = copy_fixture_faces(tmp_path_factory.mktemp("faces"), IDS)
    out = tmp_path_factory.mktemp("scenario")
    cfg = SimConfig(num_people=3, num_cameras=2, duration_s=40.0, seed=5, embedder="dlib")
    write_scenario(simulate(faces, cfg), out)
    return out


def test_cli_prints_json_and_saves_plots(scenario_dir: Path, tmp_path: Path, capsys) -> None:
    prefix = tmp_path / "plots" / "run"
    # the shipped face fit saw two of the fixture people: this test is about the output, not the protocol
    assert main([str(scenario_dir), "--method", "threshold", "--plot", str(prefix), "--out",
                 str(tmp_path / "r.json"), "--quiet", "--allow-fitted"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads((tmp_path / "r.json").read_text())
    assert printed["method"] == "threshold" and printed["scenario"]["cameras"] == 2
    assert set(printed["table_ii"]) == {"success", "failure", "failure_after_switch", "re_id_time_s", "recover_rate",
                                        "recover_rate_paper"}
    assert printed["gallery"]["people"] and len(printed["gallery"]["people"]) == 1  # half of 3 day-1 people
    assert printed["predefined_people"]["gallery_people"] == 1
    assert printed["detections"] == printed["scenario"]["detections"] > 0
    assert 0.0 <= printed["mot"]["identity"]["idf1"] <= 1.0
    assert printed["calibration"]["first_decisions"] == sum(
        printed[k][f] for k, f in (("reidentification", "success"), ("reidentification", "failure"),
                                   ("first_appearance", "success"), ("first_appearance", "failure_wrong_person")))
    assert "face" not in printed["calibration"]["at_thresholds"]  # the threshold method votes: no face posterior
    for suffix in ("_timeline.png", "_map.png", "_reliability.png"):
        path = prefix.parent / f"run{suffix}"
        assert path.stat().st_size > 10_000 and path.read_bytes()[:4] == b"\x89PNG"


def test_cli_errors(scenario_dir: Path, tmp_path: Path, capsys) -> None:
    assert main([str(scenario_dir), "--live", "--domain-id", "500", "--quiet"]) == 2
    assert "--domain-id must be in 0..232" in capsys.readouterr().err
    assert main([str(scenario_dir), "--live", "--confidence-map", "raw", "--quiet"]) == 2
    assert "--confidence-map raw is offline only" in capsys.readouterr().err
    assert main([str(scenario_dir), "--confidence-map", str(tmp_path / "none.json"), "--quiet"]) == 2
    assert "--confidence-map" in capsys.readouterr().err
    (tmp_path / "metric.json").write_text("{not json")  # corrupt: a clear error, not a traceback
    assert main([str(scenario_dir), "--body-metric", str(tmp_path / "metric.json"), "--quiet"]) == 2
    assert f"--body-metric: body metric file {tmp_path / 'metric.json'} is unusable" in capsys.readouterr().err
    assert main([str(tmp_path), "--quiet"]) == 2
    assert "no scenario.json" in capsys.readouterr().err
    assert main([str(scenario_dir), "--gallery-people", "9", "--quiet", "--allow-fitted"]) == 2
    assert "--gallery-people" in capsys.readouterr().err
    assert main([str(scenario_dir), "--likelihood", str(tmp_path / "missing.json"), "--quiet"]) == 2
    assert "--likelihood" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{}")
    assert main([str(scenario_dir), "--likelihood", str(tmp_path / "bad.json"), "--quiet"]) == 2
    assert "not a face likelihood model" in capsys.readouterr().err


def test_cli_likelihood_option_uses_that_model(scenario_dir: Path, tmp_path: Path, capsys) -> None:
    """--likelihood replaces the shipped model: a model that calls every pair 'different' creates a new
    face for every decided track (no re-identification), and the JSON says which model ran."""
    path = tmp_path / "strict.json"
    strict = LikelihoodModel(SkewNormal(0.0, 0.05, 0.01), SkewNormal(0.0, 0.9, 0.3), metadata={"data": "strict"})
    save_likelihood_model(strict, path)  # a version-1 file: pooled, no derived thresholds
    assert main([str(scenario_dir), "--likelihood", str(path), "--no-mot", "--quiet"]) == 2  # naming needs one
    assert "name_threshold" in capsys.readouterr().err
    save_face_likelihood(FaceLikelihood(strict, name_threshold=0.45, metadata={"data": "strict"}), path)
    assert main([str(scenario_dir), "--likelihood", str(path), "--no-mot", "--quiet", "--allow-fitted"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["parameters"]["likelihood_data"] == "strict"
    # this model does not say what it saw: not an honest test
    assert printed["protocol"] == {"honest": False, "models": [
        {"model": "face likelihoods and naming distance", "source": str(path), "identities_seen": None},
        {"model": "confidence map", "source": "shipped confidence map", "identities_seen": []}]}
    reid = printed["reidentification"]
    assert reid["success"] == 0 and reid["failure_new_id"] > 0
    assert main([str(scenario_dir), "--no-mot", "--quiet", "--allow-fitted"]) == 0
    shipped = json.loads(capsys.readouterr().out)
    assert shipped["reidentification"]["success"] > 0
    # the shipped fit lists its exclusions (Hugo Chavez is one): the other two fixture people were seen
    face, cmap = shipped["protocol"]["models"]
    assert cmap["model"] == "confidence map" and cmap["identities_seen"] == []
    assert shipped["protocol"]["honest"] is False and face["identities_seen"] == sorted(IDS[:2])


def test_paired_reid_times_compare_the_same_tracks(embeddings) -> None:
    a, b = embeddings[IDS[0]], embeddings[IDS[1]]
    frames, gts = _frames([(0, 0.0, 4.0, 0.0, a[:5]), (1, 0.0, 4.0, 3.0, b[:5]),
                           (0, 7.0, 11.0, 0.0, a[5:]), (1, 7.0, 11.0, 3.0, b[5:])])
    days = [(1, 0.0, 11.0, (0, 1))]
    bayes = run_master(frames, gts, _config("bayes"), days=days)
    threshold = run_master(frames, gts, _config("threshold"), days=days)
    paired = paired_reid_times(bayes, threshold, ("bayes", "threshold"))
    assert paired["tracks_both_successful"] == 2
    assert paired["only_bayes_successful"] == paired["only_threshold_successful"] == 0
    assert paired["bayes_faster"] + paired["threshold_faster"] + paired["same_time"] == 2
    # the paper's baseline needs 5 votes, the Bayesian table 3 observations: never slower here
    assert paired["threshold_faster"] == 0
    assert paired["mean_reid_time_bayes_s"] < paired["mean_reid_time_threshold_s"]
    same = paired_reid_times(bayes, bayes)
    assert same["same_time"] == 2 and same["mean_reid_time_a_s"] == same["mean_reid_time_b_s"]


def test_cli_both_methods_adds_the_paired_comparison(scenario_dir: Path, capsys) -> None:
    assert main([str(scenario_dir), "--method", "both", "--no-mot", "--quiet", "--allow-fitted"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["method"] == "both" and printed["scenario"]["cameras"] == 2
    assert printed["bayes"]["method"] == "bayes" and printed["threshold"]["method"] == "threshold"
    paired = printed["paired"]
    both = paired["tracks_both_successful"]
    assert both + paired["only_bayes_successful"] == printed["bayes"]["reidentification"]["success"]
    assert both + paired["only_threshold_successful"] == printed["threshold"]["reidentification"]["success"]
    assert main([str(scenario_dir), "--method", "both", "--live", "--quiet"]) == 2


def test_names_are_also_judged_per_detection_so_a_swapped_track_was_right_before_the_swap() -> None:
    # one track: person 0 (alice) for 2 frames shown "alice", then swapped onto person 2 (a stranger) still shown
    # "alice" for 3 frames; person 1 (bob) on another track shown "carol" (not in the gallery) once, then nothing
    t1 = _track(1, 2, 0.0, 5.0, names={"alice": 0.0}, n_det=5)
    t1.gt_counts = {0: 2, 2: 3}
    t2 = _track(2, 1, 0.0, 5.0, names={"carol": 0.0}, n_det=2)
    z = np.zeros(7)
    log = RunLog("bayes", {1: t1, 2: t2}, {}, np.arange(7), z, [0, 0, 2, 2, 2, 1, 1], [1, 1, 1, 1, 1, 2, 2], z,
                 days=((1, 0.0, 100.0, (0, 1, 2)),), det_name=[0, 0, 0, 0, 0, 1, -1], names=("alice", "carol"))
    names = evaluate_run(log, gallery_people={"alice": 0, "bob": 1}, with_mot=False)["predefined_people"]
    assert names["other_tracks_named"] == 1  # per track: the stranger's track was named
    det = names["detections"]
    assert (det["gallery_detections"], det["right_name"], det["wrong_name"]) == (4, 2, 1)
    assert (det["other_detections"], det["other_named"]) == (3, 3)
    assert names["pure_tracks"]["gallery_tracks"] == 1 and names["pure_tracks"]["wrong_name"] == 1  # bob's track
    with pytest.raises(ValueError, match="det_name"):
        RunLog("bayes", {}, {}, [0], [0.0], [0], [1], [0], det_name=[3], names=("alice",))
