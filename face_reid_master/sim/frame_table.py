"""Simulated camera messages in columns: per camera and day while simulating, then one flat frame table.

The flat table is what ``frames.npz`` stores (:mod:`face_reid_master.sim.scenario_files`): frames in stamp
order (ties: camera order), the detections of each frame (shuffled within it), the faces in detection order,
and (with bodies, ``--bodies``) the bodies in detection order.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.sim.streams import S_SHUFFLE, stream_rng

__all__ = ["BodyRows", "DetectionColumns", "FrameTable", "assemble_frames"]


@dataclass(frozen=True)
class BodyRows:
    """Body rows of some detections: projected descriptor (m, k) (zeros where not ``described``), visible
    fraction, per-part visibility (m, parts), geometry (m, 6) in GEOMETRY_FIELDS order (NaN = not measured),
    the crop shown (index into the scenario's crops list, -1 unknown), the true view angle (deg, the person's
    facing relative to the direction to the camera, counter-clockwise; NaN unknown) and the body glance."""

    descriptor: NDArray[np.float32]
    described: NDArray[np.bool_]
    visible: NDArray[np.float32]
    part_visible: NDArray[np.float32]
    geometry: NDArray[np.float32]
    crop: NDArray[np.int32]
    view_deg: NDArray[np.float32]
    glance: NDArray[np.int32]

    @staticmethod
    def empty(dim: int, parts: int) -> BodyRows:
        return BodyRows(np.zeros((0, dim), np.float32), np.zeros(0, bool), np.zeros(0, np.float32),
                        np.zeros((0, parts), np.float32), np.zeros((0, 6), np.float32), np.zeros(0, np.int32),
                        np.zeros(0, np.float32), np.zeros(0, np.int32))

    @staticmethod
    def concat(rows: list[BodyRows]) -> BodyRows:
        return BodyRows(*(np.concatenate([getattr(r, f) for r in rows]) for f in _BODY_ROW_FIELDS))

    def take(self, index: NDArray[np.integer]) -> BodyRows:
        return BodyRows(*(getattr(self, f)[index] for f in _BODY_ROW_FIELDS))

    def arrays(self) -> dict[str, NDArray[Any]]:
        """The frames.npz arrays: ``body_<field>``."""
        return {f"body_{f}": getattr(self, f) for f in _BODY_ROW_FIELDS}


_BODY_ROW_FIELDS = ("descriptor", "described", "visible", "part_visible", "geometry", "crop", "view_deg", "glance")


@dataclass
class DetectionColumns:
    """Detections of one camera over one day, columnar (frame = index into that camera's stamps)."""

    frame: list[NDArray[np.int64]] = field(default_factory=list)
    gt: list[NDArray[np.int32]] = field(default_factory=list)
    position: list[NDArray[np.float64]] = field(default_factory=list)
    std: list[NDArray[np.float32]] = field(default_factory=list)
    height: list[NDArray[np.float32]] = field(default_factory=list)
    has_face: list[NDArray[np.bool_]] = field(default_factory=list)
    embedding: list[NDArray[np.float32]] = field(default_factory=list)  # rows only for faces
    face_score: list[NDArray[np.float32]] = field(default_factory=list)
    face_quality: list[NDArray[np.float32]] = field(default_factory=list)
    face_photo: list[NDArray[np.int32]] = field(default_factory=list)
    face_glance: list[NDArray[np.int32]] = field(default_factory=list)
    face_variant: list[NDArray[np.int16]] = field(default_factory=list)
    face_eye_px: list[NDArray[np.float32]] = field(default_factory=list)
    dim: int = 128  # embedding length (256 for a camera running both embedders)
    has_body: list[NDArray[np.bool_]] = field(default_factory=list)  # per batch, with bodies only
    bodies: list[BodyRows] = field(default_factory=list)  # rows for the detections with a body

    def append(self, frame: NDArray[Any], gt: NDArray[Any], pos: NDArray[Any], std: NDArray[Any],
               height: NDArray[Any], has_face: NDArray[Any], emb: NDArray[Any], score: NDArray[Any],
               quality: NDArray[Any], photo: NDArray[Any], glance: NDArray[Any], variant: NDArray[Any],
               eye_px: NDArray[Any] | None = None) -> None:
        """Add a batch of detections (the face columns hold rows for the detections with a face only;
        ``eye_px`` None: face size unknown, 0)."""
        self.frame.append(np.asarray(frame, dtype=np.int64))
        self.gt.append(np.asarray(gt, dtype=np.int32))
        self.position.append(np.asarray(pos, dtype=np.float64).reshape(-1, 3))
        self.std.append(np.asarray(std, dtype=np.float32))
        self.height.append(np.asarray(height, dtype=np.float32))
        self.has_face.append(np.asarray(has_face, dtype=bool))
        self.embedding.append(np.asarray(emb, dtype=np.float32).reshape(-1, self.dim))
        self.face_score.append(np.asarray(score, dtype=np.float32))
        self.face_quality.append(np.asarray(quality, dtype=np.float32))
        self.face_photo.append(np.asarray(photo, dtype=np.int32))
        self.face_glance.append(np.asarray(glance, dtype=np.int32))
        self.face_variant.append(np.asarray(variant, dtype=np.int16))
        n_faces = self.face_variant[-1].size
        self.face_eye_px.append(np.zeros(n_faces, np.float32) if eye_px is None else
                                np.asarray(eye_px, dtype=np.float32).reshape(n_faces))

    def append_bodies(self, has_body: NDArray[Any], rows: BodyRows) -> None:
        """The bodies of the batch added last by :meth:`append` (every batch gets one call, or none does)."""
        flags = np.asarray(has_body, dtype=bool)
        if flags.size != self.frame[-1].size or int(flags.sum()) != rows.described.size:
            raise ValueError(f"has_body ({flags.size}, {int(flags.sum())} set) does not match the last batch "
                             f"({self.frame[-1].size}) and its {rows.described.size} body rows")
        self.has_body.append(flags)
        self.bodies.append(rows)


@dataclass
class FrameTable:
    """All frames of the scenario, flat (what frames.npz stores)."""

    camera: NDArray[np.int16]
    stamp_s: NDArray[np.float64]
    offsets: NDArray[np.int64]
    det: dict[str, NDArray[Any]]
    face: dict[str, NDArray[Any]]
    body: BodyRows | None = None  # with bodies: rows in detection order, det["body"] indexes them


def assemble_frames(per_camera: list[tuple[int, NDArray[np.float64], DetectionColumns]], seed: int,
                    body_shape: tuple[int, int] | None = None) -> FrameTable:
    """Merge the cameras' columns into one frame table in stamp order, detections shuffled within frames.

    ``body_shape`` (descriptor length, parts): the scenario has bodies (every batch has its body columns).
    """
    frame_cam, frame_stamp, frame_key = [], [], []
    det_parts: dict[str, list[NDArray[Any]]] = {k: [] for k in ("frame", "gt", "position", "std", "height", "face")}
    face_parts: dict[str, list[NDArray[Any]]] = {k: [] for k in ("embedding", "score", "quality", "photo", "glance",
                                                                  "variant", "eye_px")}
    dim = next((cols.dim for _, _, cols in per_camera), 128)
    n_frames = 0
    n_faces = 0
    with_bodies = body_shape is not None
    body_flags: list[NDArray[np.bool_]] = []
    body_rows: list[BodyRows] = []
    for cam_index, stamps, cols in per_camera:
        if with_bodies and len(cols.has_body) != len(cols.frame):
            raise ValueError(f"camera {cam_index}: {len(cols.frame)} detection batches, {len(cols.has_body)} with "
                             "bodies (all or none must have them)")
        body_flags.extend(cols.has_body)
        body_rows.extend(cols.bodies)
        frame_cam.append(np.full(stamps.size, cam_index, dtype=np.int16))
        frame_stamp.append(stamps)
        frame_key.append(np.arange(stamps.size) + n_frames)
        for i in range(len(cols.frame)):
            det_parts["frame"].append(cols.frame[i] + n_frames)
            det_parts["gt"].append(cols.gt[i])
            det_parts["position"].append(cols.position[i])
            det_parts["std"].append(cols.std[i])
            det_parts["height"].append(cols.height[i])
            face_row = np.full(cols.has_face[i].size, -1, dtype=np.int64)
            k = int(cols.has_face[i].sum())
            face_row[cols.has_face[i]] = np.arange(k) + n_faces
            n_faces += k
            det_parts["face"].append(face_row)
            face_parts["embedding"].append(cols.embedding[i])
            face_parts["score"].append(cols.face_score[i])
            face_parts["quality"].append(cols.face_quality[i])
            face_parts["photo"].append(cols.face_photo[i])
            face_parts["glance"].append(cols.face_glance[i])
            face_parts["variant"].append(cols.face_variant[i])
            face_parts["eye_px"].append(cols.face_eye_px[i])
        n_frames += stamps.size
    cam = np.concatenate(frame_cam) if frame_cam else np.zeros(0, np.int16)
    stamp = np.concatenate(frame_stamp) if frame_stamp else np.zeros(0)
    order = np.lexsort((cam, stamp))  # by stamp, then camera
    new_index = np.empty(order.size, dtype=np.int64)
    new_index[order] = np.arange(order.size)

    def cat(parts: list[NDArray[Any]], dtype: Any, width: int = 0) -> NDArray[Any]:
        if parts:
            return np.concatenate(parts).astype(dtype)
        return np.zeros((0, width) if width else 0, dtype=dtype)

    det_frame = new_index[cat(det_parts["frame"], np.int64)]
    shuffle = stream_rng(seed, S_SHUFFLE).random(det_frame.size)
    det_order = np.lexsort((shuffle, det_frame))
    det = {
        "position": cat(det_parts["position"], np.float64, 3)[det_order],
        "std_m": cat(det_parts["std"], np.float32)[det_order],
        "height_m": cat(det_parts["height"], np.float32)[det_order],
        "gt_id": cat(det_parts["gt"], np.int32)[det_order],
    }
    face_row = cat(det_parts["face"], np.int64)[det_order]
    # renumber faces in detection order
    has = face_row >= 0
    face_order = face_row[has]
    det_face = np.full(face_row.size, -1, dtype=np.int32)
    det_face[has] = np.arange(face_order.size, dtype=np.int32)
    det["face"] = det_face
    face = {
        "embedding": cat(face_parts["embedding"], np.float32, dim)[face_order],
        "score": cat(face_parts["score"], np.float32)[face_order],
        "quality": cat(face_parts["quality"], np.float32)[face_order],
        "photo": cat(face_parts["photo"], np.int32)[face_order],
        "glance": cat(face_parts["glance"], np.int32)[face_order],
        "variant": cat(face_parts["variant"], np.int16)[face_order],
        "eye_px": cat(face_parts["eye_px"], np.float32)[face_order],
    }
    counts = np.bincount(det_frame, minlength=order.size)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    body = None
    if with_bodies:
        flags = cat(body_flags, bool)
        assert body_shape is not None
        rows = BodyRows.concat([BodyRows.empty(*body_shape), *body_rows])
        body_row = np.full(flags.size, -1, dtype=np.int64)
        body_row[flags] = np.arange(int(flags.sum()))
        body_row = body_row[det_order]
        has_b = body_row >= 0
        det["body"] = np.full(body_row.size, -1, dtype=np.int32)
        det["body"][has_b] = np.arange(int(has_b.sum()), dtype=np.int32)
        body = rows.take(body_row[has_b])
    return FrameTable(cam[order], stamp[order], offsets, det, face, body)
