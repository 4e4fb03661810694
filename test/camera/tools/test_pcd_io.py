"""Tests of the PCD reader/writer (ascii, binary, binary_compressed with LZF) and intrinsics recovery."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import RGBD_DIR

from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_camera.tools.pcd_io import (
    intrinsics_from_organized_cloud,
    lzf_compress,
    lzf_decompress,
    read_pcd,
    write_pcd,
)

PERSON_PCD = RGBD_DIR / "person.pcd"


def header(fields: str, size: str, type_: str, count: str, width: int, height: int, data: str) -> bytes:
    return (
        f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\n"
        f"TYPE {type_}\nCOUNT {count}\nWIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {width * height}\nDATA {data}\n"
    ).encode("ascii")


@pytest.fixture(scope="module")
def person() -> np.ndarray:
    return read_pcd(PERSON_PCD)


def test_real_kinect_cloud_reads_as_organized_xyz(person: np.ndarray) -> None:
    assert person.shape == (480, 640, 3) and person.dtype == np.float32
    valid = np.isfinite(person[..., 2])
    assert valid.mean() == pytest.approx(0.79, abs=0.01)
    assert np.array_equal(valid, np.all(np.isfinite(person), axis=2))  # NaN in all three or none
    z = person[..., 2][valid]
    assert 0.55 < z.min() < 0.65 and 3.7 < z.max() < 3.9
    # The person stands ~0.8 m in front of the camera at the image centre.
    assert np.nanmedian(person[300:340, 300:340, 2]) == pytest.approx(0.78, abs=0.05)


def test_intrinsics_of_the_real_cloud(person: np.ndarray) -> None:
    k = intrinsics_from_organized_cloud(person)
    assert (k.width, k.height) == (640, 480)
    assert k.fx == pytest.approx(525.0, abs=0.01) and k.fy == pytest.approx(525.0, abs=0.01)
    assert k.cx == pytest.approx(319.5, abs=0.01) and k.cy == pytest.approx(239.5, abs=0.01)


def test_intrinsics_of_a_synthetic_cloud() -> None:
    truth = CameraIntrinsics(300.0, 310.0, 155.0, 118.0, 320, 240)
    rows, cols = np.mgrid[0:240, 0:320].astype(np.float64)
    depth = 1.0 + 0.5 * np.sin(cols / 40.0) + rows / 240.0
    cloud = np.stack([(cols - truth.cx) * depth / truth.fx, (rows - truth.cy) * depth / truth.fy, depth], -1)
    cloud[::7, ::3] = np.nan
    k = intrinsics_from_organized_cloud(cloud)
    for name in ("fx", "fy", "cx", "cy"):
        assert getattr(k, name) == pytest.approx(getattr(truth, name), abs=1e-6)


def test_intrinsics_rejects_unusable_clouds() -> None:
    with pytest.raises(ValueError, match="organized"):
        intrinsics_from_organized_cloud(np.zeros((100, 3)))
    with pytest.raises(ValueError, match="valid pixels"):
        intrinsics_from_organized_cloud(np.full((10, 10, 3), np.nan))


@pytest.mark.parametrize("compressed", [True, False])
@pytest.mark.parametrize("organized", [True, False])
def test_round_trip(tmp_path: Path, person: np.ndarray, compressed: bool, organized: bool) -> None:
    cloud = person if organized else person.reshape(-1, 3)[::7]
    path = tmp_path / "cloud.pcd"
    write_pcd(path, cloud, binary_compressed=compressed)
    back = read_pcd(path)
    assert back.shape == cloud.shape and back.dtype == np.float32
    np.testing.assert_array_equal(back, cloud)  # bit-exact, NaN positions included
    if compressed and organized:
        assert path.stat().st_size < 0.7 * cloud.nbytes  # the NaN runs compress


def test_round_trip_float64_input_is_stored_as_float32(tmp_path: Path) -> None:
    cloud = np.random.default_rng(0).normal(size=(50, 3))
    write_pcd(tmp_path / "c.pcd", cloud, binary_compressed=True)
    np.testing.assert_array_equal(read_pcd(tmp_path / "c.pcd"), cloud.astype(np.float32))


def test_write_rejects_bad_arrays(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="float"):
        write_pcd(tmp_path / "a.pcd", np.zeros((10, 3), np.int32))
    with pytest.raises(ValueError, match="float"):
        write_pcd(tmp_path / "a.pcd", np.zeros((10, 4)))


def test_ascii_with_extra_fields(tmp_path: Path) -> None:
    text = header("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", 2, 2, "ascii")
    text += b"1 2 3 4278190080\nnan nan nan 0\n-1.5 0.25 2e-1 16777215\n0 0 7 42\n"
    path = tmp_path / "a.pcd"
    path.write_bytes(text)
    cloud = read_pcd(path)
    assert cloud.shape == (2, 2, 3)
    np.testing.assert_array_equal(cloud[0, 0], [1, 2, 3])
    assert np.all(np.isnan(cloud[0, 1]))
    np.testing.assert_allclose(cloud[1, 0], [-1.5, 0.25, 0.2])


def test_binary_with_mixed_fields_and_counts(tmp_path: Path) -> None:
    """Fields before/after xyz, a COUNT > 1 field and 8-byte/1-byte types all shift the offsets."""
    n = 5
    rng = np.random.default_rng(1)
    record = np.dtype(
        [("id", "<u2"), ("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("hist", "<f4", (3,)), ("tag", "u1")]
    )
    data = np.zeros(n, record)
    data["id"], data["tag"] = np.arange(n), 7
    data["x"], data["y"], data["z"] = rng.normal(size=(3, n))
    data["hist"] = rng.normal(size=(n, 3))
    head = header("id x y z hist tag", "2 8 8 8 4 1", "U F F F F U", "1 1 1 1 3 1", n, 1, "binary")
    (tmp_path / "b.pcd").write_bytes(head + data.tobytes())
    cloud = read_pcd(tmp_path / "b.pcd")
    assert cloud.shape == (n, 3)
    np.testing.assert_allclose(cloud, np.stack([data["x"], data["y"], data["z"]], 1).astype(np.float32))

    # The same cloud binary_compressed: stored field by field (structure of arrays).
    soa = b"".join(np.ascontiguousarray(data[name]).tobytes() for name in record.names)
    packed = lzf_compress(soa)
    head = header("id x y z hist tag", "2 8 8 8 4 1", "U F F F F U", "1 1 1 1 3 1", n, 1, "binary_compressed")
    (tmp_path / "c.pcd").write_bytes(head + struct.pack("<II", len(packed), len(soa)) + packed)
    np.testing.assert_array_equal(read_pcd(tmp_path / "c.pcd"), cloud)


def test_lzf_round_trip_exercises_all_token_kinds() -> None:
    rng = np.random.default_rng(2)
    data = b"".join(
        [
            rng.integers(0, 256, 100, dtype=np.uint8).tobytes(),  # literals (several 32-byte runs)
            b"\x00\x00\xc0\x7f" * 400,  # NaN floats: long overlapping back-references
            b"abcd" * 3,  # short back-reference
            rng.integers(0, 256, 5, dtype=np.uint8).tobytes(),
        ]
    )
    packed = lzf_compress(data)
    assert len(packed) < len(data) / 3
    assert lzf_decompress(packed, len(data)) == data
    # A hand-made stream: literal "ab", then copy 5 bytes from distance 2 (overlapping): "ababababa".
    assert lzf_decompress(bytes([1]) + b"ab" + bytes([(3 << 5) | 0, 1]), 7) == b"abababa"


@pytest.mark.parametrize(
    ("stream", "size", "match"),
    [
        (bytes([5]) + b"abc", 6, "literal"),  # literal run past the end
        (bytes([0]) + b"a" + bytes([(1 << 5) | 0, 9]), 4, "before the start"),  # distance 10 > 1
        (bytes([0]) + b"a" + bytes([7 << 5]), 12, "back-reference"),  # truncated long token
        (bytes([2]) + b"abc", 4, "header says"),  # size mismatch
    ],
)
def test_lzf_rejects_corrupt_streams(stream: bytes, size: int, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        lzf_decompress(stream, size)


def test_truncated_and_corrupt_files_raise_value_error(tmp_path: Path) -> None:
    raw = PERSON_PCD.read_bytes()
    data_at = raw.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    cases = {
        "header_only": raw[:data_at],
        "size_words_cut": raw[: data_at + 5],
        "payload_cut": raw[: data_at + 8 + 1000],
        "no_data_line": raw[:120],
        "corrupt_payload": raw[: data_at + 8] + bytes([255, 255, 255]) + raw[data_at + 11 :],
        "bad_type": raw.replace(b"TYPE F F F", b"TYPE X F F", 1),
        "no_z": raw.replace(b"FIELDS x y z", b"FIELDS x y w", 1),
        "points_mismatch": raw.replace(b"POINTS 307200", b"POINTS 307201", 1),
        "bad_mode": raw.replace(b"DATA binary_compressed", b"DATA binary_zipped", 1),
        "not_pcd": b"\x89PNG\r\n\x1a\n" + bytes(200),
    }
    for name, content in cases.items():
        path = tmp_path / f"{name}.pcd"
        path.write_bytes(content)
        with pytest.raises(ValueError):
            read_pcd(path)
    binary = tmp_path / "binary.pcd"
    write_pcd(binary, np.zeros((10, 3), np.float32), binary_compressed=False)
    binary.write_bytes(binary.read_bytes()[:-4])
    with pytest.raises(ValueError, match="truncated"):
        read_pcd(binary)
    ascii_path = tmp_path / "ascii.pcd"
    ascii_path.write_bytes(header("x y z", "4 4 4", "F F F", "1 1 1", 2, 1, "ascii") + b"1 2 3\n4 5\n")
    with pytest.raises(ValueError, match="values"):
        read_pcd(ascii_path)
    with pytest.raises(OSError):
        read_pcd(tmp_path / "missing.pcd")


def test_reading_the_1mb_compressed_cloud_is_fast_enough() -> None:
    start = time.perf_counter()
    read_pcd(PERSON_PCD)
    assert time.perf_counter() - start < 3.0  # ~0.35 s on one core; generous for loaded CI machines
