"""Conversions between the camera core's records and ROS messages (message classes only, no rclpy).

Kept apart from the node so the conversion is unit-tested without spinning anything.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from face_reid_camera.body.observation import GEOMETRY_MSG_FIELDS
from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.stamps import set_stamp
from face_reid_camera.pipeline import FrameResult, PersonObservation


def intrinsics_from_camera_info(msg: Any) -> CameraIntrinsics:
    """CameraIntrinsics from a sensor_msgs/CameraInfo (raises ValueError when unusable)."""
    k = list(msg.k)
    if len(k) != 9:
        raise ValueError("CameraInfo.k must have 9 values")
    return CameraIntrinsics(float(k[0]), float(k[4]), float(k[2]), float(k[5]), int(msg.width), int(msg.height))


def _roi(msg: Any, xywh: tuple[float, float, float, float] | None, width: int = 0, height: int = 0) -> None:
    if xywh is None:
        return
    x, y, w, h = (float(v) for v in xywh)
    x0, y0 = max(0, round(x)), max(0, round(y))
    msg.x_offset, msg.y_offset = x0, y0
    msg.width, msg.height = max(0, round(x + w) - x0), max(0, round(y + h) - y0)


def person_to_msg(person_cls: type, person: PersonObservation) -> Any:
    """Fill a face_reid_msgs/PersonObservation."""
    m = person_cls()
    m.position_world.x, m.position_world.y, m.position_world.z = (float(v) for v in person.position_world)
    m.position_camera.x, m.position_camera.y, m.position_camera.z = (float(v) for v in person.position_camera)
    m.position_std_m = float(person.position_std_m)
    m.height_m = float(person.height_m)
    m.num_points = int(person.num_points)
    _roi(m.head_roi, person.head_roi_xywh)
    face = person.face
    if face is not None:
        m.face_found = True
        m.face_score = float(face.detection.score)
        _roi(m.face_box, tuple(float(v) for v in face.detection.box_xywh))  # type: ignore[arg-type]
        m.face_quality = float(face.quality)
        m.face_yaw_deg = float(face.yaw_deg)
        m.face_eye_distance_px = float(face.eye_distance_px)
        if face.embedding is not None:
            m.embedding = np.asarray(face.embedding, dtype=np.float32).tolist()
            m.embedding_space = face.embedding_space
    body = person.body
    if body is not None:
        if body.descriptor.size:
            m.body_descriptor = np.asarray(body.descriptor, dtype=np.float32).tolist()
            m.body_descriptor_space = body.space
        m.body_visible_fraction = float(body.visible_fraction)
        m.body_part_visible = [float(v) for v in body.part_visible]
        m.body_part_widths_m = [float(v) for v in body.geometry.part_widths_m]
        for name, value in zip(GEOMETRY_MSG_FIELDS, body.geometry.vector().tolist(), strict=True):
            if name != "height_m":  # the detection's own height, set above
                setattr(m, name, value)
    return m


def frame_to_msg(
    result: FrameResult, stamp_s: float, camera_id: str, world_frame_id: str,
    camera_frame_id: str, pose: CameraPose, frames_dropped: int = 0,
) -> Any:
    """Fill a face_reid_msgs/CameraFrame from a pipeline result."""
    from face_reid_msgs.msg import CameraFrame
    from face_reid_msgs.msg import PersonObservation as PersonMsg

    msg = CameraFrame()
    set_stamp(msg.header.stamp, stamp_s)
    msg.header.frame_id = world_frame_id
    msg.camera_id = camera_id
    msg.camera_frame_id = camera_frame_id
    msg.camera_pose.position.x, msg.camera_pose.position.y, msg.camera_pose.position.z = (
        float(v) for v in pose.translation
    )
    q = pose.quaternion_xyzw()
    o = msg.camera_pose.orientation
    o.x, o.y, o.z, o.w = q
    msg.ground_plane_found = bool(result.ground_plane_found)
    msg.processing_time_ms = float(result.timings_ms.get("total_ms", 0.0))
    msg.frames_dropped = max(0, int(frames_dropped))
    msg.people = [person_to_msg(PersonMsg, p) for p in result.people]
    return msg
