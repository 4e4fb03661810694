"""The CDR layouts of the messages read or written as raw bytes, from one definition of their fields.

Each message is described once, its fields in the order of its .msg file (:data:`CAMERA_FRAME`,
:data:`PERSON_OBSERVATION`, :data:`NAMED_TRACK_ARRAY`, :data:`NAMED_TRACK` and the standard messages they hold);
the readers and writers (face_reid_master.ros.frame_cdr, .track_cdr) take their ``struct`` formats, paddings and
field order from here (:func:`segments`, :func:`packing`) and never write an offset by hand. Plain CDR, little
endian (what Fast DDS sends): each primitive aligned to its size from the end of the 4-byte encapsulation
header. :func:`decode` / :func:`encode` read / write any described message as nested dicts (slow, generic: the
tests compare them with rclpy's ``serialize_message`` on random messages, every field). Pure Python, no rclpy.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Union

__all__ = [
    "CAMERA_FRAME", "ENCAPSULATION_LE", "HEADER", "NAMED_TRACK", "NAMED_TRACK_ARRAY", "PERSON_OBSERVATION", "Array",
    "Fixed", "Msg", "Seq", "Strings", "decode", "encode", "first_alignment", "packing", "segments",
]

ENCAPSULATION_LE = b"\x00\x01\x00\x00"  # plain CDR, little endian; options 0
PRIMITIVES: dict[str, tuple[str, int]] = {  # .msg type -> (struct code, size = alignment)
    "bool": ("?", 1), "uint8": ("B", 1), "int32": ("i", 4), "uint32": ("I", 4), "float32": ("f", 4),
    "float64": ("d", 8), "uint64": ("Q", 8),
}


@dataclass(frozen=True)
class Msg:
    """A message type: its name and its fields (name, type) in .msg order."""

    name: str
    fields: tuple[tuple[str, FieldType], ...]


@dataclass(frozen=True)
class Seq:
    """An unbounded sequence (``T[]``): a uint32 count, then the elements."""

    element: FieldType


@dataclass(frozen=True)
class Array:
    """A fixed-size array (``T[n]``) of a primitive: no count."""

    element: str
    length: int


FieldType = Union[str, Msg, Seq, Array]  # noqa: UP007  (a runtime alias: dataclass fields above refer to it)


def _msg(name: str, *fields: tuple[str, FieldType]) -> Msg:
    return Msg(name, tuple(fields))


TIME = _msg("builtin_interfaces/Time", ("sec", "int32"), ("nanosec", "uint32"))
HEADER = _msg("std_msgs/Header", ("stamp", TIME), ("frame_id", "string"))
POINT = _msg("geometry_msgs/Point", ("x", "float64"), ("y", "float64"), ("z", "float64"))
VECTOR3 = _msg("geometry_msgs/Vector3", ("x", "float64"), ("y", "float64"), ("z", "float64"))
QUATERNION = _msg("geometry_msgs/Quaternion", ("x", "float64"), ("y", "float64"), ("z", "float64"), ("w", "float64"))
POSE = _msg("geometry_msgs/Pose", ("position", POINT), ("orientation", QUATERNION))
ROI = _msg("sensor_msgs/RegionOfInterest", ("x_offset", "uint32"), ("y_offset", "uint32"), ("height", "uint32"),
           ("width", "uint32"), ("do_rectify", "bool"))

PERSON_OBSERVATION = _msg(
    "face_reid_msgs/PersonObservation",
    ("position_world", POINT), ("position_camera", POINT), ("position_std_m", "float32"), ("height_m", "float32"),
    ("num_points", "uint32"), ("head_roi", ROI), ("face_found", "bool"), ("face_score", "float32"),
    ("face_box", ROI), ("face_quality", "float32"), ("face_yaw_deg", "float32"), ("face_eye_distance_px", "float32"),
    ("embedding", Seq("float32")), ("embedding_space", "string"), ("body_descriptor", Seq("float32")),
    ("body_descriptor_space", "string"), ("body_visible_fraction", "float32"), ("body_part_visible", Seq("float32")),
    ("body_head_height_m", "float32"), ("body_shoulder_width_m", "float32"), ("body_torso_width_m", "float32"),
    ("body_hip_width_m", "float32"), ("body_torso_depth_m", "float32"), ("body_part_widths_m", Seq("float32")),
)
CAMERA_FRAME = _msg(
    "face_reid_msgs/CameraFrame",
    ("header", HEADER), ("camera_id", "string"), ("camera_frame_id", "string"), ("camera_pose", POSE),
    ("ground_plane_found", "bool"), ("processing_time_ms", "float32"), ("frames_dropped", "uint32"),
    ("people", Seq(PERSON_OBSERVATION)),
)
NAMED_TRACK = _msg(
    "face_reid_msgs/NamedTrack",
    ("track_id", "uint64"), ("face_id", "uint64"), ("name", "string"), ("identity_confidence", "float32"),
    ("face_observations", "uint32"), ("identity_evidence", "string"), ("position", POINT), ("velocity", VECTOR3),
    ("covariance", Array("float64", 16)), ("height_m", "float32"), ("state", "uint8"), ("first_seen", TIME),
    ("last_seen", TIME), ("cameras", Seq("string")),
)
NAMED_TRACK_ARRAY = _msg("face_reid_msgs/NamedTrackArray", ("header", HEADER), ("tracks", Seq(NAMED_TRACK)))


# ---------------------------------------------------------------------------------------------- the leaves
def _leaves(msg: Msg, prefix: str = "") -> Iterator[tuple[str, FieldType]]:
    """The message's fields flattened in wire order: (dotted path, primitive / 'string' / Seq / Array)."""
    for name, ftype in msg.fields:
        if isinstance(ftype, Msg):
            yield from _leaves(ftype, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", ftype


def first_alignment(msg: Msg) -> int:
    """The alignment of the message's first field on the wire (where an element of a sequence of it starts)."""
    _, ftype = next(_leaves(msg))
    if isinstance(ftype, Array):
        return PRIMITIVES[ftype.element][1]
    return PRIMITIVES[ftype][1] if isinstance(ftype, str) and ftype != "string" else 4


# ---------------------------------------------------------------------------------------------- readers' segments
@dataclass(frozen=True)
class Fixed:
    """A run of fixed-size fields read with one ``struct`` (paddings included) from a start aligned to
    ``start_align``; ``names`` the values it unpacks, in order (skipped fields are padding)."""

    struct: struct.Struct
    names: tuple[str, ...]
    start_align: int

    def index(self, name: str) -> int:
        return self.names.index(name)


@dataclass(frozen=True)
class Strings:
    """A variable-size field: 'string', or a Seq (of a primitive, of strings, of messages)."""

    name: str
    type: FieldType


def segments(msg: Msg, skip: Sequence[str] = ()) -> tuple[Fixed | Strings, ...]:
    """The message as a reader walks it: runs of fixed-size fields (one struct each; the fields under a ``skip``
    prefix are padding, not unpacked) between the variable-size fields. Each run starts aligned to its first
    field (the reader aligns there); within it the paddings follow from that."""
    out: list[Fixed | Strings] = []
    fmt: list[str] = []
    names: list[str] = []
    offset = start = 0

    def close() -> None:
        nonlocal fmt, names
        if fmt:
            out.append(Fixed(struct.Struct("<" + "".join(fmt)), tuple(names), start))
        fmt, names = [], []

    for path, ftype in _leaves(msg):
        if isinstance(ftype, Seq) or ftype == "string":
            close()
            out.append(Strings(path, ftype))
            continue
        code, size = (PRIMITIVES[ftype.element] if isinstance(ftype, Array) else PRIMITIVES[ftype])  # type: ignore[index]
        count = ftype.length if isinstance(ftype, Array) else 1
        if not fmt:
            offset, start = 0, size
        elif gap := -offset % size:
            fmt.append(f"{gap}x")
            offset += gap
        skipped = any(path == s or path.startswith(s + ".") for s in skip)
        fmt.append(f"{size * count}x" if skipped else f"{count}{code}" if count > 1 else code)
        offset += size * count
        if not skipped:
            names.extend([path] if count == 1 else [f"{path}[{i}]" for i in range(count)])
    close()
    return tuple(out)


# ---------------------------------------------------------------------------------------------- writers' packing
def packing(msg: Msg, lengths: Sequence[int], raw_arrays: bool = True, stop_at_messages: bool = True) -> struct.Struct:
    """The one ``struct`` that writes ``msg`` from a start aligned to :func:`first_alignment` (8 for a uint64),
    given ``lengths``: for each string its UTF-8 byte length, for each sequence its count (then its elements'),
    in wire order. A string packs as (length + 1, bytes: struct pads the NUL); a fixed array of a primitive as
    its raw bytes (``raw_arrays``); a sequence of messages stops the packing at its count (``stop_at_messages``:
    the writer packs each element on its own)."""
    parts = ["<"]
    offset = 0
    it = iter(lengths)

    def pad(size: int) -> None:
        nonlocal offset
        if gap := -offset % size:
            parts.append(f"{gap}x")
            offset += gap

    def field(ftype: FieldType) -> bool:
        nonlocal offset
        if ftype == "string":
            n = next(it)
            pad(4)
            parts.append(f"I{n + 1}s")
            offset += 4 + n + 1
        elif isinstance(ftype, Seq):
            count = next(it)
            pad(4)
            parts.append("I")
            offset += 4
            if isinstance(ftype.element, Msg):
                if stop_at_messages:
                    return False
                for _ in range(count):
                    for _, sub in _leaves(ftype.element):
                        field(sub)
            else:
                for _ in range(count):
                    field(ftype.element)
        elif isinstance(ftype, Array):
            code, size = PRIMITIVES[ftype.element]
            pad(size)
            parts.append(f"{size * ftype.length}s" if raw_arrays else f"{ftype.length}{code}")
            offset += size * ftype.length
        else:
            code, size = PRIMITIVES[ftype]  # type: ignore[index]
            pad(size)
            parts.append(code)
            offset += size
        return True

    for _, ftype in _leaves(msg):
        if not field(ftype):
            break
    return struct.Struct("".join(parts))


# ---------------------------------------------------------------------------------------------- generic read / write
class _Reader:
    def __init__(self, data: bytes) -> None:
        self.b, self.o = memoryview(data), 4

    def align(self, size: int) -> None:
        self.o += -(self.o - 4) % size

    def prim(self, ftype: str) -> Any:
        code, size = PRIMITIVES[ftype]
        self.align(size)
        (value,) = struct.unpack_from("<" + code, self.b, self.o)
        self.o += size
        return value

    def read(self, ftype: FieldType) -> Any:
        if isinstance(ftype, Msg):
            return {name: self.read(sub) for name, sub in ftype.fields}
        if isinstance(ftype, Seq):
            return [self.read(ftype.element) for _ in range(self.prim("uint32"))]
        if isinstance(ftype, Array):
            return [self.prim(ftype.element) for _ in range(ftype.length)]
        if ftype == "string":
            n = self.prim("uint32")
            text = str(self.b[self.o:self.o + n - 1], "utf-8")
            self.o += n
            return text
        return self.prim(ftype)


def decode(msg: Msg, data: bytes) -> dict[str, Any]:
    """The message's fields as nested dicts (sequences and arrays as lists) from its plain little-endian CDR."""
    if data[:2] != ENCAPSULATION_LE[:2]:
        raise ValueError("not a little-endian plain-CDR message")
    return _Reader(data).read(msg)


def encode(msg: Msg, values: dict[str, Any]) -> bytes:
    """The plain little-endian CDR of ``values`` (nested dicts as :func:`decode` gives) as ``msg``."""
    out = bytearray(ENCAPSULATION_LE)

    def prim(ftype: str, value: Any) -> None:
        code, size = PRIMITIVES[ftype]
        out.extend(bytes(-(len(out) - 4) % size))
        out.extend(struct.pack("<" + code, value))

    def write(ftype: FieldType, value: Any) -> None:
        if isinstance(ftype, Msg):
            for name, sub in ftype.fields:
                write(sub, value[name])
        elif isinstance(ftype, Seq):
            prim("uint32", len(value))
            for item in value:
                write(ftype.element, item)
        elif isinstance(ftype, Array):
            for item in value:
                prim(ftype.element, item)
        elif ftype == "string":
            raw = value.encode("utf-8")
            prim("uint32", len(raw) + 1)
            out.extend(raw + b"\x00")
        else:
            prim(ftype, value)

    write(msg, values)
    return bytes(out)
