"""The camera node's floor occupancy output (``floor_map_*`` parameters) and FloorOccupancy message conversion.

Off by default (``floor_map_period_s`` = 0: nothing is built, nothing runs per frame). On: one processed depth
frame in ``floor_map_every_frames`` is counted (:class:`FloorOccupancyAccumulator`) and the summary is published on
``face_reid/floor_occupancy`` (reliable, transient local, depth 1: a late map node still gets the latest) after the
first counted frame and then every ``floor_map_period_s``.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.checks import shown
from face_reid_camera.common.param_table import config_from_values
from face_reid_camera.common.stamps import set_stamp, stamp_to_seconds
from face_reid_camera.people.floor_occupancy import (
    FloorOccupancyAccumulator,
    FloorOccupancyConfig,
    FloorOccupancySnapshot,
)
from face_reid_msgs.msg import FloorOccupancy

__all__ = ["FLOOR_MAP_QOS", "FLOOR_MAP_TOPIC", "FloorMapOutput", "snapshot_from_msg", "snapshot_to_msg"]

FLOOR_MAP_TOPIC = "face_reid/floor_occupancy"
FLOOR_MAP_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
PARAM_PREFIX = "floor_map_"


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


class FloorMapOutput:
    """Accumulate and publish one camera's floor occupancy (see the module docstring); thread-safe."""

    def __init__(self, node: Any, config: FloorOccupancyConfig, camera_id: str, pose: CameraPose,
                 world_frame_id: str) -> None:
        self._node = node
        self.config = config
        self._pose = pose
        self._frame_id = world_frame_id
        self._acc = FloorOccupancyAccumulator(config, camera_id, (float(pose.translation[0]),
                                                                  float(pose.translation[1])))
        self._lock = threading.Lock()
        self._publisher: Any = None
        self._next_publish = 0.0  # monotonic s
        self.published = 0

    @classmethod
    def from_values(cls, node: Any, values: dict[str, Any], camera_id: str, pose: CameraPose,
                    world_frame_id: str) -> FloorMapOutput | None:
        """The output the parameters ask for, or None when ``floor_map_period_s`` is 0 (off)."""
        config = config_from_values(FloorOccupancyConfig, values, PARAM_PREFIX)
        return cls(node, config, camera_id, pose, world_frame_id) if config.enabled else None

    def activate(self) -> None:
        with self._lock:
            self._publisher = self._node.create_publisher(FloorOccupancy, FLOOR_MAP_TOPIC, FLOOR_MAP_QOS)
            self._next_publish = 0.0

    def deactivate(self) -> None:
        with self._lock:
            if self._publisher is not None:
                self._node.destroy_publisher(self._publisher)
                self._publisher = None

    def frame(self, stamp_s: float, depth_m: np.ndarray, intrinsics: CameraIntrinsics) -> None:
        """Count this processed depth frame if it is the n-th; publish when the period is up."""
        if not self._acc.due():
            return
        self._acc.add_depth(depth_m, intrinsics, self._pose, stamp_s)
        now = time.monotonic()
        if now < self._next_publish:
            return
        snap = self._acc.snapshot()
        if snap is None:
            return
        msg = snapshot_to_msg(snap, self._frame_id)
        with self._lock:
            if self._publisher is None:
                return
            self._publisher.publish(msg)
            self._next_publish = now + self.config.period_s
            self.published += 1
