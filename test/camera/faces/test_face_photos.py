"""Tests of face_reid_camera.faces.photos: face photos / identity folders -> embeddings, progress bar."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA_DIR

from face_reid_camera.faces.photos import (
    FaceFolderResult,
    PhotoEmbedder,
    PhotoEmbedding,
    PhotoError,
    ProgressBar,
    embed_request_photos,
    progress_bar,
    read_photo,
)

DATA_DIR = DATA_DIR
FACES_DIR = DATA_DIR / "faces"
DESK_FRAME = sorted((DATA_DIR / "rgbd" / "pcl_desk").glob("*_rgb.png"))[0]
IDS = ("lfw_Tony_Blair", "lfw_Colin_Powell", "deepface_id02")


def _photos(identity: str) -> list[Path]:
    return sorted((FACES_DIR / identity).glob("*.jpg"))


def _dist(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a.astype(np.float64) - b.astype(np.float64)))


@pytest.fixture(scope="module")
def photo_embedder() -> PhotoEmbedder:
    return PhotoEmbedder()


@pytest.fixture(scope="module")
def tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """3 identities x 3 real photos + a corrupt jpg, a face-less desk crop, a text file, junk folders."""
    root = tmp_path_factory.mktemp("faces")
    for identity in IDS:
        (root / identity).mkdir()
        for p in _photos(identity)[:3]:
            shutil.copy(p, root / identity / p.name)
    (root / IDS[0] / "zz_corrupt.jpg").write_bytes(_photos(IDS[0])[0].read_bytes()[:400])
    desk = cv2.imread(str(DESK_FRAME))
    cv2.imwrite(str(root / IDS[1] / "zz_desk.png"), desk[100:400, 150:550])
    (root / IDS[2] / "notes.txt").write_text("not a photo")
    (root / IDS[2] / ".hidden.jpg").write_bytes(b"ignored")
    (root / "only_bad").mkdir()  # an identity without any usable photo: dropped
    (root / "only_bad" / "broken.png").write_bytes(b"\x89PNG garbage")
    (root / "empty_person").mkdir()
    (root / "manifest.csv").write_text("files in the root are not identities")
    return root


@pytest.fixture(scope="module")
def tree_result(photo_embedder: PhotoEmbedder, tree: Path) -> tuple[FaceFolderResult, list[tuple[int, int]]]:
    calls: list[tuple[int, int]] = []
    result = photo_embedder.embed_folder_tree(tree, progress=lambda done, total: calls.append((done, total)))
    return result, calls


def test_folder_tree_embeds_identities_and_reports_skipped_files(
    tree: Path, tree_result: tuple[FaceFolderResult, list[tuple[int, int]]]
) -> None:
    result, calls = tree_result
    assert sorted(result.identities) == sorted(IDS)  # "only_bad" and "empty_person" dropped
    assert all(len(v) == 3 for v in result.identities.values())
    assert result.n_photos == 9
    # identities in sorted folder order: deepface_id02, lfw_Colin_Powell, lfw_Tony_Blair, only_bad
    assert result.skipped_unreadable == [tree / IDS[0] / "zz_corrupt.jpg", tree / "only_bad" / "broken.png"]
    assert result.skipped_no_face == [tree / IDS[1] / "zz_desk.png"]
    assert result.ignored_non_image == [tree / IDS[2] / "notes.txt"]
    # progress: once per image file (9 good + corrupt + desk + broken), ending at total
    assert calls == [(i, 12) for i in range(1, 13)]
    # file order and paths are kept
    assert [e.path for e in result.identities[IDS[0]]] == [tree / IDS[0] / p.name for p in _photos(IDS[0])[:3]]


def test_embeddings_separate_people(tree_result: tuple[FaceFolderResult, list[tuple[int, int]]]) -> None:
    ids = tree_result[0].identities
    same = [_dist(a.embedding, b.embedding) for v in ids.values() for i, a in enumerate(v) for b in v[i + 1 :]]
    diff = [
        _dist(a.embedding, b.embedding)
        for i, n in enumerate(IDS)
        for m in IDS[i + 1 :]
        for a in ids[n]
        for b in ids[m]
    ]
    assert max(same) < 0.6 < min(diff)
    for v in ids.values():
        for e in v:
            assert e.embedding.shape == (128,) and e.embedding.dtype == np.float32
            assert not e.embedding.flags.writeable
            assert e.score >= 0.6 and e.eye_distance_px > 15.0
            x, y, w, h = e.box_xywh
            assert w > 40 and h > 40 and -w < x < 400 and -h < y < 400


def test_path_and_array_give_the_same_embedding(photo_embedder: PhotoEmbedder) -> None:
    path = _photos(IDS[0])[0]
    from_path = photo_embedder.embed_photo(path)
    from_str = photo_embedder.embed_photo(str(path))
    from_array = photo_embedder.embed_photo(cv2.imread(str(path)))
    assert from_path is not None and from_array is not None and from_str is not None
    assert from_path.path == path and from_array.path is None
    np.testing.assert_array_equal(from_path.embedding, from_array.embedding)
    np.testing.assert_array_equal(from_path.embedding, from_str.embedding)
    # grey and BGRA images are accepted; grey is still the same person
    bgr = cv2.imread(str(path))
    grey = photo_embedder.embed_photo(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    bgra = photo_embedder.embed_photo(cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA))
    assert grey is not None and _dist(grey.embedding, from_path.embedding) < 0.3
    assert bgra is not None
    np.testing.assert_allclose(bgra.embedding, from_path.embedding, atol=1e-5)


def test_big_photo_is_detected_small_but_aligned_at_full_resolution(photo_embedder: PhotoEmbedder) -> None:
    bgr = cv2.imread(str(_photos(IDS[1])[0]))
    ref = photo_embedder.embed_photo(bgr)
    big = cv2.resize(bgr, None, fx=6.0, fy=6.0, interpolation=cv2.INTER_CUBIC)  # 1500 x 1500 px
    big = cv2.copyMakeBorder(big, 0, 0, 0, 900, cv2.BORDER_REPLICATE)  # 2400 px wide, face on the left
    out = photo_embedder.embed_photo(big)
    assert ref is not None and out is not None
    # detection ran on the photo shrunk to 640 px; its box is mapped back to full-resolution pixels
    (det,) = photo_embedder.detector.detect(cv2.resize(big, (640, 400), interpolation=cv2.INTER_AREA))
    np.testing.assert_allclose(out.box_xywh, det.box_xywh * (2400 / 640), rtol=1e-5, atol=1e-3)
    assert out.score == pytest.approx(det.score)
    lm = det.landmarks * (2400 / 640)
    assert out.eye_distance_px == pytest.approx(float(np.linalg.norm(lm[1] - lm[0])), rel=1e-5)
    assert out.eye_distance_px == pytest.approx(6.0 * ref.eye_distance_px, rel=0.12)  # YuNet jitter across scales
    # landmarks mapped back correctly: same person, within YuNet's landmark jitter (unmapped would be > 0.6)
    assert _dist(out.embedding, ref.embedding) < 0.2


def test_largest_face_is_embedded(photo_embedder: PhotoEmbedder) -> None:
    a = cv2.imread(str(_photos(IDS[0])[1]))  # 250 x 250
    b = cv2.imread(str(_photos(IDS[1])[1]))
    canvas = np.full((250, 375, 3), 128, np.uint8)
    canvas[:, 125:] = a  # big face of A on the right
    canvas[60:185, :125] = cv2.resize(b, (125, 125), interpolation=cv2.INTER_AREA)  # half-size face of B
    assert len(photo_embedder.detector.detect(canvas)) == 2
    out = photo_embedder.embed_photo(canvas)
    ref_a, ref_b = photo_embedder.embed_photo(a), photo_embedder.embed_photo(b)
    assert out is not None and ref_a is not None and ref_b is not None
    assert _dist(out.embedding, ref_a.embedding) < 0.2 < 0.6 < _dist(out.embedding, ref_b.embedding)
    assert out.box_xywh[0] > 125


def test_photo_without_face_and_unreadable_files(photo_embedder: PhotoEmbedder, tmp_path: Path) -> None:
    assert photo_embedder.embed_photo(cv2.imread(str(DESK_FRAME))) is None
    assert photo_embedder.embed_photo(np.zeros((50, 60), np.uint8)) is None
    corrupt = tmp_path / "corrupt.jpg"
    corrupt.write_bytes(b"\xff\xd8\xff\xe0 truncated")
    with pytest.raises(PhotoError, match="not a decodable image"):
        photo_embedder.embed_photo(corrupt)
    empty = tmp_path / "empty.jpg"
    empty.write_bytes(b"")
    with pytest.raises(PhotoError, match="empty file"):
        read_photo(empty)
    with pytest.raises(PhotoError, match="cannot read"):
        photo_embedder.embed_photo(tmp_path / "missing.jpg")
    assert issubclass(PhotoError, ValueError)


@pytest.mark.parametrize(
    "bad",
    [np.zeros((40, 40, 3), np.float32), np.zeros((0, 10, 3), np.uint8), np.zeros((10, 10, 2), np.uint8), 42],
)
def test_bad_arrays_are_rejected(photo_embedder: PhotoEmbedder, bad: object) -> None:
    with pytest.raises(ValueError):
        photo_embedder.embed_photo(bad)  # type: ignore[arg-type]


def test_unusable_folders_give_clear_errors(photo_embedder: PhotoEmbedder, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not a directory"):
        photo_embedder.embed_folder_tree(tmp_path / "nope")
    (tmp_path / "root").mkdir()
    with pytest.raises(ValueError, match="has no photos"):
        photo_embedder.embed_folder_tree(tmp_path / "root")
    (tmp_path / "root" / "alice").mkdir()
    (tmp_path / "root" / "alice" / "readme.md").write_text("x")
    with pytest.raises(ValueError, match="has no photos"):
        photo_embedder.embed_folder_tree(tmp_path / "root")
    cv2.imwrite(str(tmp_path / "root" / "alice" / "desk.png"), cv2.imread(str(DESK_FRAME)))
    (tmp_path / "root" / "alice" / "bad.jpg").write_bytes(b"junk")
    with pytest.raises(ValueError, match="1 unreadable, 1 without a detectable face"):
        photo_embedder.embed_folder_tree(tmp_path / "root")


def test_constructor_and_record_validation() -> None:
    with pytest.raises(ValueError, match="max_side_px"):
        PhotoEmbedder(max_side_px=10)
    with pytest.raises(ValueError, match="detector"):
        PhotoEmbedder(detector="yunet")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="128"):
        PhotoEmbedding(None, np.zeros(64), np.zeros(4), 0.9, 30.0)
    with pytest.raises(ValueError, match="128"):
        PhotoEmbedding(None, np.full(128, np.nan), np.zeros(4), 0.9, 30.0)
    with pytest.raises(ValueError, match="box_xywh"):
        PhotoEmbedding(None, np.zeros(128), np.zeros(3), 0.9, 30.0)


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_non_tty_prints_a_line_per_ten_percent() -> None:
    out = io.StringIO()
    bar = progress_bar(200, "embedding", stream=out)
    assert isinstance(bar, ProgressBar) and not bar.interactive
    for i in range(1, 201):
        bar(i, 200)
    lines = out.getvalue().splitlines()
    assert lines[0] == "embedding: 0% (1/200)"
    assert lines[-1] == "embedding: 100% (200/200)"
    assert [int(line.split(": ")[1].split("%")[0]) // 10 for line in lines] == list(range(11))
    bar(200, 200)  # finished: silent
    assert len(out.getvalue().splitlines()) == 11


def test_progress_bar_tty_redraws_one_line() -> None:
    out = _Tty()
    bar = ProgressBar(0, "fit", stream=out)
    assert bar.interactive
    for i in range(1, 5):
        bar(i, 4)  # total learned from the callback
    text = out.getvalue()
    assert text.count("\r") == 4 and text.count("\n") == 1 and text.endswith("4/4 100%\n")
    assert "[" + "#" * 30 + "]" in text
    with pytest.raises(ValueError):
        ProgressBar(-1, "x")


# ---------------------------------------------------------------- photos from untrusted requests
def test_image_size_reads_real_jpeg_and_png_headers() -> None:
    from face_reid_camera.faces.photos import image_size

    photo = sorted((FACES_DIR / "deepface_id02").glob("*.jpg"))[0]
    image = read_photo(photo)
    assert image_size(photo.read_bytes()) == (image.shape[1], image.shape[0])
    assert image_size(DESK_FRAME.read_bytes()) == tuple(cv2.imread(str(DESK_FRAME)).shape[1::-1])
    assert image_size(b"GIF89a....") is None and image_size(b"\xff\xd8\xff") is None


def test_decode_photo_refuses_bombs_other_formats_and_garbage() -> None:
    from face_reid_camera.faces.photos import decode_photo

    # a PNG header claiming 60000 x 60000 pixels (10.8 GB decoded): refused before any decoding
    bomb = b"\x89PNG\r\n\x1a\n" + b"\x00\x00\x00\rIHDR" + (60000).to_bytes(4, "big") * 2 + b"\x08\x02\x00\x00\x00"
    with pytest.raises(PhotoError, match="60000 x 60000 pixels"):
        decode_photo(bomb + b"\x00" * 64)
    ok, bmp = cv2.imencode(".bmp", np.zeros((8, 8, 3), np.uint8))
    assert ok and decode_photo(bmp.tobytes()).shape == (8, 8, 3)  # trusted folders: any format cv2 reads
    with pytest.raises(PhotoError, match="not a JPEG or PNG"):
        decode_photo(bmp.tobytes(), jpeg_png_only=True)
    with pytest.raises(PhotoError, match="empty"):
        decode_photo(b"")
    with pytest.raises(PhotoError, match="not a decodable image"):
        decode_photo(b"\xff\xd8\xff\xe0" + b"\x00" * 100)


def test_read_confined_photo_reads_only_regular_files_inside_the_root(tmp_path: Path) -> None:
    import os
    import threading

    from face_reid_camera.faces.photos import read_confined_photo

    root = tmp_path / "gallery"
    (root / "alice").mkdir(parents=True)
    photo = sorted((FACES_DIR / "deepface_id02").glob("*.jpg"))[0]
    shutil.copy(photo, root / "alice" / "a.jpg")
    (root / "inside.jpg").symlink_to(root / "alice" / "a.jpg")
    assert read_confined_photo(root, "alice/a.jpg", 10**7) == photo.read_bytes()
    assert read_confined_photo(root, str(root / "inside.jpg"), 10**7) == photo.read_bytes()  # symlink inside
    outside = tmp_path / "secret.jpg"
    shutil.copy(photo, outside)
    (root / "out.jpg").symlink_to(outside)
    (root / "zero").symlink_to("/dev/zero")
    with open(root / "sparse.jpg", "wb") as f:  # a 64 GB sparse file: refused by its size, not read
        f.truncate(64 * 2**30)
    os.mkfifo(root / "fifo.jpg")
    for requested, why in ((str(outside), "outside the photo root"), ("../secret.jpg", "outside the photo root"),
                           ("out.jpg", "outside the photo root"), ("zero", "outside the photo root"),
                           ("/dev/zero", "outside the photo root"), ("alice", "not a regular file"),
                           ("sparse.jpg", "68719476736 bytes, more than 1000000"), ("fifo.jpg", "not a regular file"),
                           ("missing.jpg", "No such file"), ("a\x00b", "NUL"), ("x" * 5000, "too long")):
        result: list[BaseException] = []
        worker = threading.Thread(target=lambda r=requested, out=result: out.append(_refusal(root, r)), daemon=True)
        worker.start()
        worker.join(10.0)  # a FIFO opened for reading would block here forever
        assert result, f"{requested[:40]!r} froze the reader"
        assert isinstance(result[0], PhotoError) and why in str(result[0]), (requested[:40], result[0])
        assert len(str(result[0])) < 300  # a 5000-character path is cut in the message
    with pytest.raises(PhotoError, match="no photo root"):
        read_confined_photo("", "alice/a.jpg", 10**7)


def _refusal(root: Path, requested: str) -> BaseException:
    from face_reid_camera.faces.photos import read_confined_photo

    try:
        read_confined_photo(root, requested, 10**6)
    except BaseException as exc:  # returned to the test thread
        return exc
    return AssertionError("not refused")


def test_a_requests_photos_stay_within_its_pixel_budget(photo_embedder: PhotoEmbedder, tmp_path: Path) -> None:
    photo = _photos("deepface_id02")[0]
    image = cv2.imread(str(photo))
    h, w = image.shape[:2]
    for name in ("a.jpg", "b.jpg", "c.jpg"):
        cv2.imwrite(str(tmp_path / name), image)
    (tmp_path / "none.jpg").write_bytes(b"not an image")
    done = embed_request_photos(photo_embedder, tmp_path, ["a.jpg", "none.jpg", "b.jpg", "c.jpg", "../x.jpg"],
                                max_bytes=10_000_000, max_pixels=10_000_000, pixel_budget=2 * w * h)
    assert len(done.embeddings) == 2  # a and b; c is beyond the budget of two photos
    assert len(done.notes) == 3
    assert "not a JPEG or PNG" in done.notes[0] and "budget" in done.notes[1] and "outside" in done.notes[2]
    small = embed_request_photos(photo_embedder, tmp_path, ["a.jpg"], 10_000_000, max_pixels=w * h - 1,
                                 pixel_budget=10 * w * h)
    assert not small.embeddings and f"more than {w * h - 1}" in small.notes[0]
