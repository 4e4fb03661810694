"""Tests of face_reid_master.storage.gallery: predefined-people galleries from photo folders or .npz files."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA_DIR

from face_reid_camera.faces.photos import PhotoEmbedder
from face_reid_master.identity.predefined_people import PredefinedPeople
from face_reid_master.storage.gallery import GalleryResult, load_gallery, save_gallery_npz, validate_person_name

DATA_DIR = DATA_DIR
FACES_DIR = DATA_DIR / "faces"
DESK_FRAME = sorted((DATA_DIR / "rgbd" / "pcl_desk").glob("*_rgb.png"))[0]
# folder name -> fixture identity; two gallery photos each, the other photos are "seen by the cameras"
GALLERY = {"Tony Blair": "lfw_Tony_Blair", "Colin Powell": "lfw_Colin_Powell", "Ariel": "lfw_Ariel_Sharon"}
N_GALLERY_PHOTOS = 2


def _photos(identity: str) -> list[Path]:
    return sorted((FACES_DIR / identity).glob("*.jpg"))


@pytest.fixture(scope="module")
def photo_embedder() -> PhotoEmbedder:
    return PhotoEmbedder()


@pytest.fixture(scope="module")
def gallery_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("gallery")
    for name, identity in GALLERY.items():
        (root / name).mkdir()
        for p in _photos(identity)[:N_GALLERY_PHOTOS]:
            shutil.copy(p, root / name / p.name)
    (root / "Ariel" / "broken.jpg").write_bytes(b"\xff\xd8\xff junk")
    cv2.imwrite(str(root / "Colin Powell" / "desk.png"), cv2.imread(str(DESK_FRAME))[50:350, 100:500])
    return root


@pytest.fixture(scope="module")
def gallery(gallery_dir: Path, photo_embedder: PhotoEmbedder) -> GalleryResult:
    return load_gallery(gallery_dir, photo_embedder)


@pytest.fixture(scope="module")
def learned(photo_embedder: PhotoEmbedder) -> dict[str, np.ndarray]:
    """Embeddings of photos NOT in the gallery: 5 of each gallery person and 5 of a stranger."""
    out = {}
    for identity in [*GALLERY.values(), "lfw_Hugo_Chavez"]:
        embs = [photo_embedder.embed_photo(p) for p in _photos(identity)[N_GALLERY_PHOTOS : N_GALLERY_PHOTOS + 5]]
        out[identity] = np.stack([e.embedding for e in embs if e is not None])
    return out


def test_folder_gallery_names_embeddings_and_skipped(gallery_dir: Path, gallery: GalleryResult) -> None:
    assert list(gallery.people) == sorted(GALLERY)
    for emb in gallery.people.values():
        assert emb.shape == (N_GALLERY_PHOTOS, 128) and emb.dtype == np.float32
    assert gallery.skipped_unreadable == [gallery_dir / "Ariel" / "broken.jpg"]
    assert gallery.skipped_no_face == [gallery_dir / "Colin Powell" / "desk.png"]


def test_the_skipped_photos_are_named(gallery_dir: Path, gallery: GalleryResult) -> None:
    """The master's warning names the photos it left out (before: "skipped 1 unreadable photos" and no name)."""
    said = gallery.skipped_summary(gallery_dir)
    assert said == ("skipped 1 unreadable photo(s): 'Ariel/broken.jpg'; skipped 1 photo(s) without a detectable "
                    "face: 'Colin Powell/desk.png'")
    many = GalleryResult({"A": np.ones((1, 128))}, [Path(f"/g/A/{i}.jpg") for i in range(7)])
    assert many.skipped_summary("/g", max_named=2) == "skipped 7 unreadable photo(s): 'A/0.jpg', 'A/1.jpg' and 5 more"
    assert GalleryResult({"A": np.ones((1, 128))}).skipped_summary() == ""


def test_gallery_names_faces_learned_from_other_photos(
    gallery: GalleryResult, learned: dict[str, np.ndarray]
) -> None:
    people = PredefinedPeople(gallery.people, min_face_features=5)
    assert isinstance(people, PredefinedPeople) and people.names() == sorted(GALLERY)
    face_ids = {identity: i for i, identity in enumerate(learned)}
    for identity, feats in learned.items():
        people.update_face(face_ids[identity], feats)
    names = {m.face_id: m.name for m in people.assignments().values()}
    assert names == {face_ids[identity]: name for name, identity in GALLERY.items()}
    assert face_ids["lfw_Hugo_Chavez"] not in names  # a stranger stays unnamed
    # a tiny threshold names nobody
    strict = PredefinedPeople(gallery.people, name_threshold=0.05, min_face_features=1)
    strict.update_face(0, learned["lfw_Tony_Blair"])
    assert strict.assignments() == {}


def test_npz_round_trip(gallery: GalleryResult, tmp_path: Path) -> None:
    path = tmp_path / "people.npz"
    save_gallery_npz(gallery.people, path)
    loaded = load_gallery(path)  # no photo embedder needed
    assert list(loaded.people) == list(gallery.people)
    for name, emb in gallery.people.items():
        np.testing.assert_array_equal(loaded.people[name], emb)
        assert loaded.people[name].dtype == np.float32
    assert loaded.skipped_unreadable == [] and loaded.skipped_no_face == []
    # any name that is a valid person name survives, including numpy keyword-like names
    odd = {"file": np.ones((1, 128)), "Zoë O'Neil": np.zeros((3, 128), np.float64)}
    save_gallery_npz(odd, tmp_path / "odd.npz")
    back = load_gallery(tmp_path / "odd.npz")
    assert sorted(back.people) == sorted(odd) and back.people["Zoë O'Neil"].shape == (3, 128)


def test_folder_names_are_stripped_and_must_stay_unique(
    tmp_path: Path, photo_embedder: PhotoEmbedder
) -> None:
    photo = _photos("lfw_Tony_Blair")[0]
    (tmp_path / "g" / " Tony ").mkdir(parents=True)
    shutil.copy(photo, tmp_path / "g" / " Tony " / photo.name)
    assert list(load_gallery(tmp_path / "g", photo_embedder).people) == ["Tony"]
    (tmp_path / "g" / "Tony").mkdir()
    shutil.copy(photo, tmp_path / "g" / "Tony" / photo.name)
    with pytest.raises(ValueError, match="two folders are named 'Tony'"):
        load_gallery(tmp_path / "g", photo_embedder)


def test_unusable_galleries_give_clear_errors(tmp_path: Path, photo_embedder: PhotoEmbedder) -> None:
    with pytest.raises(ValueError, match="does not exist"):
        load_gallery(tmp_path / "missing", photo_embedder)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="has no photos"):
        load_gallery(tmp_path / "empty", photo_embedder)
    (tmp_path / "people.txt").write_text("x")
    with pytest.raises(ValueError, match=r"must be a \.npz"):
        load_gallery(tmp_path / "people.txt", photo_embedder)
    (tmp_path / "corrupt.npz").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(ValueError, match=r"not a readable \.npz"):
        load_gallery(tmp_path / "corrupt.npz")
    (tmp_path / "text.npz").write_text("garbage")  # before: numpy's hint to load it unsafely with allow_pickle
    with pytest.raises(ValueError, match=r"not a readable \.npz of embeddings: not a zip") as text:
        load_gallery(tmp_path / "text.npz")
    assert "pickle" not in str(text.value)
    np.save(tmp_path / "array.npy", np.zeros((2, 128)))
    (tmp_path / "array.npy").rename(tmp_path / "array.npz")  # before: a TypeError (an array is no context manager)
    with pytest.raises(ValueError, match=r"not a readable \.npz of embeddings: not a zip"):
        load_gallery(tmp_path / "array.npz")
    np.savez(tmp_path / "flat.npz", bob=np.zeros(128))
    with pytest.raises(ValueError, match=r"shape \(k >= 1, 128 or 256\)"):
        load_gallery(tmp_path / "flat.npz")
    np.savez(tmp_path / "nan.npz", bob=np.full((2, 128), np.nan))
    with pytest.raises(ValueError, match="NaN"):
        load_gallery(tmp_path / "nan.npz")
    np.savez(tmp_path / "none.npz")
    with pytest.raises(ValueError, match="no people"):
        load_gallery(tmp_path / "none.npz")
    with pytest.raises(ValueError, match="PhotoEmbedder"):
        load_gallery(tmp_path / "empty", photo_embedder="yes")  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["", "   ", " bob", "bob\n", "a/b", 7])
def test_bad_names_are_rejected(name: object, tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        validate_person_name(name)
    with pytest.raises(ValueError):
        save_gallery_npz({name: np.zeros((1, 128))}, tmp_path / "g.npz")  # type: ignore[dict-item]


def test_save_validates_arrays_and_suffix(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="128"):
        save_gallery_npz({"bob": np.zeros((2, 64))}, tmp_path / "g.npz")
    with pytest.raises(ValueError, match="at least one person"):
        save_gallery_npz({}, tmp_path / "g.npz")
    with pytest.raises(ValueError, match=r"must end in \.npz"):
        save_gallery_npz({"bob": np.zeros((2, 128))}, tmp_path / "g.json")
    assert not (tmp_path / "g.npz").exists()
