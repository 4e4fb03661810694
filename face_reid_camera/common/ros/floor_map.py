"""The floor occupancy topic both ends share: its name, its QoS (reliable, transient local, depth 1: a late map
node still gets the latest) and FloorOccupancy message conversion."""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from face_reid_camera.common.checks import shown
from face_reid_camera.common.floor_snapshot import FloorOccupancySnapshot
from face_reid_camera.common.stamps import set_stamp, stamp_to_seconds
from face_reid_msgs.msg import FloorOccupancy

__all__ = ["FLOOR_MAP_QOS", "FLOOR_MAP_TOPIC", "snapshot_from_msg", "snapshot_to_msg"]

FLOOR_MAP_TOPIC = "face_reid/floor_occupancy"
FLOOR_MAP_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)


def snapshot_to_msg(snap: FloorOccupancySnapshot, world_frame_id: str) -> Any:
    """A face_reid_msgs/FloorOccupancy of ``snap``."""
    msg = FloorOccupancy()
    set_stamp(msg.header.stamp, snap.stamp_s)
    msg.header.frame_id = world_frame_id
    msg.camera_id = snap.camera_id
    msg.resolution_m = float(snap.resolution_m)
    msg.origin_x_m, msg.origin_y_m = float(snap.origin_x_m), float(snap.origin_y_m)
    msg.width, msg.height = snap.width, snap.height
    msg.min_height_m, msg.max_height_m = float(snap.min_height_m), float(snap.max_height_m)
    msg.frames = min(int(snap.frames), 2**32 - 1)
    msg.floor_counts = snap.floor_counts.reshape(-1)
    msg.occupied_counts = snap.occupied_counts.reshape(-1)
    return msg


def snapshot_from_msg(msg: Any) -> FloorOccupancySnapshot:
    """The snapshot a FloorOccupancy message carries; ValueError when its arrays do not match width x height."""
    w, h = int(msg.width), int(msg.height)
    floor = np.asarray(msg.floor_counts, dtype=np.uint16)
    occ = np.asarray(msg.occupied_counts, dtype=np.uint16)
    if w * h == 0 or floor.size != w * h or occ.size != w * h:
        raise ValueError(f"FloorOccupancy from {shown(msg.camera_id, 64)}: {floor.size} floor and {occ.size} occupied "
                         f"counts for {w} x {h} cells")
    return FloorOccupancySnapshot(
        camera_id=str(msg.camera_id), stamp_s=stamp_to_seconds(msg.header.stamp),
        resolution_m=_float32_value(msg.resolution_m), origin_x_m=float(msg.origin_x_m),
        origin_y_m=float(msg.origin_y_m), min_height_m=_float32_value(msg.min_height_m),
        max_height_m=_float32_value(msg.max_height_m), frames=int(msg.frames),
        floor_counts=floor.reshape(h, w), occupied_counts=occ.reshape(h, w))


def _float32_value(value: float) -> float:
    """The decimal a float32 message field was set from (0.05, not 0.05000000074505806: maps files stay clean)."""
    return float(str(np.float32(value)))
