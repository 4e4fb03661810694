"""face-reid-camera: the per-camera ROS 2 node (thin: messages <-> CameraPipeline).

Subscribes to colour + registered depth images and CameraInfo, pairs them by stamp, runs
:class:`~face_reid_camera.pipeline.CameraPipeline` on the newest pair in a worker thread
(older unprocessed pairs are dropped, never queued) and publishes one
``face_reid_msgs/CameraFrame`` per processed frame.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_camera.common.errors import ModelLoadError
from face_reid_camera.pipeline import CameraPipeline, FrameResult
from face_reid_camera.ros import params as camera_params
from face_reid_camera.ros.frame_sync import StampSynchronizer
from face_reid_camera.ros.image_codec import ImageDecodeError, decode_image, depth_to_metres, to_bgr
from face_reid_camera.ros.node_main import run_node

USAGE = """usage: face-reid-camera [--ros-args --params-file config/camera.yaml -p name:=value ...]

The face-reid camera node: RGB-D frames in, face_reid_msgs/CameraFrame out.
Parameters (all declared with descriptions; `ros2 param describe` lists them):
"""


@dataclass
class NodeCounters:
    """What the node dropped or rejected, by reason (logged periodically, never silent)."""

    frames_published: int = 0
    bad_color: int = 0
    bad_depth: int = 0
    no_camera_info: int = 0
    stale: int = 0
    superseded: int = 0
    size_mismatch: int = 0
    pipeline_errors: int = 0


def intrinsics_from_camera_info(msg: Any) -> CameraIntrinsics:
    """CameraIntrinsics from a sensor_msgs/CameraInfo (raises ValueError when unusable)."""
    k = list(msg.k)
    if len(k) != 9:
        raise ValueError("CameraInfo.k must have 9 values")
    return CameraIntrinsics(float(k[0]), float(k[4]), float(k[2]), float(k[5]), int(msg.width), int(msg.height))


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    return run_node("face-reid-camera", USAGE, camera_params.TABLE, CameraNode,
                    (ModelLoadError, FileNotFoundError, ValueError), argv)


def _make_node_class() -> type:
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image

    from face_reid_camera.faces.detector import YuNetDetector
    from face_reid_camera.faces.embedder import FaceEmbedder
    from face_reid_msgs.msg import CameraFrame

    class _CameraNode(Node):
        def __init__(self) -> None:
            super().__init__(camera_params.NODE_NAME)
            values: dict[str, Any] = {}
            for spec in camera_params.CAMERA_PARAMS:
                self.declare_parameter(spec.name, spec.default, ParameterDescriptor(description=spec.description))
                values[spec.name] = camera_params.check_value(spec.name, self.get_parameter(spec.name).value)
            self.values = values
            self.config = camera_params.pipeline_config(values)
            self.pose = camera_params.camera_pose(values)
            detector = embedder = None
            if self.config.detect_faces:
                threads = int(values["num_threads"])
                detector = YuNetDetector(
                    values["detector_model_path"] or None,
                    score_threshold=float(values["face_score_threshold"]),
                    nms_iou_threshold=float(values["face_nms_iou_threshold"]),
                    roi_input_size_px=int(values["face_roi_input_px"]),
                    num_threads=threads,
                )
                embedder = FaceEmbedder(values["embedder_model_path"] or None, num_threads=threads)
            self.pipeline = CameraPipeline(
                self.config, self.pose, detector, embedder, bool(values["seed_ground_from_pose"])
            )
            self.counters = NodeCounters()
            self._reported: dict[str, int] = {}
            self._last_logged: dict[str, float] = {}
            self._intrinsics: CameraIntrinsics | None = None
            self._camera_frame_id = str(values["camera_frame_id"])
            self._sync: StampSynchronizer[Any, Any] = StampSynchronizer(float(values["sync_slop_s"]))
            self._slot: tuple[float, Any, Any] | None = None
            self._cond = threading.Condition()
            self._running = True

            image_qos = QoSProfile(
                depth=2, history=HistoryPolicy.KEEP_LAST,
                reliability=ReliabilityPolicy.RELIABLE if values["image_qos_reliable"]
                else ReliabilityPolicy.BEST_EFFORT,
            )
            self.create_subscription(Image, str(values["color_topic"]), self._on_color, image_qos)
            self.create_subscription(Image, str(values["depth_topic"]), self._on_depth, image_qos)
            self.create_subscription(CameraInfo, str(values["camera_info_topic"]), self._on_info, image_qos)
            self.publisher = self.create_publisher(
                CameraFrame, str(values["output_topic"]),
                QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE),
            )
            self.CameraFrame = CameraFrame
            self._worker = threading.Thread(target=self._work, name="face_reid_camera_pipeline", daemon=True)
            self._worker.start()
            self.create_timer(10.0, self._report)
            self.get_logger().info(
                f"camera '{self.config.camera_id}': colour={values['color_topic']} depth={values['depth_topic']} "
                f"info={values['camera_info_topic']} -> {self.publisher.topic_name} "
                f"(faces {'on' if self.config.detect_faces else 'off'})"
            )

        # --- callbacks: decode cheaply, pair, hand the newest pair to the worker ---------------
        def _on_info(self, msg: Any) -> None:
            try:
                intr = intrinsics_from_camera_info(msg)
            except ValueError as exc:
                self._count("no_camera_info", f"unusable CameraInfo: {exc}")
                return
            self._intrinsics = intr
            if not self._camera_frame_id:
                self._camera_frame_id = msg.header.frame_id

        def _on_color(self, msg: Any) -> None:
            try:
                img = to_bgr(
                    decode_image(msg.encoding, msg.height, msg.width, msg.step, msg.data, bool(msg.is_bigendian)),
                    msg.encoding,
                )
            except ImageDecodeError as exc:
                self._count("bad_color", f"colour image rejected: {exc}")
                return
            self._offer(self._sync.add_color(_stamp_s(msg.header.stamp), img))

        def _on_depth(self, msg: Any) -> None:
            try:
                depth = depth_to_metres(
                    decode_image(msg.encoding, msg.height, msg.width, msg.step, msg.data, bool(msg.is_bigendian)),
                    msg.encoding,
                )
            except ImageDecodeError as exc:
                self._count("bad_depth", f"depth image rejected: {exc}")
                return
            self._offer(self._sync.add_depth(_stamp_s(msg.header.stamp), depth))

        def _offer(self, pair: tuple[float, Any, Any] | None) -> None:
            if pair is None:
                return
            with self._cond:
                if self._slot is not None:
                    self.counters.superseded += 1
                self._slot = pair
                self._cond.notify()

        # --- worker ---------------------------------------------------------------------------
        def _work(self) -> None:
            while True:
                with self._cond:
                    while self._running and self._slot is None:
                        self._cond.wait(0.5)
                    if not self._running:
                        return
                    pair, self._slot = self._slot, None
                assert pair is not None
                try:
                    self._process(*pair)
                except Exception as exc:  # a bug must not kill the camera: log, count, go on
                    self._count("pipeline_errors", f"frame processing failed: {type(exc).__name__}: {exc}")

        def _process(self, stamp_s: float, color: np.ndarray, depth: np.ndarray) -> None:
            intr = self._intrinsics
            if intr is None:
                self._count("no_camera_info", "no CameraInfo received yet: frame dropped")
                return
            max_age = float(self.values["max_frame_age_s"])
            now_s = self.get_clock().now().nanoseconds * 1e-9
            if max_age > 0 and now_s - stamp_s > max_age:
                self._count("stale", f"frame {now_s - stamp_s:.3f} s old (> max_frame_age_s {max_age}): dropped")
                return
            if depth.shape != (intr.height, intr.width):
                self._count(
                    "size_mismatch",
                    f"depth is {depth.shape[1]}x{depth.shape[0]} but CameraInfo says {intr.width}x{intr.height}",
                )
                return
            ch, cw = color.shape[:2]
            if abs(cw / intr.width - ch / intr.height) > 0.02:
                self._count("size_mismatch", f"colour {cw}x{ch} and depth {intr.width}x{intr.height} differ in aspect")
                return
            result = self.pipeline.process(color, depth, intr)
            self.publisher.publish(self._to_msg(stamp_s, result))
            self.counters.frames_published += 1

        def _to_msg(self, stamp_s: float, result: FrameResult) -> Any:
            from face_reid_camera.ros.convert import frame_to_msg

            dropped = (
                self.counters.superseded + self.counters.stale + self._sync.stats.dropped_color
                + self._sync.stats.dropped_depth
            )
            msg = frame_to_msg(
                self.CameraFrame, result, stamp_s, self.config.camera_id, str(self.values["world_frame_id"]),
                self._camera_frame_id, self.pose, dropped - self._reported.get("_dropped", 0),
            )
            self._reported["_dropped"] = dropped
            return msg

        # --- reporting ------------------------------------------------------------------------
        def _count(self, counter: str, message: str) -> None:
            """Count a dropped input; log it at once the first time, then at most every 5 s per reason."""
            total = getattr(self.counters, counter) + 1
            setattr(self.counters, counter, total)
            now = time.monotonic()
            if now - self._last_logged.get(counter, -1e9) >= 5.0:
                self._last_logged[counter] = now
                self.get_logger().error(f"{message} [{counter}: {total} so far]")

        def _report(self) -> None:
            c, s = self.counters, self._sync.stats
            self.get_logger().info(
                f"published {c.frames_published} frames; dropped: superseded {c.superseded}, stale {c.stale}, "
                f"unpaired colour {s.dropped_color} depth {s.dropped_depth}, out-of-order {s.rejected_out_of_order}; "
                f"rejected: colour {c.bad_color}, depth {c.bad_depth}, no CameraInfo {c.no_camera_info}, "
                f"size mismatch {c.size_mismatch}, errors {c.pipeline_errors}"
            )

        def shutdown(self) -> None:
            with self._cond:
                self._running = False
                self._cond.notify()
            self._worker.join(timeout=2.0)

    return _CameraNode


def _stamp_s(stamp: Any) -> float:
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def CameraNode() -> Any:
    """Create the node (imports rclpy lazily so ``--help`` works without a ROS environment)."""
    return _make_node_class()()


if __name__ == "__main__":
    sys.exit(main())
