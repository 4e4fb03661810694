"""Tests of the scenario simulator on the project's licensed face fixtures, with the real models.

Feature level (3 people, 2 cameras, 20 s), a second day, a tiny pixel-level run through the real camera
pipeline, determinism, the directory format and bad faces folders."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import copy_fixture_faces

from face_reid_master.core.config import MasterConfig
from face_reid_master.records import CameraFrameRecord, PersonRecord
from face_reid_master.sim.cli import main
from face_reid_master.sim.photos import NUM_FRAME_CHANGES, NUM_VARIANTS, InsufficientFacesError, PhotoBank
from face_reid_master.sim.scenario_files import ScenarioFormatError, load_scenario, write_scenario
from face_reid_master.sim.simulate import SimConfig, simulate

# identities with >= 4 photos, copied into a small faces folder so the tests embed few photos
IDENTITIES = ("lfw_Colin_Powell", "lfw_Tony_Blair", "deepface_id02", "deepface_id03", "facerec_obama")
PHOTOS_PER_IDENTITY = 4


@pytest.fixture(scope="module")
def faces(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return copy_fixture_faces(tmp_path_factory.mktemp("faces"), IDENTITIES, PHOTOS_PER_IDENTITY)


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cache") / "embeddings.npz"


@pytest.fixture(scope="module")
def feature_dir(faces: Path, cache: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    cfg = SimConfig(num_people=3, num_cameras=2, duration_s=20.0, seed=3, second_day=True, new_people=1,
                    embedder="dlib")
    out = tmp_path_factory.mktemp("scenario")
    write_scenario(simulate(faces, cfg, cache_path=cache), out)
    return out


def _true_xy(scenario, gt_id: int, stamp: float) -> np.ndarray:
    g = scenario.ground_truth
    day = g.day[int(np.argmin(np.abs(g.t_s - stamp)))]
    sel = g.day == day
    return np.array([np.interp(stamp, g.t_s[sel], g.xy[gt_id, sel, k]) for k in range(2)])


def test_feature_level_scenario_matches_its_ground_truth(feature_dir: Path, faces: Path, cache: Path) -> None:
    s = load_scenario(feature_dir)
    doc = s.document
    assert doc["level"] == "feature" and doc["seed"] == 3
    assert [c.camera_id for c in s.cameras] == ["camera1", "camera2"]
    assert len(s.frames) == doc["summary"]["frames"] == 2 * 2 * 20 * 15  # 2 days, 2 cameras, 20 s, 15 Hz
    stamps = np.array([f.stamp_s for f in s.frames])
    assert np.all(np.diff(stamps) >= 0)
    assert all(isinstance(f, CameraFrameRecord) and all(isinstance(p, PersonRecord) for p in f.people)
               for f in s.frames)
    assert len(s.frame_gt_ids) == len(s.frames)
    n_det = sum(len(f.people) for f in s.frames)
    assert n_det == doc["summary"]["detections"] > 100
    # positions: noisy measurements of the true positions
    errors = []
    for f, gts in zip(s.frames, s.frame_gt_ids, strict=True):
        assert len(gts) == len(f.people)
        for p, gt in zip(f.people, gts, strict=True):
            assert p.position_world.shape == (3,) and 0.03 < p.position_std_m < 0.15
            if gt >= 0:
                errors.append(np.linalg.norm(p.position_world[:2] - _true_xy(s, int(gt), f.stamp_s)))
    errors_a = np.array(errors)
    assert np.median(errors_a) < 0.15 and errors_a.max() < 0.6
    # faces: real embeddings, nearest to a photo of the right identity
    bank = PhotoBank(faces, cache)
    photos = {p["index"]: p for p in doc["photos"]}
    base = {}
    for ident in doc["identities"]:
        loaded = bank.load_identity(ident["name"])
        assert loaded is not None
        for ph in loaded.photos:
            index = next(i for i, p in photos.items() if p["path"] == ph.rel_path)
            base[index] = (ident["gt_id"], ph.embeddings[0])
    keys = sorted(base)
    matrix = np.array([base[k][1] for k in keys])
    owners = np.array([base[k][0] for k in keys])
    right, total = 0, 0
    for f, gts, photo_ids in zip(s.frames, s.frame_gt_ids, s.frame_face_photos, strict=True):
        for p, gt, ph in zip(f.people, gts, photo_ids, strict=True):
            if p.embedding is None:
                assert ph == -1 and p.face_score == 0.0
                continue
            assert p.embedding.shape == (128,) and p.embedding.dtype == np.float32
            assert 0.6 <= p.face_score <= 1.0 and 0.0 <= p.face_quality <= 1.0
            assert photos[int(ph)]["identity"] == doc["identities"][int(gt)]["name"]
            total += 1
            right += int(owners[np.argmin(np.linalg.norm(matrix - p.embedding, axis=1))] == gt)
    assert total >= 20
    assert right / total > 0.8


def test_glances_reuse_one_photo_and_days_use_their_own_photos(feature_dir: Path) -> None:
    s = load_scenario(feature_dir)
    with np.load(feature_dir / "frames.npz") as a:
        offsets, cams, stamps = a["frame_offsets"], a["frame_camera"], a["frame_stamp_s"]
        det_face, det_gt = a["det_face"], a["det_gt_id"]
        f_photo, f_glance, f_variant = a["face_photo"], a["face_glance"], a["face_variant"]
    frame_of_det = np.repeat(np.arange(stamps.size), np.diff(offsets))
    has = det_face >= 0
    glance = f_glance[det_face[has]]
    photo = f_photo[det_face[has]]
    gt = det_gt[has]
    cam = cams[frame_of_det[has]]
    t = stamps[frame_of_det[has]]
    assert np.all(glance >= 0) and np.all((f_variant >= 0) & (f_variant < NUM_FRAME_CHANGES))
    multi = 0
    for g in np.unique(glance):
        sel = glance == g
        assert len(set(photo[sel])) == 1, "a glance switched photos"
        assert len(set(f_variant[det_face[has]][sel])) == 1, "a glance switched its image change"
        assert len(set(gt[sel])) == 1 and len(set(cam[sel])) == 1
        multi += int(sel.sum() > 1)
        if sel.sum() > 1:  # consecutive frames of one camera, and not all the same embedding
            assert np.diff(np.sort(t[sel])).max() < 1.0
    assert multi >= 3
    # frames within one glance differ a little (variants + noise), less than other people's faces do
    emb = {}
    with np.load(feature_dir / "frames.npz") as a:
        e = a["face_embedding"]
    for g in np.unique(glance):
        rows = det_face[has][glance == g]
        if rows.size > 2:
            emb[int(g)] = e[rows]
    within = np.median([np.median(np.linalg.norm(v - v.mean(0), axis=1)) for v in emb.values()])
    assert 0.02 < within < 0.35
    # photos per day: day-2 faces come from day-2 photos, never from day-1 ones
    doc = s.document
    day2_start = doc["days"][1]["start_s"]
    for ident in doc["identities"]:
        used = {d: set(photo[(gt == ident["gt_id"]) & ((t >= day2_start) == (d == 2))].tolist()) for d in (1, 2)}
        for d in ident["days"]:
            assert used[d] <= set(ident["photos"][str(d)])
        if ident["days"] == [1, 2]:
            assert not set(ident["photos"]["1"]) & set(ident["photos"]["2"])


def test_second_day_brings_back_some_people_and_new_ones(feature_dir: Path) -> None:
    s = load_scenario(feature_dir)
    days = s.days
    assert [d["day"] for d in days] == [1, 2]
    assert days[1]["start_s"] == pytest.approx(20.0 + SimConfig.day_gap_s)  # overnight
    assert SimConfig.day_gap_s > MasterConfig.body_window_s  # day-1 clothes do not count on day 2
    assert days[0]["gt_ids"] == [0, 1, 2]
    back = [g for g in days[1]["gt_ids"] if g in days[0]["gt_ids"]]
    assert len(back) == 2 and days[1]["gt_ids"][-1] == 3 and len(s.identities) == 4
    g = s.ground_truth
    assert g.xy.shape == (4, g.t_s.size, 2) and g.in_view.shape == (4, g.t_s.size, 2)
    assert np.isnan(g.xy[3, g.day == 1]).all() and np.isfinite(g.xy[3, g.day == 2]).all()
    day2 = days[1]["start_s"]
    gts_day2 = {int(x) for f, gts in zip(s.frames, s.frame_gt_ids, strict=True) if f.stamp_s >= day2 for x in gts}
    assert 3 in gts_day2 and not gts_day2 - set(days[1]["gt_ids"]) - {-1}
    summary = s.summary
    assert summary["losses"] == sum(d["losses"] for d in summary["per_day"])


def test_same_seed_gives_identical_files_other_seed_differs(faces: Path, cache: Path, tmp_path: Path) -> None:
    cfg = SimConfig(num_people=3, num_cameras=2, duration_s=10.0, seed=11, embedder="dlib")
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    write_scenario(simulate(faces, cfg, cache_path=cache), a)
    write_scenario(simulate(faces, cfg, cache_path=cache), b)
    write_scenario(simulate(faces, SimConfig(num_people=3, num_cameras=2, duration_s=10.0, seed=12, embedder="dlib"),
                            cache_path=cache), c)
    for name in ("frames.npz", "ground_truth.npz", "scenario.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "frames.npz").read_bytes() != (c / "frames.npz").read_bytes()


def test_pixel_level_runs_the_real_camera_pipeline(faces: Path, cache: Path, tmp_path: Path) -> None:
    # 2 people, 1 camera, 2 s at 2 Hz; with this seed both people are in view most of the time
    cfg = SimConfig(num_people=2, num_cameras=1, duration_s=2.0, rate_hz=2.0, seed=13, level="pixel",
                    room_size_m=(7.0, 5.0), embedder="dlib")
    write_scenario(simulate(faces, cfg, cache_path=cache), tmp_path / "px")
    s = load_scenario(tmp_path / "px")
    assert s.level == "pixel" and len(s.frames) == 4
    g = s.ground_truth
    expected, found, faces_found = 0, 0, 0
    for f, gts, photos in zip(s.frames, s.frame_gt_ids, s.frame_face_photos, strict=True):
        k = int(np.argmin(np.abs(g.t_s - f.stamp_s)))
        in_view = set(np.flatnonzero(g.in_view[:, k, 0]).tolist())
        expected += len(in_view)
        for p, gt, ph in zip(f.people, gts, photos, strict=True):
            if gt < 0:
                continue
            found += int(gt) in in_view
            assert np.linalg.norm(p.position_world[:2] - _true_xy(s, int(gt), f.stamp_s)) < 0.3
            if p.embedding is not None and ph >= 0:
                faces_found += 1
                assert s.document["photos"][int(ph)]["identity"] == s.identities[int(gt)]["name"]
    assert expected >= 6
    assert found >= 0.75 * expected  # the real depth detector finds the people the world model says are in view
    assert faces_found >= 1
    with np.load(tmp_path / "px" / "frames.npz") as a:
        assert (a["face_variant"] == -1).all()


@pytest.mark.slow
def test_cli_reports_skipped_photos_and_rejects_unusable_folders(
    faces: Path, cache: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad"
    for ident in IDENTITIES[:3]:
        shutil.copytree(faces / ident, bad / ident)
    (bad / IDENTITIES[0] / "corrupt.jpg").write_bytes(b"not a jpeg at all")
    cv2.imwrite(str(bad / IDENTITIES[1] / "wall.jpg"), np.full((120, 120, 3), 128, np.uint8))
    (bad / IDENTITIES[1] / "notes.txt").write_text("ignored")
    out = tmp_path / "out"
    code = main(["--faces", str(bad), "--people", "3", "--cameras", "1", "--duration", "5", "--seed", "2",
                 "--out", str(out), "--cache", str(cache)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "skipped 1 unreadable files and 1 photos without a detectable face" in captured.err
    summary = json.loads(captured.out)
    assert summary["skipped_unreadable"] == 1 and summary["skipped_no_face"] == 1
    doc = json.loads((out / "scenario.json").read_text())
    assert doc["summary"]["skipped_unreadable"] == [f"{IDENTITIES[0]}/corrupt.jpg"]
    assert doc["summary"]["skipped_no_face"] == [f"{IDENTITIES[1]}/wall.jpg"]
    assert load_scenario(out).summary["frames"] == 5 * 15
    # more people than identity folders: refused before anything is embedded
    code = main(["--faces", str(bad), "--people", "4", "--out", str(tmp_path / "o2"), "--cache", str(cache)])
    assert code == 2
    assert f"faces folder {bad} has 3 identity folders with photos, the scenario needs 4" in capsys.readouterr().err
    # enough folders, but one has too few photos: more people than usable identities
    (bad / IDENTITIES[3]).mkdir()
    shutil.copy(next((faces / IDENTITIES[3]).iterdir()), bad / IDENTITIES[3])
    code = main(["--faces", str(bad), "--people", "4", "--out", str(tmp_path / "o2"), "--cache", str(cache)])
    assert code == 2
    assert "only 3 usable identities" in capsys.readouterr().err
    # an empty folder, and one that does not exist
    (tmp_path / "empty").mkdir()
    assert main(["--faces", str(tmp_path / "empty"), "--out", str(tmp_path / "o3")]) == 2
    assert "has no photos" in capsys.readouterr().err
    assert main(["--faces", str(tmp_path / "nope"), "--out", str(tmp_path / "o4")]) == 2
    assert "does not exist" in capsys.readouterr().err
    # bad arguments
    assert main(["--faces", str(bad), "--people", "0", "--out", str(tmp_path / "o5")]) == 2
    assert "num_people" in capsys.readouterr().err
    with pytest.raises(InsufficientFacesError):
        simulate(tmp_path / "empty", SimConfig())


def test_too_few_identity_folders_fail_before_any_photo_is_embedded(faces: Path, tmp_path: Path) -> None:
    few = tmp_path / "few"
    for ident in IDENTITIES[:2]:
        shutil.copytree(faces / ident, few / ident)
    bank = PhotoBank(few, embedder="dlib")
    with pytest.raises(InsufficientFacesError, match="has 2 identity folders with photos, the scenario needs 3"):
        bank.choose(3, np.random.default_rng(0))
    assert bank.embedded_now == 0


def test_load_scenario_rejects_broken_directories(feature_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(ScenarioFormatError, match=r"no scenario\.json"):
        load_scenario(tmp_path)
    broken = tmp_path / "broken"
    shutil.copytree(feature_dir, broken)
    (broken / "frames.npz").write_bytes((feature_dir / "frames.npz").read_bytes()[:1000])
    with pytest.raises(ScenarioFormatError, match=r"frames\.npz"):
        load_scenario(broken)
    shutil.copy(feature_dir / "frames.npz", broken / "frames.npz")
    doc = json.loads((broken / "scenario.json").read_text())
    doc["version"] = 99
    (broken / "scenario.json").write_text(json.dumps(doc))
    with pytest.raises(ScenarioFormatError, match="version"):
        load_scenario(broken)
    doc["version"] = 1
    doc["cameras"] = doc["cameras"][:1]  # frames refer to camera index 1
    (broken / "scenario.json").write_text(json.dumps(doc))
    with pytest.raises(ScenarioFormatError, match="frame_camera"):
        load_scenario(broken)


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="level"):
        SimConfig(level="voxel")
    with pytest.raises(ValueError, match="duration_s"):
        SimConfig(duration_s=0.0)
    with pytest.raises(ValueError, match="new_people"):
        SimConfig(num_people=3, new_people=4)
    with pytest.raises(ValueError, match="miss_probability"):
        SimConfig(miss_probability=float("nan"))
    with pytest.raises(ValueError, match="rate_hz"):
        SimConfig(rate_hz=-1.0)
    assert SimConfig(level="pixel").frame_rate_hz == 5.0 and SimConfig().frame_rate_hz == 15.0
    assert SimConfig(num_people=6, second_day=True).num_new_people == 2
    assert SimConfig(num_people=6).num_new_people == 0


@pytest.mark.slow
def test_both_embedders_and_a_larger_colour_image(faces: Path, tmp_path: Path) -> None:
    """--embedder both stores dlib | SFace side by side (each half the photo variant's own embedding, plus
    the simulator's noise) with the eye distance of the face each embedding shows; a colour image of twice
    the resolution shows more faces with 20 px or more between the eyes (camera-true views); the bank's fixed
    variants (face-reid-fit-likelihood --camera-views) include the 14, 10 and 9 px ones."""
    from face_reid_master.sim.photos import variant_eye_px

    cache = tmp_path / "both.npz"
    base = SimConfig(num_people=3, num_cameras=2, duration_s=20.0, seed=3, embedder="both")
    sizes = {}
    for label, cfg in (("vga", base), ("2x", dataclasses.replace(base, color_resolution=(1280, 960)))):
        out = tmp_path / label
        write_scenario(simulate(faces, cfg, cache_path=cache), out)
        s = load_scenario(out)
        assert s.document["embedding_space"] == "dlib_resnet_v1+sface_2021dec"
        people = [p for f in s.frames for p in f.people if p.embedding is not None]
        assert people and all(p.embedding.shape == (256,) and p.embedding_space == s.document["embedding_space"]
                              for p in people)
        sface_norms = np.array([np.linalg.norm(p.embedding[128:]) for p in people])
        assert np.all(np.abs(sface_norms - 1.0) < 0.2)  # unit-length SFace rows, plus noise
        sizes[label] = np.array([p.face_eye_distance_px for p in people])
        assert np.all(sizes[label] > 0)
    bank = PhotoBank(faces, cache, embedder="both")
    ident = bank.load_identity(IDENTITIES[0])
    assert ident is not None and ident.photos[0].embeddings.shape == (NUM_VARIANTS, 256)
    allowed = {float(v) for ph in ident.photos for v in variant_eye_px(ph, np.arange(NUM_VARIANTS))}
    assert {9.0, 10.0, 14.0} <= allowed
    assert np.mean(sizes["2x"] >= 20) > np.mean(sizes["vga"] >= 20)  # more native-size faces
    with pytest.raises(ValueError, match="embedder must be one of"):
        SimConfig(embedder="openface")
    with pytest.raises(ValueError, match="color_resolution"):
        SimConfig(color_resolution=(10, 10))


def test_simulated_people_pass_each_other_instead_of_walking_through(faces: Path, cache: Path, tmp_path: Path) -> None:
    """5 people in a 5 x 4 m room for 40 s: without avoidance (passing distance 0, the simulator of before) some
    walk through each other; with the default 0.5 m no two people in the room ever come closer, people still
    pass each other at 0.5-0.8 m, and the same seed gives the same files."""
    from face_reid_master.sim.motion import MotionConfig

    cfg = SimConfig(num_people=5, num_cameras=1, duration_s=40.0, seed=5, embedder="dlib", room_size_m=(5.0, 4.0))

    def closest(out: Path) -> tuple[float, int]:
        g = load_scenario(out).ground_truth
        xy, here = g.xy.astype(np.float64), g.in_room
        best, passes = np.inf, 0
        for a in range(xy.shape[0]):
            for b in range(a + 1, xy.shape[0]):
                both = here[a] & here[b]
                if both.any():
                    dist = np.linalg.norm(xy[a, both] - xy[b, both], axis=1)
                    best = min(best, float(dist.min()))
                    passes += int(dist.min() < 0.8)
        return best, passes

    ghosts = tmp_path / "ghosts"
    write_scenario(simulate(faces, dataclasses.replace(cfg, motion=MotionConfig(passing_distance_m=0.0)),
                            cache_path=cache), ghosts)
    assert closest(ghosts)[0] < 0.3, "the planned paths no longer go through each other: the test shows nothing"
    a, b = tmp_path / "a", tmp_path / "b"
    write_scenario(simulate(faces, cfg, cache_path=cache), a)
    write_scenario(simulate(faces, cfg, cache_path=cache), b)
    for name in ("frames.npz", "ground_truth.npz", "scenario.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    best, passes = closest(a)
    assert best >= 0.5 - 1e-4  # the ground truth is float32
    assert passes >= 2, "nobody passes anybody: people avoid each other's paths instead of crossing them"
    doc = json.loads((a / "scenario.json").read_text())
    assert doc["parameters"]["motion"]["passing_distance_m"] == 0.5
    day = doc["summary"]["per_day"][0]
    assert day["closest_approach_m"] >= 0.5 - 1e-4 and day["giving_way"]["slowed_share"] > 0
    assert "giving_way" not in json.loads((ghosts / "scenario.json").read_text())["summary"]["per_day"][0]


def test_cli_passing_distance_option(faces: Path, tmp_path: Path, capsys) -> None:
    assert main(["--faces", str(faces), "--out", str(tmp_path / "s"), "--passing-distance", "0.3", "--quiet"]) == 2
    assert "passing_distance_m must be 0" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
