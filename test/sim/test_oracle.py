"""Oracle evidence (face-reid-sim --oracle-evidence): the pure transform on a hand-made frame table, and a small
simulation and evaluation with it on the fixture faces."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import FACES_DIR

from face_reid_master.evaluation.cli import main as eval_main
from face_reid_master.sim.cli import main as sim_main
from face_reid_master.sim.frame_table import BodyRows, FrameTable
from face_reid_master.sim.oracle import closest_pair, medoid_index, oracle_table, space_medoid
from face_reid_master.sim.simulate import SimConfig

SPACE = "dlib_resnet_v1+sface_2021dec"
NOISE = 0.01


def _photos() -> list[np.ndarray]:
    """Two identities, three photos each, 256 values (dlib 128 + SFace 128). Identity 0: the dlib part's medoid is
    photo 1 (values 0, 1, 3 on one axis), the SFace part's photo 2 (0, 5, 4): each part on its own."""
    rng = np.random.default_rng(0)
    out = []
    for ident in range(2):
        base = rng.normal(size=256).astype(np.float32)
        rows = np.repeat(base[None], 3, axis=0)
        rows[:, 0] += np.array([0.0, 1.0, 3.0]) + 10 * ident
        rows[:, 128] += np.array([0.0, 5.0, 4.0])
        out.append(rows)
    return out


def _table() -> FrameTable:
    """Two frames (day 1 at 0 s, day 2 at 100 s), each: person 0, person 1 and a false positive, all with faces
    and bodies; the second frame's person 1 body is undescribed."""
    rng = np.random.default_rng(1)
    det = {"gt_id": np.array([0, 1, -1, 0, 1, -1], np.int32), "face": np.arange(6, dtype=np.int32),
           "body": np.arange(6, dtype=np.int32), "position": np.zeros((6, 3)), "std_m": np.zeros(6, np.float32),
           "height_m": np.zeros(6, np.float32)}
    face = {"embedding": rng.normal(size=(6, 256)).astype(np.float32), "score": np.ones(6, np.float32)}
    descriptor = rng.normal(size=(6, 8)).astype(np.float32)
    described = np.array([True, True, True, True, False, True])
    descriptor[~described] = 0.0
    body = BodyRows(descriptor, described, np.ones(6, np.float32), np.ones((6, 2), np.float32),
                    np.zeros((6, 6), np.float32), np.zeros(6, np.int32), np.zeros(6, np.float32),
                    np.zeros(6, np.int32))
    return FrameTable(np.zeros(2, np.int16), np.array([10.0, 110.0]), np.array([0, 3, 6]), det, face, body)


def _oracle(table: FrameTable, seed: int = 7) -> tuple[FrameTable, object]:
    rng = np.random.default_rng(seed)
    return oracle_table(table, _photos(), [0, 3], SPACE, [0.0, 100.0], NOISE, rng, np.random.default_rng(seed + 1))


def test_medoid_is_the_most_central_real_row() -> None:
    assert medoid_index(np.array([[0.0], [1.0], [3.0]])) == 1
    assert medoid_index(np.array([[0.0, 0.0], [10.0, 0.0], [1.0, 1.0], [0.5, 0.0]])) == 3
    centre, chosen = space_medoid(_photos()[0], SPACE)
    assert chosen == [1, 2]  # per component space: a joint embedding's parts come from different photos
    assert np.array_equal(centre[:128], _photos()[0][1, :128]) and np.array_equal(centre[128:], _photos()[0][2, 128:])
    assert closest_pair({0: np.zeros(2), 1: np.array([3.0, 4.0]), 2: np.array([0.0, 1.0])}) == (1.0, 0, 2)


def test_oracle_faces_one_vector_per_person_plus_noise_false_positives_untouched() -> None:
    table = _table()
    out, summary = _oracle(table)
    emb = out.face["embedding"]
    centres = [space_medoid(p, SPACE)[0] for p in _photos()]
    for gt, rows in ((0, [0, 3]), (1, [1, 4])):
        dev = emb[rows] - centres[gt]
        assert np.abs(dev).max() < 6 * NOISE and 0.5 * NOISE < dev.std() < 2 * NOISE  # within noise of one vector
        assert not np.array_equal(emb[rows[0]], emb[rows[1]])  # each observation its own noise
    between = np.linalg.norm(emb[[1, 4]].mean(axis=0) - emb[[0, 3]].mean(axis=0))
    assert between == pytest.approx(np.linalg.norm(centres[1] - centres[0]), abs=0.05)  # the medoids' distance
    assert np.array_equal(emb[[2, 5]], table.face["embedding"][[2, 5]])  # false positives keep theirs
    assert summary.face_rows == 4 and summary.face_medoid_photos == {0: [1, 2], 1: [4, 5]}
    assert summary.face_closest[1:] == (0, 1)
    assert summary.face_closest[0] == pytest.approx(float(np.linalg.norm(centres[1] - centres[0])), rel=1e-5)
    assert np.array_equal(out.det["gt_id"], table.det["gt_id"]) and out.face["score"] is table.face["score"]
    again, _ = _oracle(_table())
    assert np.array_equal(again.face["embedding"], emb)  # seeded
    other, _ = _oracle(_table(), seed=8)
    assert not np.array_equal(other.face["embedding"], emb)


def test_oracle_bodies_one_real_descriptor_per_person_and_day() -> None:
    table = _table()
    out, summary = _oracle(table)
    desc, old = out.body.descriptor, table.body.descriptor
    # person 0 on day 1 (row 0) and on day 2 (row 3): one real descriptor of theirs each day (here the only one)
    assert np.abs(desc[0] - old[0]).max() < 6 * NOISE and np.abs(desc[3] - old[3]).max() < 6 * NOISE
    assert np.abs(desc[0] - old[0]).max() > 0  # with noise
    assert np.array_equal(desc[4], np.zeros(8))  # undescribed stays zeros
    assert np.array_equal(desc[[2, 5]], old[[2, 5]])  # false positives keep theirs
    assert summary.body_rows == 3
    assert np.array_equal(out.body.described, table.body.described)


def test_config_records_the_oracle_only_when_asked() -> None:
    assert "oracle_noise_std" not in SimConfig().to_json()
    assert SimConfig(oracle_noise_std=0.01).to_json()["oracle_noise_std"] == 0.01
    for bad in (-0.1, float("nan"), 2.0):
        with pytest.raises(ValueError, match="oracle_noise_std"):
            SimConfig(oracle_noise_std=bad)


def test_simulate_and_evaluate_with_oracle_evidence(tmp_path: Path, capsys) -> None:
    out = tmp_path / "S"
    assert sim_main(["--faces", str(FACES_DIR), "--people", "4", "--cameras", "2", "--duration", "60", "--seed", "1",
                     "--oracle-evidence", "--out", str(out), "--quiet"]) == 0
    doc = json.loads((out / "scenario.json").read_text())
    assert doc["oracle"] is True and doc["oracle_evidence"]["noise_std"] == 0.01
    assert doc["parameters"]["oracle_noise_std"] == 0.01
    assert doc["oracle_evidence"]["face_rows"] == doc["summary"]["face_detections"] > 0
    capsys.readouterr()
    assert eval_main([str(out), "--allow-fitted", "--no-mot", "--quiet", "--out", str(tmp_path / "r.json")]) == 0
    result = json.loads((tmp_path / "r.json").read_text())
    oracle = result["oracle"]
    assert oracle["people"] == 4 and oracle["space"] == SPACE and result["scenario"]["oracle"] is True
    # no two people confusable: the closest observations of two people lie beyond the decision and naming distances
    assert oracle["min_between_observations_distance"] > oracle["decision_distance"] > oracle["name_distance"]
    assert oracle["separated"] is True
    assert 0.1 < oracle["median_within_person_distance"] < 0.25  # N(0, 0.01) in 256 values, scaled
    assert {"tracks", "success", "recover_rate"} <= result["reidentification"]["with_face"].keys()
    per = result["per_detection"]
    assert per["published_detections"] == per["right"] + per["wrong_identity"] + per["undecided"] > 0
