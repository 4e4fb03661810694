"""The honest-evaluation check (face_reid_master.evaluation.protocol) and face-reid-eval's use of it.

``check_protocol`` runs on synthetic scenario documents against metadata in each format a fit tool wrote
(``identities`` as a list or as the text of one, older face fits' ``excluded``, nothing); the CLI on a tiny
scenario of fixture faces the shipped face fit saw: refused (exit 3), then evaluated with ``--allow-fitted``
(marked not honest), then honest with a likelihood file that records other identities.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import pytest
from conftest import copy_fixture_faces

from face_reid_master.body.metric_file import default_body_metric
from face_reid_master.evaluation.cli import main
from face_reid_master.evaluation.protocol import check_protocol, fitted_identities, scenario_crop_identities
from face_reid_master.identity.size_likelihood import default_face_likelihood, save_face_likelihood

FACE_MODEL = "face likelihoods and naming distance"


# ------------------------------------------------------------------------------------- fitted_identities
def test_fitted_identities_reads_lists_and_their_text_and_says_none_otherwise() -> None:
    assert fitted_identities({"identities": ["b", "a"]}) == frozenset({"a", "b"})
    assert fitted_identities({"identities": ("a",)}) == frozenset({"a"})
    # the shipped body metric stores its metadata values as text: "['market1501_0002', ...]"
    assert fitted_identities({"identities": "['market1501_0002', 'pku_003']"}) == {"market1501_0002", "pku_003"}
    assert fitted_identities({"identities": []}) == frozenset()  # fitted on nobody: a real (empty) answer
    for meta in ({}, {"identities": None}, {"identities": "market1501_0002"}, {"identities": [1, 2]},
                 {"identities": "{'a': 1}"}, {"n_identities": 3}):
        assert fitted_identities(meta) is None, meta


def test_the_shipped_body_metric_records_its_identities() -> None:
    metric = default_body_metric()
    seen = fitted_identities(metric.metadata)
    assert seen is not None and len(seen) == int(metric.metadata["n_identities"])


# ------------------------------------------------------------------------------------- check_protocol
def _document(*, projection_fit: list[str] | None = None, bodies: bool = True) -> dict[str, Any]:
    """Two people; alice wears pku_001 on day 1 and pku_002 on day 2, bob market_0101 (bodies only)."""
    alice: dict[str, Any] = {"gt_id": 0, "name": "lfw_Alice"}
    bob: dict[str, Any] = {"gt_id": 1, "name": "orl_s07"}
    doc: dict[str, Any] = {"identities": [alice, bob]}
    if bodies:
        alice["clothes"] = {"1": "pku_001", "2": "pku_002"}
        bob["clothes"] = {"1": "market_0101"}
        doc["body_space"] = "body_pca_test"
        doc["body_projection_fit"] = projection_fit
    return doc


CLEAN_FACES = {"identities": ["lfw_Carol", "orl_s01"]}
CLEAN_BODIES = ["pku_009", "market_0200"]


def _seen(check: Any) -> dict[str, tuple[str, ...] | None]:
    return {o.model: o.seen for o in check.overlaps}


def test_scenario_crop_identities_are_every_day_clothes() -> None:
    assert scenario_crop_identities(_document()) == ["market_0101", "pku_001", "pku_002"]
    assert scenario_crop_identities(_document(bodies=False)) == []


def test_face_fit_recording_its_identities() -> None:
    check = check_protocol(_document(bodies=False), {"identities": ["lfw_Alice", "lfw_Carol"]}, "f.json")
    assert _seen(check) == {FACE_MODEL: ("lfw_Alice",)} and not check.honest
    (problem,) = check.problems()
    assert "f.json" in problem and "1 of the scenario's identities: lfw_Alice" in problem
    clean = check_protocol(_document(bodies=False), CLEAN_FACES, "f.json")
    assert clean.honest and clean.problems() == []
    assert clean.as_json() == {"honest": True, "models": [
        {"model": FACE_MODEL, "source": "f.json", "identities_seen": []}]}


@pytest.mark.parametrize("as_text", [False, True])
def test_older_face_fit_recording_only_its_exclusions(as_text: bool) -> None:
    """The shipped face likelihoods (written before ``identities``) used every folder but the excluded ones."""
    def meta(excluded: dict[str, list[str]]) -> dict[str, Any]:
        return {"excluded": str(excluded) if as_text else excluded}

    doc = _document(bodies=False)
    by_name = check_protocol(doc, meta({"patterns": ["celeba_*"], "scenario_identities": ["lfw_Alice"]}), "f")
    assert _seen(by_name) == {FACE_MODEL: ("orl_s07",)} and not by_name.honest
    by_glob = check_protocol(doc, meta({"patterns": ["orl_*"], "scenario_identities": ["lfw_Alice"]}), "f")
    assert _seen(by_glob) == {FACE_MODEL: ()} and by_glob.honest
    nothing_left_out = check_protocol(doc, meta({"patterns": [], "scenario_identities": []}), "f")
    assert _seen(nothing_left_out) == {FACE_MODEL: ("lfw_Alice", "orl_s07")}
    # ``identities`` wins over ``excluded`` when a file has both
    both = check_protocol(doc, {**meta({"patterns": [], "scenario_identities": []}), **CLEAN_FACES}, "f")
    assert both.honest


def test_face_fit_saying_nothing_is_not_honest() -> None:
    check = check_protocol(_document(bodies=False), {"data": "somewhere"}, "mystery.json")
    assert _seen(check) == {FACE_MODEL: None} and not check.honest
    assert check.problems() == [f"{FACE_MODEL} (mystery.json) does not record the identities it was fitted on"]
    assert check.as_json()["models"][0]["identities_seen"] is None


def test_body_projection_and_metric_are_checked_against_the_clothes_worn() -> None:
    doc = _document(projection_fit=CLEAN_BODIES)
    clean = check_protocol(doc, CLEAN_FACES, "f", {"identities": str(CLEAN_BODIES)}, "metric.json")
    assert _seen(clean) == {FACE_MODEL: (), "body projection": (), "body metric": ()} and clean.honest
    assert [o.source for o in clean.overlaps] == ["f", "body_pca_test", "metric.json"]

    metric_saw = check_protocol(doc, CLEAN_FACES, "f", {"identities": ["pku_002", "pku_009"]}, "metric.json")
    assert _seen(metric_saw)["body metric"] == ("pku_002",) and not metric_saw.honest
    (problem,) = metric_saw.problems()
    assert problem.startswith("body metric (metric.json) was fitted on 1") and problem.endswith("pku_002")

    projection_saw = check_protocol(_document(projection_fit=["market_0101", *CLEAN_BODIES]), CLEAN_FACES, "f",
                                    {"identities": CLEAN_BODIES}, "metric.json")
    assert _seen(projection_saw)["body projection"] == ("market_0101",) and not projection_saw.honest

    # a scenario simulated before face-reid-sim recorded the projection's fit, and a metric that says nothing
    unknown = check_protocol(_document(projection_fit=None), CLEAN_FACES, "f", {}, "metric.json")
    assert _seen(unknown) == {FACE_MODEL: (), "body projection": None, "body metric": None}
    assert not unknown.honest and len(unknown.problems()) == 2

    # bodies not evaluated (no metric passed): only the face fit and the projection count
    no_metric = check_protocol(doc, CLEAN_FACES, "f")
    assert set(_seen(no_metric)) == {FACE_MODEL, "body projection"} and no_metric.honest
    # a faces-only scenario: a metric that saw everyone does not matter
    faces_only = check_protocol(_document(bodies=False), CLEAN_FACES, "f", {"identities": ["pku_001"]}, "m")
    assert set(_seen(faces_only)) == {FACE_MODEL} and faces_only.honest


def test_honest_only_when_every_model_is_clean() -> None:
    dirty_faces = {"identities": ["orl_s07"]}
    doc = _document(projection_fit=CLEAN_BODIES)
    metric = {"identities": CLEAN_BODIES}
    assert check_protocol(doc, CLEAN_FACES, "f", metric, "m").honest
    assert not check_protocol(doc, dirty_faces, "f", metric, "m").honest
    assert not check_protocol(_document(projection_fit=["pku_001"]), CLEAN_FACES, "f", metric, "m").honest
    assert not check_protocol(doc, CLEAN_FACES, "f", {"identities": ["pku_001"]}, "m").honest


def test_many_overlapping_identities_are_shown_eight_and_counted() -> None:
    names = [f"orl_s{i:02d}" for i in range(12)]
    doc = {"identities": [{"gt_id": i, "name": n} for i, n in enumerate(names)]}
    (problem,) = check_protocol(doc, {"identities": names}, "f").problems()
    assert "fitted on 12 of the scenario's identities" in problem
    assert "orl_s07 and 4 more" in problem and "orl_s08" not in problem


# ------------------------------------------------------------------------------------- face-reid-eval
SEEN_BY_SHIPPED_FIT = ("lfw_Colin_Powell", "lfw_Tony_Blair")  # not in its `excluded` (lfw_Hugo_Chavez is)


@pytest.fixture(scope="module")
def seen_scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two fixture people the shipped dlib face likelihoods were fitted on, 30 s, two cameras."""
    from face_reid_master.sim.scenario_files import write_scenario
    from face_reid_master.sim.simulate import SimConfig, simulate

    faces = copy_fixture_faces(tmp_path_factory.mktemp("faces"), SEEN_BY_SHIPPED_FIT)
    out = tmp_path_factory.mktemp("scenario")
    write_scenario(simulate(faces, SimConfig(num_people=2, num_cameras=2, duration_s=30.0, seed=5, embedder="dlib")),
                   out)
    return out


def test_cli_refuses_a_scenario_of_people_the_face_fit_saw_unless_allowed(
        seen_scenario: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r.json"
    assert main([str(seen_scenario), "--no-mot", "--quiet", "--out", str(out)]) == 3
    captured = capsys.readouterr()
    assert captured.out == "" and not out.exists()
    assert "not an honest test" in captured.err and "--allow-fitted" in captured.err
    assert f"fitted on 2 of the scenario's identities: {', '.join(SEEN_BY_SHIPPED_FIT)}" in captured.err

    assert main([str(seen_scenario), "--no-mot", "--quiet", "--allow-fitted"]) == 0
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    assert "NOT AN HONEST TEST" in captured.err
    assert printed["protocol"]["honest"] is False
    face, cmap = printed["protocol"]["models"]
    assert face["model"] == FACE_MODEL and face["identities_seen"] == list(SEEN_BY_SHIPPED_FIT)
    assert cmap["model"] == "confidence map" and cmap["identities_seen"] == []  # fitted on other people
    assert printed["detections"] == printed["scenario"]["detections"] > 0  # the run happened


def test_cli_is_honest_with_a_face_fit_that_records_other_people(
        seen_scenario: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    shipped = default_face_likelihood("dlib_resnet_v1")
    path = tmp_path / "fit.json"
    save_face_likelihood(dataclasses.replace(
        shipped, metadata={**shipped.metadata, "identities": ["lfw_Hugo_Chavez", "orl_s01"]}), path)
    assert main([str(seen_scenario), "--likelihood", str(path), "--evidence", "face", "--no-mot", "--quiet"]) == 0
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    assert printed["protocol"] == {"honest": True, "models": [
        {"model": FACE_MODEL, "source": str(path), "identities_seen": []},
        {"model": "confidence map", "source": "shipped confidence map", "identities_seen": []}]}
    assert "HONEST" not in captured.err
    # the same file naming one of the scenario's people is refused
    path = tmp_path / "fit2.json"
    save_face_likelihood(dataclasses.replace(shipped, metadata={"identities": ["lfw_Tony_Blair"]}), path)
    assert main([str(seen_scenario), "--likelihood", str(path), "--evidence", "face", "--no-mot", "--quiet"]) == 3
    err = capsys.readouterr().err
    assert f"({path}) was fitted on 1 of the scenario's identities: lfw_Tony_Blair" in err


def test_the_confidence_map_is_checked_against_faces_and_crops_alike() -> None:
    doc = _document(projection_fit=CLEAN_BODIES)
    seen = _seen(check_protocol(doc, CLEAN_FACES, "faces", {"identities": CLEAN_BODIES}, "metric",
                                {"identities": ["orl_s07", "pku_002", "someone_else"]}, "map"))
    assert seen["confidence map"] == ("orl_s07", "pku_002")
    clean = check_protocol(doc, CLEAN_FACES, "faces", {"identities": CLEAN_BODIES}, "metric",
                           {"identities": []}, "raw")
    assert clean.honest and _seen(clean)["confidence map"] == ()
