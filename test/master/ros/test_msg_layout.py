"""The one definition of the raw-CDR messages' layouts (common.msg_layout) against rclpy: the fields are the
messages' own, in order; random messages (every field set) decode from rclpy's serialize_message bytes, and
encode to bytes of the same length that rclpy reads back as the same message (rclpy does not zero its padding
bytes: they are not compared)."""

from __future__ import annotations

import importlib
import struct

import numpy as np
import pytest

from face_reid_camera.common import msg_layout as ml

rclpy_serialization = pytest.importorskip("rclpy.serialization")
msgs = pytest.importorskip("face_reid_msgs.msg")

_TEXT = ["", "a", "ab", "abc", "abcd", "world", "cam_07", "kamera-ø", "✓✓", "x" * 9]
_INTS = {"octet": (0, 2**8), "uint8": (0, 2**8), "int32": (-(2**31), 2**31), "uint32": (0, 2**32),
         "uint64": (0, 2**64)}
_RCL_TYPES = {"bool": "boolean", "float32": "float", "float64": "double", "uint8": "uint8", "int32": "int32",
              "uint32": "uint32", "uint64": "uint64", "string": "string"}


def _class(type_name: str) -> type:
    pkg, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _random(rng: np.random.Generator, kind: str) -> object:
    if kind == "boolean":
        return bool(rng.random() < 0.5)
    if kind in _INTS:
        lo, hi = _INTS[kind]
        return int(rng.integers(lo, hi, dtype=np.uint64 if kind == "uint64" else np.int64))
    if kind == "float":
        return float(np.float32(rng.normal() * 100))
    if kind == "double":
        return float(rng.normal() * 1e3)
    if kind == "string":
        return str(rng.choice(_TEXT))
    raise AssertionError(kind)


def _fill(rng: np.random.Generator, msg: object) -> object:
    """Every field of ``msg`` (a rosidl message) set at random, nested and sequence elements too, from rclpy's
    own description of the type (not msg_layout's)."""
    for name, kind in msg.get_fields_and_field_types().items():
        if kind.startswith("sequence<"):
            inner = kind[len("sequence<"):-1]
            items = [_fill(rng, _class(inner)()) if "/" in inner else _random(rng, inner)
                     for _ in range(int(rng.choice([0, 1, 2, 3, 5])))]
            setattr(msg, name, items)
        elif kind.endswith("]"):
            inner, n = kind[:-1].split("[")
            setattr(msg, name, [_random(rng, inner) for _ in range(int(n))])
        elif "/" in kind:
            _fill(rng, getattr(msg, name))
        else:
            setattr(msg, name, _random(rng, kind))
    return msg


def _values(msg: object) -> dict:
    """A rosidl message as msg_layout's nested dicts (sequences and arrays as lists)."""
    out = {}
    for name, kind in msg.get_fields_and_field_types().items():
        value = getattr(msg, name)
        if "/" in kind and kind.startswith("sequence<"):
            value = [_values(v) for v in value]
        elif "/" in kind:
            value = _values(value)
        elif kind.startswith("sequence<") or kind.endswith("]"):
            value = [v.item() if hasattr(v, "item") else v for v in value]
        out[name] = value
    return out


def _rcl_type(ftype: object) -> str:
    if isinstance(ftype, ml.Msg):
        return ftype.name
    if isinstance(ftype, ml.Seq):
        return f"sequence<{_rcl_type(ftype.element)}>"
    if isinstance(ftype, ml.Array):
        return f"{_RCL_TYPES[ftype.element]}[{ftype.length}]"
    return _RCL_TYPES[ftype]


@pytest.mark.parametrize("definition", [ml.CAMERA_FRAME, ml.PERSON_OBSERVATION, ml.NAMED_TRACK_ARRAY, ml.NAMED_TRACK,
                                        ml.HEADER, ml.POSE, ml.ROI],
                         ids=lambda d: d.name)
def test_the_definition_has_the_messages_fields_in_order(definition: ml.Msg) -> None:
    fields = _class(definition.name)().get_fields_and_field_types()
    assert [(n, _rcl_type(t)) for n, t in definition.fields] == list(fields.items())


@pytest.mark.parametrize("definition", [ml.CAMERA_FRAME, ml.NAMED_TRACK_ARRAY], ids=lambda d: d.name)
def test_random_messages_decode_from_and_encode_to_rclpys_bytes(definition: ml.Msg) -> None:
    rng = np.random.default_rng(3)
    for _ in range(150):
        msg = _fill(rng, _class(definition.name)())
        data = rclpy_serialization.serialize_message(msg)
        assert ml.decode(definition, data) == _values(msg)
        encoded = ml.encode(definition, _values(msg))  # rclpy leaves its padding bytes as they were: compare values
        assert len(encoded) == len(data) and rclpy_serialization.deserialize_message(encoded, type(msg)) == msg


def test_the_derived_structs_are_the_wire_layout() -> None:
    """The runs a reader unpacks and the packing a writer uses sit where rclpy puts those fields."""
    rng = np.random.default_rng(5)
    msg = _fill(rng, msgs.NamedTrack())
    msg.cameras = ["cam_a", "kamera-ø"]
    array = msgs.NamedTrackArray(tracks=[msg])
    array.header.frame_id = "world"
    data = rclpy_serialization.serialize_message(array)
    head = ml.packing(ml.NAMED_TRACK_ARRAY, (5, 1))
    assert head.unpack_from(data, 4) == (array.header.stamp.sec, array.header.stamp.nanosec, 6, b"world\x00", 1)
    track = ml.packing(ml.NAMED_TRACK, (len(msg.name.encode()), len(msg.identity_evidence.encode()), 2, 5, 9))
    start = 4 + head.size + (-head.size % ml.first_alignment(ml.NAMED_TRACK))
    values = track.unpack_from(data, start)
    assert values[0] == msg.track_id and values[1] == msg.face_id and values[-1] == "kamera-ø".encode() + b"\x00"
    assert start + track.size == len(data)
    first = ml.segments(ml.CAMERA_FRAME)[0]
    assert first.names == ("header.stamp.sec", "header.stamp.nanosec") and first.struct.format == "<iI"
    assert struct.calcsize("<" + "d" * 3) == 24
