"""The camera node's floor occupancy output (``floor_map_*`` parameters).

Off by default (``floor_map_period_s`` = 0: nothing is built, nothing runs per frame). On: one processed depth
frame in ``floor_map_every_frames`` is counted (:class:`FloorOccupancyAccumulator`) and the summary is published on
the floor map topic after the first counted frame and then every ``floor_map_period_s``.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.param_table import config_from_values
from face_reid_camera.common.ros.floor_map import FLOOR_MAP_QOS, FLOOR_MAP_TOPIC, snapshot_to_msg
from face_reid_camera.people.floor_occupancy import FloorOccupancyAccumulator, FloorOccupancyConfig
from face_reid_msgs.msg import FloorOccupancy

__all__ = ["FloorMapOutput"]

PARAM_PREFIX = "floor_map_"


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
