"""Conversions between the master core's records and ROS messages (message classes only, no rclpy)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from face_reid_camera.body.observation import GEOMETRY_MSG_FIELDS
from face_reid_camera.common.embedding_spaces import DLIB_SPACE as LEGACY_EMBEDDING_SPACE
from face_reid_camera.common.stamps import set_stamp, stamp_to_seconds
from face_reid_master.records import STATE_LOST, BodyRecord, CameraFrameRecord, NamedTrackRecord, PersonRecord


def _body_from_msg(p: Any) -> BodyRecord | None:
    """The body fields of a PersonObservation (None: the camera sent none, e.g. one from before bodies)."""
    descriptor = np.asarray(p.body_descriptor, dtype=np.float32)
    if not descriptor.size and not p.body_visible_fraction:
        return None
    geometry = np.array([getattr(p, name) for name in GEOMETRY_MSG_FIELDS], dtype=np.float32)
    return BodyRecord(descriptor, str(p.body_descriptor_space), float(p.body_visible_fraction), geometry,
                      np.asarray(p.body_part_visible, dtype=np.float32),
                      np.asarray(p.body_part_widths_m, dtype=np.float32))


def frame_from_msg(msg: Any) -> CameraFrameRecord:
    """CameraFrame message -> core record (no validation: the core validates and counts)."""
    people = []
    for p in msg.people:
        emb = np.asarray(p.embedding, dtype=np.float32) if p.face_found and len(p.embedding) else None
        people.append(
            PersonRecord(
                np.array([p.position_world.x, p.position_world.y, p.position_world.z]),
                float(p.position_std_m), float(p.height_m), emb, float(p.face_score), float(p.face_quality),
                # an empty space: a camera from before spaces were named, which ran the dlib embedder
                str(p.embedding_space) or LEGACY_EMBEDDING_SPACE, float(p.face_eye_distance_px), _body_from_msg(p),
            )
        )
    return CameraFrameRecord(msg.camera_id, stamp_to_seconds(msg.header.stamp), tuple(people), msg.header.frame_id)


def frame_record_to_msg(frame: CameraFrameRecord, stamp_s: float) -> Any:
    """A core record -> face_reid_msgs/CameraFrame stamped ``stamp_s`` (the inverse of :func:`frame_from_msg`;
    replays recorded frames, e.g. ``face-reid-eval --live``)."""
    from face_reid_msgs.msg import CameraFrame, PersonObservation

    msg = CameraFrame()
    set_stamp(msg.header.stamp, stamp_s)
    msg.header.frame_id = frame.frame_id
    msg.camera_id = frame.camera_id
    for person in frame.people:
        m = PersonObservation()
        m.position_world.x, m.position_world.y, m.position_world.z = (float(v) for v in person.position_world)
        m.position_std_m = float(person.position_std_m)
        m.height_m = float(person.height_m)
        if person.embedding is not None:
            m.face_found = True
            m.face_score = float(person.face_score)
            m.face_quality = float(person.face_quality)
            m.embedding = np.asarray(person.embedding, dtype=np.float32).tolist()
            m.embedding_space = person.embedding_space
            m.face_eye_distance_px = float(person.face_eye_distance_px)
        body = person.body
        if body is not None:
            m.body_descriptor = np.asarray(body.descriptor, dtype=np.float32).tolist()
            m.body_descriptor_space = body.space if body.descriptor.size else ""
            m.body_visible_fraction = float(body.visible_fraction)
            m.body_part_visible = np.asarray(body.part_visible, dtype=np.float32).tolist()
            m.body_part_widths_m = np.asarray(body.part_widths_m, dtype=np.float32).tolist()
            for name, value in zip(GEOMETRY_MSG_FIELDS, np.asarray(body.geometry, dtype=np.float32), strict=True):
                if name != "height_m":  # the detection's own height
                    setattr(m, name, float(value))
        msg.people.append(m)
    return msg


def track_from_msg(t: Any, to_seconds: Callable[[float], float] | None = None) -> NamedTrackRecord:
    """A face_reid_msgs/NamedTrack -> record (the inverse of :func:`tracks_to_msg` for one track); ``to_seconds``
    maps its stamps (default: seconds as stamped). ValueError/TypeError for a malformed one."""
    def secs(stamp: Any) -> float:
        value = stamp_to_seconds(stamp)
        return to_seconds(value) if to_seconds is not None else value

    return NamedTrackRecord(
        int(t.track_id), int(t.face_id), str(t.name), float(t.identity_confidence), int(t.face_observations),
        np.array([t.position.x, t.position.y], dtype=np.float64), np.array([t.velocity.x, t.velocity.y],
                                                                           dtype=np.float64),
        np.asarray(t.covariance, dtype=np.float64).reshape(4, 4), float(t.height_m), int(t.state),
        secs(t.first_seen), secs(t.last_seen), tuple(t.cameras), str(t.identity_evidence),
    )


def tracks_to_msg(tracks: list[NamedTrackRecord], stamp_s: float, frame_id: str) -> Any:
    """Core tracks -> face_reid_msgs/NamedTrackArray (the master publishes the same message serialized by
    :func:`face_reid_master.ros.track_cdr.tracks_to_cdr`)."""
    from face_reid_msgs.msg import NamedTrack, NamedTrackArray

    out = NamedTrackArray()
    out.header.frame_id = frame_id
    set_stamp(out.header.stamp, max(0.0, stamp_s))
    for tr in tracks:
        m = NamedTrack()
        m.track_id, m.face_id, m.name = int(tr.track_id), int(tr.face_id), tr.name
        m.identity_confidence = float(tr.identity_confidence)
        m.face_observations = int(tr.face_observations)
        m.identity_evidence = tr.identity_evidence
        m.position.x, m.position.y = float(tr.position_xy[0]), float(tr.position_xy[1])
        m.velocity.x, m.velocity.y = float(tr.velocity_xy[0]), float(tr.velocity_xy[1])
        m.covariance = np.asarray(tr.covariance, dtype=np.float64).reshape(16)  # the setter copies it
        m.height_m = float(tr.height_m) if math.isfinite(tr.height_m) else 0.0
        m.state = int(tr.state)
        set_stamp(m.first_seen, max(0.0, tr.first_seen_s))
        set_stamp(m.last_seen, max(0.0, tr.last_seen_s))
        m.cameras = list(tr.cameras)
        out.tracks.append(m)
    return out


def markers_for(tracks: list[NamedTrackRecord], stamp_msg: Any, frame_id: str) -> Any:
    """RViz markers: a cylinder per person and a text label (name, face id or track id)."""
    from visualization_msgs.msg import Marker, MarkerArray

    arr = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    arr.markers.append(clear)
    for tr in tracks:
        height = tr.height_m if math.isfinite(tr.height_m) and tr.height_m > 0 else 1.7
        body = Marker()
        body.header.frame_id, body.header.stamp = frame_id, stamp_msg
        body.ns, body.id, body.type, body.action = "people", int(tr.track_id) * 2, Marker.CYLINDER, Marker.ADD
        body.pose.position.x, body.pose.position.y = float(tr.position_xy[0]), float(tr.position_xy[1])
        body.pose.position.z = height / 2
        body.pose.orientation.w = 1.0
        body.scale.x = body.scale.y = 0.4
        body.scale.z = height
        named, lost = bool(tr.name), tr.state == STATE_LOST
        body.color.r, body.color.g, body.color.b = (0.1, 0.8, 0.2) if named else (0.2, 0.5, 0.9)
        body.color.a = 0.3 if lost else 0.8
        label = Marker()
        label.header = body.header
        label.ns, label.id, label.type, label.action = "labels", int(tr.track_id) * 2 + 1, Marker.TEXT_VIEW_FACING, 0
        label.pose.position.x, label.pose.position.y = body.pose.position.x, body.pose.position.y
        label.pose.position.z = height + 0.3
        label.pose.orientation.w = 1.0
        label.scale.z = 0.25
        label.color.r = label.color.g = label.color.b = label.color.a = 1.0
        who = tr.name or (f"face {tr.face_id}" if tr.face_id else f"track {tr.track_id}")
        label.text = f"{who} ({tr.identity_confidence:.2f})" if tr.face_id else who
        arr.markers.extend([body, label])
    return arr
