"""Tests of bodies in the simulator (``face-reid-sim --bodies``) on a generated crops folder.

The crops folder is made here: PKU-Reid-style identities (``CC_O.png``: 2 cameras x 8 orientations, the
orientation drawn into the crop) and Market-1501-style ones (``PID_cCsS_...jpg``, camera only), each in its
own clothes colours; a body projection is fitted on their descriptors. Faces come from the licensed fixture.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import copy_fixture_faces

from face_reid_camera.body.descriptor import body_descriptor
from face_reid_camera.body.projection import BodyProjection, fit_pca_block, load_body_projection, save_body_projection
from face_reid_camera.common.atomic_file import write_npz
from face_reid_master.records import BodyRecord
from face_reid_master.sim.bodies import (
    PKU_VIEW_DEG,
    BodyBank,
    BodySimConfig,
    BodyWorld,
    InsufficientBodiesError,
    choose_crops,
    make_measures,
    view_angle_deg,
)
from face_reid_master.sim.cli import main
from face_reid_master.sim.scenario_files import ScenarioFormatError, load_scenario, write_scenario
from face_reid_master.sim.simulate import SimConfig, simulate

FACE_IDENTITIES = ("lfw_Colin_Powell", "lfw_Tony_Blair", "deepface_id02", "deepface_id03", "facerec_obama")
PKU_IDS = ("pku_001", "pku_002", "pku_003", "pku_004", "pku_005")
MARKET_IDS = ("market_0101", "market_0102", "market_0103", "market_0104", "market_0105")


def _person_crop(top: tuple[int, int, int], legs: tuple[int, int, int], mark: int, rng: np.random.Generator,
                 width: int = 48) -> np.ndarray:
    """A 128-row person crop: noisy background, skin head, top and leg colours, a mark column set by ``mark``."""
    crop = rng.integers(90, 140, size=(128, width, 3)).astype(np.uint8)
    cx = width // 2
    crop[4:22, cx - 6: cx + 6] = (120, 150, 200)
    crop[22:64, cx - 14: cx + 14] = top
    crop[64:124, cx - 11: cx - 1] = legs
    crop[64:124, cx + 1: cx + 11] = legs
    col = cx - 12 + 3 * mark
    crop[30:60, col: col + 2] = (255 - np.array(top)).astype(np.uint8)  # orientation-dependent detail
    return crop


@pytest.fixture(scope="module")
def crops_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("bodies")
    rng = np.random.default_rng(5)
    for name in PKU_IDS:
        (root / name).mkdir()
        top, legs = tuple(int(v) for v in rng.integers(0, 256, 3)), tuple(int(v) for v in rng.integers(0, 120, 3))
        for cam in ("01", "02"):
            for o in range(1, 9):
                cv2.imwrite(str(root / name / f"{cam}_{o}.png"), _person_crop(top, legs, o, rng))
    for name in MARKET_IDS:
        (root / name).mkdir()
        pid = name.split("_")[1]
        top, legs = tuple(int(v) for v in rng.integers(0, 256, 3)), tuple(int(v) for v in rng.integers(0, 120, 3))
        for j, cam in enumerate((1, 2, 3)):
            cv2.imwrite(str(root / name / f"{pid}_c{cam}s1_{1000 + 37 * j:06d}_00.jpg"),
                        _person_crop(top, legs, j, rng, width=64), [cv2.IMWRITE_JPEG_QUALITY, 95])
    (root / "notes.txt").write_text("not an identity folder")
    return root


@pytest.fixture(scope="module")
def projection_file(crops_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    descs = [body_descriptor(cv2.imread(str(p))) for p in sorted(crops_dir.glob("*/*.*"))]
    projection = BodyProjection((fit_pca_block("hsv", np.array([d.hsv for d in descs]), 8),
                                 fit_pca_block("siltp", np.array([d.siltp for d in descs]), 6)))
    return save_body_projection(projection, tmp_path_factory.mktemp("proj") / "body_projection.npz")


@pytest.fixture(scope="module")
def projection(projection_file: Path) -> BodyProjection:
    from face_reid_camera.body.projection import load_body_projection

    return load_body_projection(projection_file)


@pytest.fixture(scope="module")
def faces(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return copy_fixture_faces(tmp_path_factory.mktemp("faces"), FACE_IDENTITIES)


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cache") / "embeddings.npz"


def _config(**kwargs: object) -> SimConfig:
    base: dict[str, object] = dict(num_people=3, num_cameras=2, duration_s=20.0, seed=3, second_day=True,
                                   new_people=1, embedder="dlib", bodies=BodySimConfig())
    return SimConfig(**(base | kwargs))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def feature_dir(faces: Path, cache: Path, crops_dir: Path, projection: BodyProjection,
                tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("scenario")
    write_scenario(simulate(faces, _config(), cache_path=cache, bodies_dir=crops_dir, body_projection=projection), out)
    return out


def _frame_of_detection(a: dict) -> np.ndarray:
    return np.repeat(np.arange(a["frame_stamp_s"].size), np.diff(a["frame_offsets"]))


def test_clothes_ground_truth_and_a_change_of_clothes_on_day_two(feature_dir: Path, crops_dir: Path,
                                                                 projection: BodyProjection) -> None:
    s = load_scenario(feature_dir)
    doc = s.document
    assert doc["bodies_dir"] == str(crops_dir) and doc["body_space"] == projection.space
    assert doc["body_descriptor_length"] == projection.length
    assert {d["identity"] for d in doc["body_crops"]} <= set(PKU_IDS + MARKET_IDS)
    worn = []
    for ident in doc["identities"]:
        assert set(ident["clothes"]) == {str(d) for d in ident["days"]}
        worn.extend(ident["clothes"].values())
        if ident["days"] == [1, 2]:
            assert ident["clothes"]["1"] != ident["clothes"]["2"]  # returning people changed clothes
        assert 0.3 < ident["body_measures"]["shoulder_width_m"] < 0.6
    assert len(worn) == 6 and len(set(worn)) == 6  # 3 on day 1, 2 back + 1 new on day 2: nobody shares clothes
    # every detection of a true person has a body; the crop it shows is of the clothes of that person that day
    with np.load(feature_dir / "frames.npz") as f:
        a = {k: f[k] for k in f.files}
    gt, det_body = a["det_gt_id"], a["det_body"]
    assert np.all((det_body >= 0) == (gt >= 0)) and (gt < 0).any()
    day2 = doc["days"][1]["start_s"]
    day = np.where(a["frame_stamp_s"][_frame_of_detection(a)] >= day2, 2, 1)
    crops = doc["body_crops"]
    rows = det_body >= 0
    for g, d, c in zip(gt[rows], day[rows], a["body_crop"][det_body[rows]], strict=True):
        assert crops[int(c)]["identity"] == doc["identities"][int(g)]["clothes"][str(d)]
    # the loaded records carry the bodies
    records = [(p, int(g)) for fr, gts in zip(s.frames, s.frame_gt_ids, strict=True) for p, g in
               zip(fr.people, gts, strict=True)]
    assert all((p.body is None) == (g < 0) for p, g in records)
    bodies = [p.body for p, g in records if g >= 0]
    assert all(isinstance(b, BodyRecord) and b.space == projection.space and b.geometry.shape == (6,)
               and b.part_visible.shape == (4,) and 0.0 <= b.visible_fraction <= 1.0 for b in bodies)
    described = [b for b in bodies if b.descriptor.size]
    assert len(described) > 0.9 * len(bodies) and all(b.descriptor.shape == (projection.length,) for b in described)
    assert doc["summary"]["body_detections"] == len(bodies)
    # the crop shown per detection agrees with the loaded per-frame crops
    flat = np.concatenate(s.frame_body_crops)
    assert np.array_equal(flat[rows], a["body_crop"][det_body[rows]]) and np.all(flat[~rows] == -1)


def test_descriptors_are_the_crops_own_and_tell_clothes_apart(feature_dir: Path) -> None:
    """Same clothes within a day give nearer descriptors than other people's clothes; glances keep their light."""
    with np.load(feature_dir / "frames.npz") as f:
        a = {k: f[k] for k in f.files}
    doc = json.loads((feature_dir / "scenario.json").read_text())
    rows = a["det_body"][a["det_body"] >= 0]
    desc, described = a["body_descriptor"][rows], a["body_described"][rows]
    names = np.array([doc["body_crops"][int(c)]["identity"] for c in a["body_crop"][rows]])
    full = a["body_visible"][rows] == 1.0
    keep = described & full
    desc, names = desc[keep], names[keep]
    rng = np.random.default_rng(0)
    pick = rng.choice(desc.shape[0], size=min(600, desc.shape[0]), replace=False)
    d = np.linalg.norm(desc[pick, None] - desc[None, pick], axis=2)
    same = names[pick, None] == names[None, pick]
    off = ~np.eye(pick.size, dtype=bool)
    assert np.median(d[same & off]) < 0.6 * np.median(d[~same])
    assert len(set(names)) >= 4
    # frames of a glance change a little (frame variants + noise), much less than clothes do
    glances = a["body_glance"][rows][keep]
    within = [np.median(np.linalg.norm(desc[glances == g] - desc[glances == g].mean(0), axis=1))
              for g in np.unique(glances) if (glances == g).sum() > 3]
    assert len(within) >= 5 and 0.02 < np.median(within) < 0.4 * np.median(d[~same])
    # undescribed rows (too little seen) are zeros
    assert not a["body_descriptor"][~a["body_described"]].any()


def test_orientation_matched_crop_choice(crops_dir: Path, projection: BodyProjection) -> None:
    """PKU-style clothes show the crop whose orientation is nearest the view, from one source camera per glance;
    camera-only clothes show one crop per glance."""
    assert PKU_VIEW_DEG[7] == 0.0 and PKU_VIEW_DEG[3] == -180.0 and PKU_VIEW_DEG[1] == -90.0
    assert PKU_VIEW_DEG[5] == 90.0 and PKU_VIEW_DEG[6] == 45.0 and PKU_VIEW_DEG[8] == -45.0
    # a person at the origin facing -y seen by a camera at (-3, 0): facing the image's right = +90
    assert view_angle_deg(np.array([-3.0, 0.0]), np.array([[0.0, 0.0]]), np.array([-np.pi / 2]))[0] == \
        pytest.approx(90.0)
    bank = BodyBank(crops_dir, projection)
    pku, market = bank.load_identity(PKU_IDS[0]), bank.load_identity(MARKET_IDS[0])
    assert pku is not None and market is not None and pku.oriented and not market.oriented
    assert len(pku.sector_crops) == 2 and len(market.crops) == 3
    bodies = BodyWorld(bank, BodySimConfig(), {(0, 1): pku, (1, 1): market}, make_measures(np.ones(2) * 1.7,
                       np.random.default_rng(0)), np.ones((1, 3)))
    n = 400
    stamps = np.arange(n) / 10.0
    present = np.ones((n, 2), dtype=bool)
    present[100:120] = False  # a gap: two glances each
    present[300:330] = False
    view = np.stack([np.linspace(-180.0, 540.0, n), np.zeros(n)], axis=1)  # person 0 turns around twice
    view = (view + 180.0) % 360.0 - 180.0
    crop, glance, level = choose_crops(bodies, 1, [0, 1], stamps, present, view, 0.5, np.random.default_rng(1))
    assert np.all((crop >= 0) == present) and np.all((glance >= 0) == present)
    assert len(np.unique(glance[present[:, 0], 0])) == 3 and set(np.unique(level)) <= {-1, 0, 1}
    shown = crop[present[:, 0], 0]
    views = np.array([bank.crop_view_deg(int(c)) for c in shown])
    gap = np.abs((views - view[present[:, 0], 0] + 180.0) % 360.0 - 180.0)
    assert gap.max() <= 22.5 + 1e-6
    assert len({bank.crops[int(c)].orientation for c in shown}) == 8  # every orientation shows while turning
    for g in np.unique(glance[:, 0][glance[:, 0] >= 0]):
        sel = glance[:, 0] == g
        assert len({bank.crops[int(c)].camera for c in crop[sel, 0]}) == 1  # one source camera per glance
        assert len(set(level[sel, 0])) == 1
        sel1 = glance[:, 1] == g + 3
        assert len(set(crop[sel1, 1])) == 1  # camera-only clothes: one crop per glance
    assert {bank.crops[int(c)].identity for c in crop[present[:, 1], 1]} == {MARKET_IDS[0]}


def test_geometry_follows_the_view_and_the_visible_bands(feature_dir: Path) -> None:
    """Shoulder width seen from the front is the person's width, from the side their depth; a measure is NaN
    when its band is hidden, and the visible fraction is the share of bands seen."""
    with np.load(feature_dir / "frames.npz") as f:
        a = {k: f[k] for k in f.files}
    doc = json.loads((feature_dir / "scenario.json").read_text())
    rows = a["det_body"] >= 0
    b = a["det_body"][rows]
    gt = a["det_gt_id"][rows]
    view = a["body_view_deg"][b]
    shoulders = a["body_geometry"][b, 2]
    measures = [doc["identities"][int(g)]["body_measures"] for g in gt]
    width = np.array([m["shoulder_width_m"] for m in measures])
    depth = np.array([m["shoulder_depth_m"] for m in measures])
    front = (np.abs(view) < 15) | (np.abs(view) > 165)
    side = np.abs(np.abs(view) - 90) < 15
    assert front.sum() > 20 and side.sum() > 20
    assert abs(np.nanmedian(shoulders[front] - width[front])) < 0.02
    assert abs(np.nanmedian(shoulders[side] - depth[side])) < 0.02
    assert np.nanmedian(shoulders[front]) > np.nanmedian(shoulders[side]) + 0.08
    visible = a["body_visible"][b]
    assert np.all(visible[np.isnan(a["body_geometry"][b, 5])] < 1.0)  # hip NaN only when something is hidden
    assert (visible < 1.0).any() and np.all(np.isin(np.round(visible * 8), np.arange(9)))
    assert np.allclose(a["body_geometry"][b, 0], a["det_height_m"][rows])


def test_same_seed_same_files_and_bodies_leave_everything_else_alone(
    faces: Path, cache: Path, crops_dir: Path, projection: BodyProjection, tmp_path: Path
) -> None:
    cfg = _config(duration_s=8.0, second_day=False, new_people=None)
    plain = SimConfig(**{**{f: getattr(cfg, f) for f in cfg.__dataclass_fields__}, "bodies": None})
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for out in (a, b):
        write_scenario(simulate(faces, cfg, cache_path=cache, bodies_dir=crops_dir, body_projection=projection), out)
    write_scenario(simulate(faces, plain, cache_path=cache), c)
    for name in ("frames.npz", "ground_truth.npz", "scenario.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "ground_truth.npz").read_bytes() == (c / "ground_truth.npz").read_bytes()
    with np.load(a / "frames.npz") as fa, np.load(c / "frames.npz") as fc:
        assert set(fa.files) - set(fc.files) == {"det_body", "body_descriptor", "body_described", "body_visible",
                                                 "body_part_visible", "body_geometry", "body_crop", "body_view_deg",
                                                 "body_glance"}
        for k in fc.files:
            assert np.array_equal(fa[k], fc[k]), k
    doc_a, doc_c = (json.loads((d / "scenario.json").read_text()) for d in (a, c))
    for key in ("bodies_dir", "body_space", "body_projection_fit", "body_descriptor_length", "body_crops",
                "body_orientation_view_deg"):
        del doc_a[key]
    for ident in doc_a["identities"]:
        del ident["clothes"], ident["body_measures"]
    for key in ("body_detections", "body_descriptors", "body_glances", "body_crops_skipped_unreadable"):
        del doc_a["summary"][key]
    for doc in (doc_a, doc_c):  # the rows the camera gave the bodies (none without bodies)
        del doc["summary"]["camera_true"]["body_rows"], doc["summary"]["camera_true"]["bodies_reduced"]
    del doc_a["parameters"]["bodies"]
    assert doc_a == doc_c
    # a scenario without bodies (as written before bodies existed) loads with no body anywhere
    s = load_scenario(c)
    assert all(p.body is None for f in s.frames for p in f.people)
    assert all(np.all(x == -1) for x in s.frame_body_crops) and len(s.frame_body_crops) == len(s.frames)
    # incomplete body arrays are refused
    with np.load(a / "frames.npz") as fa:
        arrays = {k: fa[k] for k in fa.files if k != "body_geometry"}
    write_npz(a / "frames.npz", arrays)
    with pytest.raises(ScenarioFormatError, match="body arrays incomplete"):
        load_scenario(a)


def test_pixel_level_bodies_through_the_camera_pipeline(faces: Path, cache: Path, crops_dir: Path,
                                                        projection: BodyProjection, tmp_path: Path) -> None:
    cfg = SimConfig(num_people=2, num_cameras=1, duration_s=2.0, rate_hz=2.0, seed=13, level="pixel",
                    room_size_m=(7.0, 5.0), embedder="dlib", bodies=BodySimConfig())
    for out in ("p1", "p2"):
        write_scenario(simulate(faces, cfg, cache_path=cache, bodies_dir=crops_dir, body_projection=projection),
                       tmp_path / out)
    for name in ("frames.npz", "scenario.json"):
        assert (tmp_path / "p1" / name).read_bytes() == (tmp_path / "p2" / name).read_bytes(), name
    s = load_scenario(tmp_path / "p1")
    doc = s.document
    seen = 0
    for f, gts, crops in zip(s.frames, s.frame_gt_ids, s.frame_body_crops, strict=True):
        for p, gt, c in zip(f.people, gts, crops, strict=True):
            if gt < 0 or p.body is None:
                continue
            seen += 1
            assert p.body.space == projection.space and p.body.geometry[0] == pytest.approx(p.height_m, abs=0.05)
            assert doc["body_crops"][int(c)]["identity"] == doc["identities"][int(gt)]["clothes"]["1"]
            if p.body.descriptor.size:
                assert p.body.descriptor.shape == (projection.length,) and np.isfinite(p.body.descriptor).all()
    assert seen >= 4
    assert doc["summary"]["body_descriptors"] >= 4


def test_cli_body_errors(faces: Path, cache: Path, crops_dir: Path, projection_file: Path, tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    common = ["--faces", str(faces), "--people", "2", "--cameras", "1", "--duration", "3", "--cache", str(cache)]
    code = main([*common, "--bodies", str(crops_dir), "--body-projection", str(tmp_path / "none.npz"),
                 "--out", str(tmp_path / "o1")])
    assert code == 1 and "body projection file" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    code = main([*common, "--bodies", str(tmp_path / "empty"), "--body-projection", str(projection_file),
                 "--out", str(tmp_path / "o2")])
    assert code == 2 and "no images" in capsys.readouterr().err
    small = tmp_path / "small"
    shutil.copytree(crops_dir / PKU_IDS[0], small / PKU_IDS[0])
    code = main([*common, "--bodies", str(small), "--body-projection", str(projection_file), "--out",
                 str(tmp_path / "o3")])
    assert code == 2 and "1 usable crop identities, the scenario needs 2" in capsys.readouterr().err
    code = main([*common, "--bodies", str(crops_dir), "--body-projection", str(projection_file), "--out",
                 str(tmp_path / "o4")])
    assert code == 0, capsys.readouterr().err
    assert json.loads((tmp_path / "o4" / "scenario.json").read_text())["body_space"] == \
        json.loads(np.load(projection_file)["meta"].item())["space"]
    with pytest.raises(InsufficientBodiesError, match="does not exist"):
        BodyBank(tmp_path / "nope", load_body_projection(projection_file))
    with pytest.raises(ValueError, match="go together"):
        simulate(faces, _config(), cache_path=cache)


def test_crop_descriptor_ignores_background_and_hidden_bands(tmp_path: Path, projection: BodyProjection) -> None:
    """Only the crop's central columns (the person) and its seen bands count, as at a camera cutting the person
    out by depth; the light changes the descriptor."""
    rng = np.random.default_rng(3)
    crop = _person_crop((200, 30, 30), (40, 40, 40), 2, rng)
    other_background = crop.copy()
    other_background[:, :5] = (0, 255, 0)  # (SILTP looks 3 px beyond the mask at full, 6 at half size)
    other_background[:, -5:] = (255, 0, 255)
    other_legs = crop.copy()
    other_legs[104:] = (0, 0, 255)  # within bands 6 and 7 of 8 (rows 96-127), beyond SILTP's reach of band 5
    for name, image in (("a", crop), ("b", other_background), ("c", other_legs)):
        (tmp_path / "crops" / name).mkdir(parents=True)
        cv2.imwrite(str(tmp_path / "crops" / name / "01_7.png"), image)
    bank = BodyBank(tmp_path / "crops", projection)
    for name in "abc":
        assert bank.load_identity(name) is not None
    one = np.ones(3)
    full, upper = 0xFF, 0x3F

    def desc(i: int, bands: int = full, gains: np.ndarray = one, key: tuple[int, ...] = (0, 0)) -> np.ndarray:
        return bank.descriptor(i, gains, key, bands, 8, 128, 0.5)

    assert np.allclose(desc(0), desc(1), atol=1e-6)  # background left out
    assert not np.allclose(desc(0), desc(2), atol=1e-3)  # legs differ ...
    assert np.allclose(desc(0, upper), desc(2, upper), atol=1e-6)  # ... unless hidden
    assert not np.allclose(desc(0), desc(0, gains=np.array([0.6, 0.9, 1.3]), key=(1, 0)), atol=1e-3)
    assert desc(0) is desc(0)  # cached


# ------------------------------------------------------------------------------------- honest evaluation
def _worn(doc: dict) -> set[str]:
    return {c for ident in doc["identities"] for c in ident["clothes"].values()}


def test_cli_records_the_identities_the_body_projection_was_fitted_on(
        faces: Path, cache: Path, crops_dir: Path, projection: BodyProjection, projection_file: Path,
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """face-reid-sim writes ``body_projection_fit`` (None when the projection does not say) for face-reid-eval."""
    from face_reid_master.evaluation.protocol import check_protocol

    fitted = [MARKET_IDS[0], PKU_IDS[0], PKU_IDS[1], "market1501_0002"]
    recorded = save_body_projection(dataclasses.replace(projection, metadata={"identities": fitted}),
                                    tmp_path / "recorded.npz")
    common = ["--faces", str(faces), "--people", "3", "--cameras", "1", "--duration", "3", "--cache", str(cache),
              "--bodies", str(crops_dir), "--seed", "3"]
    assert main([*common, "--body-projection", str(recorded), "--out", str(tmp_path / "a")]) == 0, \
        capsys.readouterr().err
    doc = json.loads((tmp_path / "a" / "scenario.json").read_text())
    assert doc["body_projection_fit"] == sorted(fitted)
    seen = _worn(doc) & set(fitted)
    check = check_protocol(doc, {"identities": []}, "faces")
    assert {o.model: o.seen for o in check.overlaps}["body projection"] == tuple(sorted(seen))
    assert check.honest == (not seen)
    assert main([*common, "--body-projection", str(projection_file), "--out", str(tmp_path / "b")]) == 0
    assert json.loads((tmp_path / "b" / "scenario.json").read_text())["body_projection_fit"] is None


def test_eval_checks_and_uses_the_body_metric_given(faces: Path, cache: Path, crops_dir: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """With the shipped projection and metric (fitted on other crops) and a face fit recording other people,
    the generated scenario is an honest test; a --body-metric file fitted on its crops is refused, and with
    --allow-fitted that file is the run's metric (its rank-1, not the shipped one's, in the JSON)."""
    from face_reid_master.body.linear_metric import LinearMetric
    from face_reid_master.body.metric_file import default_body_metric, save_body_metric
    from face_reid_master.evaluation.cli import main as eval_main
    from face_reid_master.identity.size_likelihood import default_face_likelihood, save_face_likelihood

    scenario = tmp_path / "s"
    assert main(["--faces", str(faces), "--people", "3", "--cameras", "2", "--duration", "20", "--cache", str(cache),
                 "--bodies", str(crops_dir), "--seed", "3", "--embedder", "dlib", "--out", str(scenario),
                 "--quiet"]) == 0, capsys.readouterr().err
    capsys.readouterr()  # the simulator's summary
    worn = sorted(_worn(json.loads((scenario / "scenario.json").read_text())))
    face_fit = tmp_path / "faces.json"
    save_face_likelihood(dataclasses.replace(default_face_likelihood(), metadata={"identities": ["orl_s01"]}),
                         face_fit)
    common = [str(scenario), "--likelihood", str(face_fit), "--no-mot", "--quiet"]
    assert eval_main(common) == 0
    shipped = json.loads(capsys.readouterr().out)
    assert shipped["protocol"]["honest"] is True
    assert [m["model"] for m in shipped["protocol"]["models"]] == [
        "face likelihoods and naming distance", "body projection", "body metric", "confidence map"]

    base = default_body_metric()
    fused = base.features["fused"]
    one_dim = LinearMetric(fused.metric.projection[:, :1], fused.metric.metric[:1, :1], fused.metric.name)  # worse
    fitted = dataclasses.replace(
        base, features={**base.features, "fused": dataclasses.replace(fused, metric=one_dim)},
        metadata={**base.metadata, "identities": [*worn, "pku_999"]})
    path = tmp_path / "metric.json"
    save_body_metric(fitted, path)
    assert eval_main([*common, "--body-metric", str(path)]) == 3
    err = capsys.readouterr().err
    assert f"body metric ({path}) was fitted on {len(worn)} of the scenario's identities" in err
    assert eval_main([*common, "--body-metric", str(path), "--allow-fitted"]) == 0
    printed = json.loads(capsys.readouterr().out)
    metric = printed["protocol"]["models"][2]
    assert printed["protocol"]["honest"] is False
    assert metric == {"model": "body metric", "source": str(path), "identities_seen": worn}
    assert printed["body_metric"]["bodies"] == shipped["body_metric"]["bodies"] > 0
    assert printed["body_metric"]["rank1"] != shipped["body_metric"]["rank1"]

