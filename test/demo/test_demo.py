"""face-reid-demo without DDS: the scripted scenario, the player's spec and rendering, the summary metrics,
the table, and the process clean-up (process groups, death with the parent)."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import FACES_DIR, REPO_ROOT

from face_reid_master.demo import report, run
from face_reid_master.demo import scenario as demo_scenario
from face_reid_master.demo.children import start_child, stop_children
from face_reid_master.evaluation.published_tracks import TrackMessage
from face_reid_master.records import STATE_CONFIRMED, NamedTrackRecord
from face_reid_master.sim.motion import sample_trajectories
from face_reid_master.sim.rgbd_player import PlayerSpec, ScenePlayer
from face_reid_master.sim.visibility import camera_visibility


@pytest.fixture(scope="module")
def scenario() -> demo_scenario.DemoScenario:
    return demo_scenario.build_scenario(FACES_DIR, demo_scenario.DEFAULT_SEED)


def test_display_names() -> None:
    assert demo_scenario.display_name("lfw_Colin_Powell") == "Colin Powell"
    assert demo_scenario.display_name("facerec_obama") == "Obama"
    assert demo_scenario.display_name("deepface_id01") == "Id01"
    assert demo_scenario.display_name("Alice") == "Alice"


def test_default_scenario_is_the_advertised_one(scenario: demo_scenario.DemoScenario) -> None:
    assert scenario.seed == demo_scenario.DEFAULT_SEED, "the default seed must pass the script checks by itself"
    assert [p.identity for p in scenario.people] == list(demo_scenario.DEFAULT_IDENTITIES[:4])
    assert [p.in_gallery for p in scenario.people] == [True, True, False, False]
    assert len(scenario.cameras) == 2 and len(scenario.world.doors) == 4
    t = np.arange(0.0, scenario.duration_s, 0.1)
    xy, inside = scenario.true_xy(t)
    _, face = scenario.visibility(t)
    for p, person in enumerate(scenario.people):
        # gallery photos are never shown in the scene
        assert not set(person.gallery_photos) & set(person.scene_photos)
        assert bool(person.gallery_photos) == person.in_gallery
        # leaves once, comes back >= 12 s before the end, and shows a face in both visits
        assert len(person.visits) == 2
        (enter1, leave1), (enter2, _) = person.visits
        assert enter1 < leave1 < enter2 <= scenario.duration_s - 12.0
        out = (t > leave1 + 0.5) & (t < enter2 - 0.5)
        assert out.any() and not inside[out, p].any(), "outside between the visits"
        for a, b in person.visits:
            span = (t >= a) & (t < b)
            assert face[span, p].sum() >= 20, f"{person.name} shows no face for 2 s in visit {a}-{b}"
    # nobody walks through anybody
    for a in range(len(scenario.people)):
        for b in range(a + 1, len(scenario.people)):
            both = inside[:, a] & inside[:, b]
            assert np.linalg.norm(xy[both, a] - xy[both, b], axis=1).min() >= 0.6


def test_build_scenario_is_deterministic_and_validates(scenario: demo_scenario.DemoScenario) -> None:
    again = demo_scenario.build_scenario(FACES_DIR, demo_scenario.DEFAULT_SEED)
    for p, q in zip(scenario.people, again.people, strict=True):
        np.testing.assert_array_equal(p.trajectory.xy, q.trajectory.xy)
        assert p.photo_spans == q.photo_spans
    with pytest.raises(ValueError, match="num_people"):
        demo_scenario.build_scenario(FACES_DIR, 0, num_people=0)
    with pytest.raises(ValueError, match="a 5 s scenario is too short for 4 people"):
        demo_scenario.build_scenario(FACES_DIR, 0, duration_s=5.0)
    with pytest.raises(ValueError, match="gallery_people"):
        demo_scenario.build_scenario(FACES_DIR, 0, num_people=2, gallery_people=3)


def test_choose_identities_needs_enough_photos(tmp_path: Path) -> None:
    for ident in ("lfw_Colin_Powell", "lfw_Tony_Blair"):
        (tmp_path / ident).mkdir()
        for f in sorted((FACES_DIR / ident).glob("*.jpg"))[:4]:
            shutil.copy(f, tmp_path / ident / f.name)
    (tmp_path / "too_few").mkdir()
    shutil.copy(sorted((FACES_DIR / "lfw_Ariel_Sharon").glob("*.jpg"))[0], tmp_path / "too_few" / "a.jpg")
    cast = demo_scenario.choose_identities(tmp_path, 2)
    assert [name for name, _ in cast] == ["lfw_Colin_Powell", "lfw_Tony_Blair"]  # built-in cast first
    with pytest.raises(ValueError, match="has 2 identities with >= 4 photos"):
        demo_scenario.choose_identities(tmp_path, 3)


def test_player_spec_round_trip_and_rendering(scenario: demo_scenario.DemoScenario, tmp_path: Path) -> None:
    spec = scenario.player_spec(0, 5.0)
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec.to_json()))
    back = PlayerSpec.load(path)
    assert back.camera_id == "camera1" and back.xyz_rpy == spec.xyz_rpy and back.rate_hz == 5.0
    for a, b in zip(spec.people, back.people, strict=True):
        np.testing.assert_allclose(a.trajectory.xy, b.trajectory.xy)
        assert a.photos == b.photos
        assert a.clothes is not None and a.clothes == b.clothes
    doc = spec.to_json()
    del doc["people"][0]["t_s"]
    with pytest.raises(ValueError, match="malformed player spec"):
        PlayerSpec.from_json(doc)
    with pytest.raises(ValueError, match="not a player spec"):
        PlayerSpec.from_json({"format": "other"})
    # the player renders what the scenario says camera 1 sees: a face exactly when the person faces it
    player = ScenePlayer(back)
    t = np.arange(1.0, 12.0, 0.5)
    _, face = scenario.visibility(t)
    shown = np.zeros_like(face)
    for i, ts in enumerate(t):
        frame, xy, inside, face_visible = player.render(float(ts), i)
        assert frame.rgb_bgr.shape == (480, 640, 3) and frame.depth_mm.dtype == np.uint16
        true_xy, true_in = scenario.true_xy(np.array([ts]))
        np.testing.assert_allclose(xy, true_xy[0])
        np.testing.assert_array_equal(inside, true_in[0])
        shown[i] = face_visible
    cam1 = scenario.cameras[0]
    xy, facing = sample_trajectories([p.trajectory for p in scenario.people], t)
    heights = np.array([p.trajectory.height_m for p in scenario.people])
    vis = camera_visibility(cam1, xy, facing, heights, scenario.world.room.contains(xy))
    assert shown.any()
    # the analytic model and the renderer agree on most frames (they differ at the edges of the angle limits)
    assert (shown == vis.face_visible).mean() > 0.8


def test_people_wear_textured_clothes(scenario: demo_scenario.DemoScenario) -> None:
    """Bodies are in the demo: everybody wears made-up clothes of their own (no two alike), drawn as a texture by
    each camera's player, the same texture in every camera."""
    outfits = [p.clothes for p in scenario.people]
    assert len(set(outfits)) == len(outfits) and outfits == list(demo_scenario.OUTFITS[:len(outfits)])
    specs = [scenario.player_spec(c, 5.0) for c in range(len(scenario.cameras))]
    players = [ScenePlayer(spec) for spec in specs]
    for p in range(len(scenario.people)):
        np.testing.assert_array_equal(players[0].textures[p], players[1].textures[p])
    flat = [ScenePlayer(dataclasses.replace(spec, people=tuple(dataclasses.replace(q, clothes=None)
                                                                 for q in spec.people))) for spec in specs]
    striped = next(p for p, person in enumerate(scenario.people) if person.clothes[2])
    plain = next(p for p, person in enumerate(scenario.people) if not person.clothes[2])
    # near-white grey pixels (the stripes are (235, 235, 235)) a person shows, with their clothes and without
    white = {(p, dressed): 0 for p in (striped, plain) for dressed in (True, False)}
    seen = {striped: 0, plain: 0}
    for dressed, plain_player in zip(players, flat, strict=True):
        for k, t in enumerate(np.arange(1.0, 40.0, 2.0)):
            for is_dressed, player in ((True, dressed), (False, plain_player)):
                frame, _, inside, _ = player.render(float(t), k)
                drawn = list(np.flatnonzero(inside))  # person_ids index the people drawn (those in the room)
                for p in seen:
                    if p not in drawn:
                        continue
                    pixels = frame.rgb_bgr[frame.person_ids == drawn.index(p)].astype(int)
                    seen[p] += pixels.shape[0] if is_dressed else 0
                    grey = pixels.max(axis=1) - pixels.min(axis=1) < 25
                    white[p, is_dressed] += int(np.count_nonzero(grey & (pixels.min(axis=1) > 170)))
    assert min(seen.values()) > 5000  # both were seen
    assert white[striped, True] - white[striped, False] > 0.05 * seen[striped], (white, seen)
    assert abs(white[plain, True] - white[plain, False]) < 0.01 * seen[plain], (white, seen)


def _perfect_messages(scenario: demo_scenario.DemoScenario, *, return_face_offset: int = 0, name_for: dict[int, str]
                      | None = None) -> list[TrackMessage]:
    """What an ideal master publishes: one track per visit at the true position, the person's face id on it
    (+ ``return_face_offset`` on the return visit: a new face id), gallery people named."""
    messages = []
    for t in np.arange(0.0, scenario.duration_s, 0.2):
        xy, inside = scenario.true_xy(np.array([t]))
        tracks = []
        for p, person in enumerate(scenario.people):
            if not inside[0, p]:
                continue
            visit = 0 if t < person.visits[0][1] + 0.5 else 1
            first_seen = max(0.0, person.visits[visit][0])
            face = p + 1 + (return_face_offset if visit else 0)
            decided = t - first_seen > 1.0
            name = (name_for or {}).get(p, person.name if person.in_gallery else "")
            tracks.append(NamedTrackRecord(
                10 * (p + 1) + visit, face if decided else 0, name if decided else "", 0.99 if decided else 0.3,
                5, xy[0, p] + 0.05, np.zeros(2), np.eye(4), 1.75, STATE_CONFIRMED, first_seen, t, ("camera1",)))
        messages.append(TrackMessage(float(t), tuple(tracks)))
    return messages


def test_summary_of_a_perfect_run(scenario: demo_scenario.DemoScenario) -> None:
    summary = report.summarize(scenario, _perfect_messages(scenario))
    assert summary["reidentification"]["success"] == 4 and summary["reidentification"]["failure"] == 0
    assert summary["false_tracks"] == 0
    assert summary["median_position_error_m"] == pytest.approx(0.0707, abs=0.01)
    for person in summary["people"]:
        assert person["tracks"] == 2 and person["reid_correct"] == 1 and person["reid_wrong"] == 0
        assert person["mean_reid_time_s"] == pytest.approx(1.1, abs=0.15)
        if person["in_gallery"]:
            assert (person["names_right"], person["names_wrong"], person["names_none"]) == (2, 0, 0)
        else:
            assert (person["names_right"], person["names_wrong"], person["names_none"]) == (0, 0, 2)
    text = report.format_summary(summary)
    assert "Colin Powell (gallery)" in text and "4 correct, 0 wrong, 0 pending" in text


def test_summary_counts_new_ids_and_wrong_names(scenario: demo_scenario.DemoScenario) -> None:
    summary = report.summarize(scenario, _perfect_messages(scenario, return_face_offset=10,
                                                         name_for={2: "Colin Powell"}))
    assert summary["reidentification"]["success"] == 0
    assert summary["reidentification"]["failure_new_id"] == 4
    putin = next(p for p in summary["people"] if p["name"] == "Vladimir Putin")
    assert putin["reid_wrong"] == 1 and putin["names_wrong"] == 2  # not in the gallery, yet named
    assert summary["predefined_people"]["other_tracks_named"] == 2


def test_summary_without_messages(scenario: demo_scenario.DemoScenario) -> None:
    summary = report.summarize(scenario, [])
    assert summary["messages"] == 0 and all(p["tracks"] == 0 for p in summary["people"])
    assert summary["median_position_error_m"] is None


def test_table_rows(scenario: demo_scenario.DemoScenario) -> None:
    msgs = _perfect_messages(scenario)
    msg = msgs[100]  # t = 20 s
    table = report.format_table(scenario, msg, 20.0)
    lines = table.splitlines()
    assert lines[1].split()[:3] == ["track", "who", "conf"]
    assert len(lines) == 2 + len(msg.tracks)
    for tr in msg.tracks:
        row = next(line for line in lines[2:] if line.split()[0] == str(tr.track_id))
        truth = scenario.people[tr.track_id // 10 - 1].name
        assert row.endswith(truth)
    compact = report.format_table(scenario, msg, 20.0, compact=True)
    assert "\n" not in compact and f"{len(msg.tracks)} tracks" in compact
    assert "no /tracks_named message yet" in report.format_table(scenario, None, 1.0)


_IGNORES_SIGINT = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); print('up', flush=True); " \
                  "time.sleep(60)"


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return True
    return "\nState:\tZ" in state


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process groups and PDEATHSIG: Linux")
def test_stop_all_kills_stubborn_process_groups(tmp_path: Path) -> None:
    env = dict(os.environ)
    polite = start_child("polite", ["-c", "import time; time.sleep(60)"], env, tmp_path)
    stubborn = start_child("stubborn", ["-c", _IGNORES_SIGINT], env, tmp_path)
    time.sleep(0.5)
    t0 = time.monotonic()
    stop_children([polite, stubborn], timeout_s=1.0)
    assert time.monotonic() - t0 < 5.0
    assert polite.proc.returncode is not None and stubborn.proc.returncode == -signal.SIGKILL
    assert polite.proc.pid != os.getpgid(0)  # each child had its own process group


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")
def test_children_die_with_the_demo(tmp_path: Path) -> None:
    script = (
        "import os, sys; from pathlib import Path; from face_reid_master.demo.children import start_child; "
        f"c = start_child('orphan', ['-c', {_IGNORES_SIGINT!r}], dict(os.environ), Path({str(tmp_path)!r})); "
        "print(c.proc.pid, flush=True); os._exit(0)"
    )
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=30)
    pid = int(out.stdout.split()[0])
    deadline = time.monotonic() + 5.0
    while not _gone(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _gone(pid), "the demo's child outlived the demo"


def test_cli_rejects_bad_arguments(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert run.main(["--rate-hz", "0"]) == 2
    assert "--rate-hz" in capsys.readouterr().err
    assert run.main(["--faces", str(tmp_path / "missing")]) == 2
    assert "no face photos" in capsys.readouterr().err
    assert run.main(["--people", "9"]) == 2
    assert "num_people" in capsys.readouterr().err


@pytest.mark.parametrize(("args", "message"), [
    # before: 'no usable demo scenario ... give them more time (longer duration) or take fewer people'
    (["--people", "1", "--duration-s", "20"], "a 20 s scenario is too short for 1 person: at least 25 s for 1, 35 s "
     "for 2-4, 40 s for 5, 45 s for 6 people, at most 600 s"),
    # before: the documented range said 20 s, the check refused up to ~35 s after a search
    (["--people", "4", "--duration-s", "30"], "a 30 s scenario is too short for 4 people: at least 25 s for 1, "),
    (["--people", "5", "--cameras", "1"], "one camera's room takes at most 4 people, got 5: use 2 or more cameras"),
])
def test_the_demo_states_its_minimum_duration_and_refuses_below_it(capsys: pytest.CaptureFixture[str],
                                                                    args: list[str], message: str) -> None:
    assert run.main(args) == 2
    assert capsys.readouterr().err.startswith(f"face-reid-demo: {message}")


def test_the_documented_minimum_durations_give_a_scenario() -> None:
    """The minimum the help states is one the planner meets (the default seed, two cameras)."""
    for people in (1, 4, 6):
        scenario = demo_scenario.build_scenario(FACES_DIR, demo_scenario.DEFAULT_SEED, 2, people, min(2, people),
                                                demo_scenario.min_duration_s(people))
        assert len(scenario.people) == people
    help_text = run._parser().format_help()
    assert "at least 25 s for 1, 35 s for 2-4, 40 s for 5, 45 s for 6 people" in " ".join(help_text.split())


def test_demo_faces_dir_lookup(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from face_reid_camera.common.resources import demo_faces_dir

    monkeypatch.delenv("FACE_REID_DEMO_FACES_DIR", raising=False)
    assert demo_faces_dir() == FACES_DIR.resolve()  # a source checkout: the test fixtures
    monkeypatch.setenv("FACE_REID_DEMO_FACES_DIR", str(tmp_path))
    assert demo_faces_dir() == tmp_path


def test_the_domain_of_a_run_honours_the_environment_and_any_valid_id() -> None:
    from face_reid_master.demo.children import domain_id_for_run

    assert domain_id_for_run(7, {"ROS_DOMAIN_ID": "150"}) == 7  # --domain-id wins
    assert domain_id_for_run(None, {"ROS_DOMAIN_ID": "150"}) == 150  # above 101 is fine
    assert domain_id_for_run(None, {"ROS_DOMAIN_ID": "0"}) == 0
    assert 1 <= domain_id_for_run(None, {}) <= 100 and 1 <= domain_id_for_run(None, {"ROS_DOMAIN_ID": " "}) <= 100
    with pytest.raises(ValueError, match=r"0\.\.232"):
        domain_id_for_run(233, {})
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID must be an integer"):
        domain_id_for_run(None, {"ROS_DOMAIN_ID": "kitchen"})


def test_a_bad_domain_is_refused_before_anything_starts(capsys: pytest.CaptureFixture[str]) -> None:
    from face_reid_master.demo.run import main

    assert main(["--domain-id", "300"]) == 2
    assert "0..232" in capsys.readouterr().err


def test_a_lost_track_is_shown_inside_the_room(scenario: demo_scenario.DemoScenario) -> None:
    """A lost track's prediction drifts on (here 40 m away): the table shows it at the room's edge."""
    from face_reid_master.records import STATE_LOST

    msg = _perfect_messages(scenario)[100]
    far = dataclasses.replace(msg.tracks[0], state=STATE_LOST, position_xy=np.array([40.0, -40.0]))
    table = report.format_table(scenario, TrackMessage(msg.stamp_s, (far,)), 20.0)
    half = scenario.world.room.half_extents
    row = table.splitlines()[2]
    assert " lost " in row and f" {half[0]:.2f} " in row and f" {-half[1]:.2f} " in row and "40.00" not in row


def test_an_undecided_track_shows_no_confidence(scenario: demo_scenario.DemoScenario) -> None:
    """Face id 0 claims nobody: "?" with no number (not "? (1.00)"), whatever confidence came with it."""
    msg = _perfect_messages(scenario)[100]
    decided = dataclasses.replace(msg.tracks[0], identity_confidence=0.94)
    undecided = dataclasses.replace(msg.tracks[0], track_id=99, face_id=0, name="", identity_confidence=1.0)
    shown = TrackMessage(msg.stamp_s, (decided, undecided))
    rows = {line.split()[0]: line for line in report.format_table(scenario, shown, 20.0).splitlines()[2:]}
    assert rows["99"].split()[1:3] == ["?", "-"] and "1.00" not in rows["99"]
    assert " 0.94 " in rows[str(decided.track_id)]
    compact = report.format_table(scenario, shown, 20.0, compact=True)
    assert "#99 ? (undecided) at" in compact and "1.00" not in compact
    assert "(0.94) at" in compact


def test_node_parameters_pass_through_and_bad_ones_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    from face_reid_master.demo.run import _parser

    args = _parser().parse_args(["--camera-param", "floor_map_period_s:=2", "--camera-param",
                                 "person.voxel_size_m:=0.05", "--master-param", "publish_people:=true"])
    assert args.camera_param == ["floor_map_period_s:=2", "person.voxel_size_m:=0.05"]
    assert args.master_param == ["publish_people:=true"]
    for bad in ("floor_map_period_s=2", ":=2", "a b:=1"):
        with pytest.raises(SystemExit):
            _parser().parse_args(["--camera-param", bad])
        assert "expected NAME:=VALUE" in capsys.readouterr().err


def test_node_parameters_the_nodes_would_refuse_stop_the_demo_before_it_starts(
        capsys: pytest.CaptureFixture[str]) -> None:
    """Checked by the nodes' own loader (before: the camera nodes failed at start, the demo with them)."""
    assert run.main(["--camera-param", "floor_map_period_s:=2", "--master-param", "publish_peeple:=true"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "face-reid-demo: warning: --master-param: publish_peeple:=true: 'publish_peeple' is not a parameter of "
        "face_reid_master: ignored (did you mean 'publish_people'?)",
        "face-reid-demo: --camera-param: floor_map_period_s:=2: parameter 'floor_map_period_s' must be a float like "
        "0.0, got 2 (write numbers with a decimal point, e.g. 2.0)"]
