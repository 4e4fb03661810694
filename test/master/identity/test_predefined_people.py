"""Tests of predefined-people naming (face_reid_master.identity.predefined_people, paper Sec. III-F)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import DATA_DIR, FACES_DIR

from face_reid_master.identity.predefined_people import (
    NameMatch,
    PredefinedPeople,
    assign_one_to_one,
    face_to_person_distance,
)

YUNET_PATH = DATA_DIR.parents[1] / "models" / "face_detection_yunet_2023mar.onnx"


def _pts(*rows: tuple[float, float]) -> np.ndarray:
    return np.array(rows, dtype=np.float32)


def test_distance_is_min_over_all_pairs() -> None:
    learned = _pts((0, 0), (10, 0))
    gallery = _pts((3, 4), (10, 7), (-6, -8))
    # pairs: (0,0)-(3,4)=5, (0,0)-(10,7)=12.21, (0,0)-(-6,-8)=10, (10,0)-(3,4)=8.06, (10,0)-(10,7)=7, ...
    assert face_to_person_distance(learned, gallery) == pytest.approx(5.0)
    # k = 2: nearest-gallery distance of each learned feature is 5 and 7 -> mean 6
    assert face_to_person_distance(learned, gallery, k_smallest=2) == pytest.approx(6.0)
    assert face_to_person_distance(learned, gallery, k_smallest=9) == pytest.approx(6.0)  # capped at k


@pytest.mark.parametrize(
    ("a", "b", "k"),
    [
        (np.zeros((0, 2)), np.zeros((1, 2)), 1),
        (np.zeros((1, 2)), np.zeros((1, 3)), 1),
        (np.zeros((1, 2)), np.zeros((1, 2)), 0),
        (np.full((1, 2), np.nan), np.zeros((1, 2)), 1),
    ],
)
def test_distance_rejects_bad_input(a: np.ndarray, b: np.ndarray, k: int) -> None:
    with pytest.raises(ValueError):
        face_to_person_distance(a, b, k)


def test_one_to_one_greedy_assignment_by_increasing_distance() -> None:
    d = np.array(
        [
            [0.30, 0.20, 0.90],  # face 0: closest to name 1
            [0.25, 0.10, 0.90],  # face 1: also closest to name 1, and closer -> takes it
            [0.90, 0.90, 0.70],  # face 2: only name 2, above the threshold
        ]
    )
    # by hand: (1,1)=0.10 first; then (0,1) blocked, (1,0) blocked, (0,0)=0.30 ok; name 2 at 0.70 >= 0.5
    assert assign_one_to_one(d, 0.5) == [(1, 1, 0.10), (0, 0, 0.30)]
    assert assign_one_to_one(d, 0.2) == [(1, 1, 0.10)]
    assert assign_one_to_one(np.array([[math.nan, 0.1]]), 0.5) == [(0, 1, 0.1)]
    assert assign_one_to_one(np.zeros((0, 3)), 0.5) == []
    with pytest.raises(ValueError):
        assign_one_to_one(np.zeros(3), 0.5)


def _cluster(centre: float, n: int, rng: np.random.Generator, dim: int = 8) -> np.ndarray:
    c = np.zeros(dim)
    c[0] = centre
    return (c + rng.normal(0, 0.02, (n, dim))).astype(np.float32)


def test_faces_are_named_once_they_have_enough_features_and_links_are_one_to_one() -> None:
    rng = np.random.default_rng(0)
    people = PredefinedPeople(
        {"ada": _cluster(0.0, 3, rng), "bob": _cluster(1.0, 3, rng)},
        name_threshold=0.3,
        min_face_features=4,
        embedding_dim=8,
    )
    assert people.names() == ["ada", "bob"]
    people.update_face(1, _cluster(0.0, 2, rng))  # ada, but only 2 features
    assert people.assignments() == {} and people.distance(1, "ada") is None
    people.update_face(1, _cluster(0.0, 4, rng))  # learned more: eligible now
    people.update_face(2, _cluster(1.0, 6, rng))  # bob
    people.update_face(3, _cluster(5.0, 6, rng))  # a stranger
    links = people.assignments()
    assert set(links) == {1, 2}
    assert links[1].name == "ada" and links[2].name == "bob" and isinstance(links[1], NameMatch)
    assert links[1].distance == pytest.approx(people.distance(1, "ada"))
    # a second face of ada (e.g. while face 1 is still around): only one face gets the name, the closer one
    people.update_face(4, _cluster(0.0, 6, rng) + np.float32(0.1))
    links = people.assignments()
    assert [f for f, m in links.items() if m.name == "ada"] == [1]
    people.remove_face(1)
    assert people.assignments()[4].name == "ada"
    people.remove_person("ada")
    assert {m.name for m in people.assignments().values()} == {"bob"}
    with pytest.raises(KeyError):
        people.remove_person("ada")


def test_gallery_changes_are_applied_to_known_faces() -> None:
    rng = np.random.default_rng(1)
    people = PredefinedPeople(name_threshold=0.3, min_face_features=1, embedding_dim=8)
    people.update_face(7, _cluster(2.0, 3, rng))
    assert people.assignments() == {}
    people.set_person("cy", _cluster(2.0, 2, rng))
    assert people.assignments()[7].name == "cy"


@pytest.mark.parametrize(
    "kw",
    [
        {"name_threshold": 0.0},
        {"name_threshold": math.nan},
        {"min_face_features": 0},
        {"k_smallest": 0},
        {"embedding_dim": 0},
    ],
)
def test_bad_parameters_raise(kw: dict) -> None:
    with pytest.raises(ValueError):
        PredefinedPeople(**kw)


def test_bad_gallery_and_face_inputs_raise() -> None:
    people = PredefinedPeople(embedding_dim=4)
    with pytest.raises(ValueError):
        people.set_person("", np.zeros((1, 4)))
    with pytest.raises(ValueError):
        people.set_person("x", np.zeros((1, 3)))
    with pytest.raises(ValueError):
        people.set_person("x", np.full((1, 4), np.inf))
    with pytest.raises(ValueError):
        people.update_face(1, np.zeros((0, 4)))
    with pytest.raises(ValueError):
        people.update_face("1", np.zeros((1, 4)))  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------ real faces
@pytest.fixture(scope="module")
def lfw_embeddings() -> dict[str, np.ndarray]:
    cv2 = pytest.importorskip("cv2")
    try:
        from face_reid_camera.faces.alignment import align_face
        from face_reid_camera.faces.embedder import FaceEmbedder
    except ImportError:
        pytest.skip("face_reid_camera.faces.embedder not available")
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    embedder = FaceEmbedder(num_threads=1)
    out = {}
    for folder in sorted(FACES_DIR.glob("lfw_*")):
        chips = []
        for path in sorted(folder.glob("*.jpg")):
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            detector.setInputSize((image.shape[1], image.shape[0]))
            _, faces = detector.detect(image)
            largest = faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]
            chips.append(align_face(image, largest[4:14].reshape(5, 2)))
        out[folder.name] = embedder.embed(np.stack(chips))
    return out


def test_real_learned_faces_get_the_right_names(lfw_embeddings: dict[str, np.ndarray]) -> None:
    names = sorted(lfw_embeddings)
    named, strangers = names[:7], names[7:]  # 3 people are not in the gallery
    people = PredefinedPeople({n: lfw_embeddings[n][:3] for n in named})  # 3 photos per name
    for face_id, person in enumerate(names, start=1):
        people.update_face(face_id, lfw_embeddings[person][3:])  # 7 other photos = learned features
    links = people.assignments()
    assert {f: m.name for f, m in links.items()} == {names.index(n) + 1: n for n in named}
    for s in strangers:
        assert names.index(s) + 1 not in links


def test_person_names_are_short_printable_and_refused_otherwise() -> None:
    from face_reid_master.identity.predefined_people import MAX_NAME_CHARS, check_person_name

    assert check_person_name("Zoë O'Neill-Søren") == "Zoë O'Neill-Søren"
    for bad, why in (("", "empty"), ("   ", "empty"), ("A" * (MAX_NAME_CHARS + 1), "more than"),
                     ("x" * 1_000_000, "1000000 characters"), ("Eve\n   7  Mallory", "control"),
                     ("\x1b[2J\x1b[31mroot", "control"), (" Bob", "space"), (42, "string")):
        with pytest.raises(ValueError, match=why) as info:
            check_person_name(bad)
        assert len(str(info.value)) < 200 and "\x1b" not in str(info.value) and "\n" not in str(info.value)
    people = PredefinedPeople(embedding_dim=4, name_threshold=0.5)
    with pytest.raises(ValueError, match="control"):
        people.set_person("Eve\nMallory", np.ones((1, 4), np.float32))
    assert people.names() == []
