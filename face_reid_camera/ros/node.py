"""face-reid-camera: the per-camera ROS 2 lifecycle node (thin: messages <-> CameraPipeline).

configure loads the models and builds the pipeline; activate subscribes to colour + registered depth
images and CameraInfo, pairs them by stamp and runs :class:`~face_reid_camera.pipeline.CameraPipeline`
on the newest pair in a worker thread (older unprocessed pairs are dropped, never queued), publishing
one ``face_reid_msgs/CameraFrame`` per processed frame; deactivate / cleanup undo it.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any

import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_camera.common.clock_step import ClockStepDetector
from face_reid_camera.common.diagnostics import DiagnosticReport, NodeHealth
from face_reid_camera.common.ros.lifecycle import ManagedNode, run_node
from face_reid_camera.common.ros.sealed import seal_message
from face_reid_camera.common.stamps import stamp_to_seconds
from face_reid_camera.pipeline import CameraPipeline
from face_reid_camera.ros import params as camera_params
from face_reid_camera.ros.convert import frame_to_msg, intrinsics_from_camera_info
from face_reid_camera.ros.floor_map_output import FloorMapOutput
from face_reid_camera.ros.frame_sync import DROP_MEANINGS, DROP_REASONS, RESET_BACKWARD_S, StampSynchronizer
from face_reid_camera.ros.image_codec import ImageDecodeError, decode_image, depth_to_metres, to_bgr
from face_reid_msgs.msg import CameraFrame

USAGE = """usage: face-reid-camera [--ros-args --params-file config/camera.yaml -p name:=value ...]

The face-reid camera node (a lifecycle node; autostart:=false waits for a lifecycle manager):
RGB-D frames in, face_reid_msgs/CameraFrame out, status on /diagnostics.
Parameters (all declared with descriptions and ranges; `ros2 param describe` lists them):
"""

REJECT_REASONS = ("bad_color", "bad_depth", "no_camera_info", "stale", "size_mismatch", "pipeline_errors",
                  *DROP_REASONS)


class CameraNode(ManagedNode):
    """The camera node; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(camera_params.TABLE, **kwargs)
        self.values: dict[str, Any] = {}
        self.pipeline: CameraPipeline | None = None
        self.health: NodeHealth | None = None
        self._intrinsics: CameraIntrinsics | None = None
        self._color_intrinsics: CameraIntrinsics | None = None
        self._sync: StampSynchronizer[Any, Any] | None = None
        self._sealer: Any = None  # Sealer of this camera when the network has a key
        self._slot: tuple[float, Any, Any] | None = None
        self._cond = threading.Condition()
        self._running = False
        self._busy = False  # the worker is processing a pair
        self._worker: threading.Thread | None = None
        self._subs: list[Any] = []
        self._qos_timer: Any = None
        self.publisher: Any = None
        self._pub_lock = threading.Lock()
        self._superseded = 0
        self._dropped_reported = 0
        self._stamp_drops_reported: dict[str, int] = {}
        self._floor_found: bool | None = None
        self._floor_check: Any = None  # FloorCheck of the last frame the pose was checked on
        self._floor_map: FloorMapOutput | None = None  # floor occupancy output (floor_map_period_s > 0)
        self._wall_steps = ClockStepDetector()  # this host's wall clock stepping: frames stamped off it (an ERROR)

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        from face_reid_camera.faces.detector import YuNetDetector
        from face_reid_camera.faces.embedder import load_embedder

        values = self.parameter_values()
        config = camera_params.pipeline_config(values)
        pose = camera_params.camera_pose(values)
        detector = embedder = None
        if config.detect_faces:
            threads = int(values["num_threads"])
            detector = YuNetDetector(
                values["detector_model_path"] or None,
                score_threshold=float(values["face_score_threshold"]),
                nms_iou_threshold=float(values["face_nms_iou_threshold"]),
                roi_input_size_px=int(values["face_roi_input_px"]),
                num_threads=threads,
            )
            embedder = load_embedder(str(values["embedder"]), threads, {
                "dlib": str(values["dlib_model_path"]), "sface": str(values["sface_model_path"])})
        projection = None
        if config.describe_bodies:
            from face_reid_camera.body.projection import load_body_projection

            projection = load_body_projection(str(values["body_projection_path"]))
        self.values = values
        self.pipeline = CameraPipeline(config, pose, detector, embedder, bool(values["seed_ground_from_pose"]),
                                       projection)
        self.health = NodeHealth(f"{self.get_name()}: camera {config.camera_id}", config.camera_id,
                                 float(values["no_input_warning_s"]))
        self._camera_frame_id = str(values["camera_frame_id"])
        self._floor_map = FloorMapOutput.from_values(self, values, config.camera_id, pose,
                                                     str(values["world_frame_id"]))
        self._sync = StampSynchronizer(float(values["sync_slop_s"]), max_age_s=float(values["max_frame_age_s"]),
                                       on_drop=self._reject)
        self._stamp_drops_reported = {}
        self._sealer = None
        if values["network_key_path"]:
            from face_reid_camera.common.sealing import Sealer, load_network_key

            self._sealer = Sealer(load_network_key(str(values["network_key_path"])), config.camera_id)
        else:
            self.get_logger().warning(
                "UNSECURED: no network_key_path: frames (positions and face embeddings, biometric data) go out "
                "in clear and any participant of this DDS domain can read them or send frames as this camera")

    def activate(self) -> None:
        values = self.values
        reliable = values["image_qos"] == "reliable"
        frame_qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        with self._pub_lock:
            if self._sealer is not None:
                from face_reid_msgs.msg import Sealed

                self.publisher = self.create_publisher(Sealed, str(values["sealed_output_topic"]), frame_qos)
            else:
                self.publisher = self.create_publisher(CameraFrame, str(values["output_topic"]), frame_qos)
        inputs = [(Image, str(values["color_topic"]), self._on_color),
                  (Image, str(values["depth_topic"]), self._on_depth),
                  (CameraInfo, str(values["camera_info_topic"]), self._on_info)]
        if values["color_camera_info_topic"]:
            inputs.append((CameraInfo, str(values["color_camera_info_topic"]), self._on_color_info))
        self._subs = [self._subscribe_input(msg_type, topic, callback, reliable)
                      for msg_type, topic, callback in inputs]
        if values["image_qos"] == "auto":
            self._qos_timer = self.create_steady_timer(1.0, self._match_driver_qos)
        if self._floor_map is not None:
            self._floor_map.activate()
        assert self.health is not None
        self.health.start(self.now_s())
        self._running = True
        self._worker = threading.Thread(target=self._work, name="face_reid_camera_pipeline", daemon=True)
        self._worker.start()
        assert self.pipeline is not None
        self.get_logger().info(
            f"camera '{self.pipeline.config.camera_id}': colour={values['color_topic']} depth={values['depth_topic']} "
            f"info={values['camera_info_topic']} -> {self.publisher.topic_name} "
            f"(faces {'on, embedder ' + str(values['embedder']) if self.pipeline.config.detect_faces else 'off'}; "
            f"bodies {self.pipeline.body_projection.space if self.pipeline.body_projection else 'off'})"
        )

    def deactivate(self) -> None:
        with self._cond:
            self._running = False
            self._slot = None
            self._cond.notify()
        if self._worker is not None:
            self._worker.join(timeout=5.0)
            self._worker = None
        if self._floor_map is not None:
            self._floor_map.deactivate()
        if self._qos_timer is not None:
            self.destroy_timer(self._qos_timer)
            self._qos_timer = None
        for sub in self._subs:
            self.destroy_subscription(sub)
        self._subs = []
        with self._pub_lock:
            if self.publisher is not None:
                self.destroy_publisher(self.publisher)
                self.publisher = None

    def _subscribe_input(self, msg_type: Any, topic: str, callback: Any, reliable: bool) -> Any:
        qos = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)
        return self.create_subscription(msg_type, topic, callback, qos)

    def _match_driver_qos(self) -> None:
        """image_qos auto: a subscription whose publishers are all reliable becomes reliable (no frame lost to a
        busy subscriber); one with a best-effort publisher becomes best effort (else it would hear nothing)."""
        for k, sub in enumerate(self._subs):
            topic = sub.topic_name
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            want = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
            if want == (sub.qos_profile.reliability == ReliabilityPolicy.RELIABLE):
                continue
            msg_type, callback = sub.msg_type, sub.callback
            self.destroy_subscription(sub)
            self._subs[k] = self._subscribe_input(msg_type, topic, callback, want)
            self.get_logger().info(f"{topic}: the driver publishes {'reliable' if want else 'best effort'}: "
                                   "subscribed so")

    def cleanup(self) -> None:
        self.pipeline = None
        self._floor_map = None
        self._sync = None
        self._intrinsics = None
        self._color_intrinsics = None

    # ------------------------------------------------------------------ callbacks: decode, pair, hand over
    def _on_info(self, msg: Any) -> None:
        try:
            intr = intrinsics_from_camera_info(msg)
        except ValueError as exc:
            self._reject("no_camera_info", f"unusable CameraInfo: {exc}")
            return
        self._intrinsics = intr
        if not self._camera_frame_id:
            self._camera_frame_id = msg.header.frame_id

    def _on_color_info(self, msg: Any) -> None:
        try:
            self._color_intrinsics = intrinsics_from_camera_info(msg)
        except ValueError as exc:
            self._reject("no_camera_info", f"unusable colour CameraInfo: {exc}")

    def _on_color(self, msg: Any) -> None:
        img = self._decode(msg, to_bgr, "bad_color", "colour")
        if img is not None:
            self._pair(True, msg, img)

    def _on_depth(self, msg: Any) -> None:
        depth = self._decode(msg, depth_to_metres, "bad_depth", "depth")
        if depth is not None:
            self._pair(False, msg, depth)

    def _pair(self, is_color: bool, msg: Any, image: np.ndarray) -> None:
        """Hand an image to the synchroniser with this node's clock as the receive time; offer a completed pair."""
        sync = self._sync
        if sync is None:
            return
        resets = sync.stats.resets
        add = sync.add_color if is_color else sync.add_depth
        pair = add(stamp_to_seconds(msg.header.stamp), image, self.now_s())
        if sync.stats.resets != resets:
            self.log_throttled("sync_reset", f"image stamps went back by more than {RESET_BACKWARD_S:g} s (a bag "
                               "loop or a clock jump): colour/depth pairing restarted", sync.stats.resets, warn=True)
        self._offer(pair)

    def _decode(self, msg: Any, convert: Any, reason: str, what: str) -> np.ndarray | None:
        """The image of a sensor_msgs/Image through ``convert`` (to BGR / to metres), or None: rejected, counted."""
        try:
            return convert(decode_image(msg.encoding, msg.height, msg.width, msg.step, msg.data,
                                        bool(msg.is_bigendian)), msg.encoding)
        except ImageDecodeError as exc:
            self._reject(reason, f"{what} image rejected: {exc}")
            return None

    def _offer(self, pair: tuple[float, Any, Any] | None) -> None:
        if pair is None:
            return
        if self.health is not None:
            self.health.frame_in(self.now_s())
        with self._cond:
            if self._slot is not None:
                self._superseded += 1
            self._slot = pair
            self._cond.notify()

    # ------------------------------------------------------------------ worker
    def _work(self) -> None:
        while True:
            with self._cond:
                while self._running and self._slot is None:
                    self._cond.wait(0.5)
                if not self._running:
                    return
                pair, self._slot = self._slot, None
                self._busy = True
            assert pair is not None
            try:
                self._process(*pair)
            except Exception as exc:  # a bug must not kill the camera: log, count, go on
                self._reject("pipeline_errors", f"frame processing failed: {type(exc).__name__}: {exc}")
            finally:
                with self._cond:
                    self._busy = False

    def _process(self, stamp_s: float, color: np.ndarray, depth: np.ndarray) -> None:
        intr, pipeline, health = self._intrinsics, self.pipeline, self.health
        if pipeline is None or health is None:
            return
        if intr is None:
            self._reject("no_camera_info", "no CameraInfo received yet: frame dropped")
            return
        now_s = self.now_s()
        sync = self._sync
        if sync is not None and sync.gate.expired(stamp_s, now_s):  # past the deadline its admission set
            self._reject("stale", f"frame {now_s - stamp_s:.3f} s old (> max_frame_age_s {sync.gate.max_age_s}): "
                         "dropped")
            return
        if depth.shape != (intr.height, intr.width):
            self._reject("size_mismatch",
                         f"depth is {depth.shape[1]}x{depth.shape[0]} but CameraInfo says {intr.width}x{intr.height}")
            return
        ch, cw = color.shape[:2]
        color_intr = None
        if self.values["color_camera_info_topic"]:
            color_intr = self._color_intrinsics
            if color_intr is None:
                self._reject("no_camera_info", "no colour CameraInfo received yet: frame dropped")
                return
            if (cw, ch) != (color_intr.width, color_intr.height):
                self._reject("size_mismatch", f"colour is {cw}x{ch} but its CameraInfo says "
                             f"{color_intr.width}x{color_intr.height}")
                return
        elif abs(cw / intr.width - ch / intr.height) > 0.02:
            self._reject("size_mismatch", f"colour {cw}x{ch} and depth {intr.width}x{intr.height} differ in aspect "
                         "(set color_camera_info_topic when colour has its own CameraInfo)")
            return
        result = pipeline.process(color, depth, intr, color_intr, stamp_s)
        self._floor_found = bool(result.ground_plane_found)
        if result.floor_check is not None or result.ground_plane_source == "ransac":
            self._floor_check = result.floor_check  # None again once the pose's floor is seen in the data
        if result.floor_check is not None and not result.floor_check.agrees:
            self.log_throttled("pose_check", f"camera {pipeline.config.camera_id}: {result.floor_check.describe()}: "
                               "fix camera_pose_xyz_m (z) / camera_pose_rpy_rad (roll, pitch); until then no people "
                               "are published from the configured floor", warn=True)
        msg = frame_to_msg(result, stamp_s, pipeline.config.camera_id, str(self.values["world_frame_id"]),
                           self._camera_frame_id, pipeline.camera_pose, self._new_drops())
        if self._sealer is not None:
            msg = seal_message(self._sealer, msg)
        with self._pub_lock:
            if self.publisher is None:
                return
            self.publisher.publish(msg)
        health.frame_processed(result.timings_ms.get("total_ms", 0.0), len(result.people), result.num_faces)
        health.published()
        if self._floor_map is not None:
            self._floor_map.frame(stamp_s, depth, intr)

    def _dropped_total(self) -> int:
        sync = self._sync
        unpaired = (sync.stats.dropped_color + sync.stats.dropped_depth) if sync is not None else 0
        stale = self.health.rejected.get("stale", 0) if self.health is not None else 0
        return self._superseded + stale + unpaired

    def _new_drops(self) -> int:
        total = self._dropped_total()
        new, self._dropped_reported = total - self._dropped_reported, total
        return max(0, new)

    # ------------------------------------------------------------------ reporting
    def _reject(self, reason: str, message: str) -> None:
        total = self.health.reject(reason) if self.health is not None else 0
        self.log_throttled(reason, message, total)

    def diagnostics(self, now_s: float) -> DiagnosticReport:
        health = self.health
        assert health is not None
        health.frames_dropped = self._dropped_total()
        sync = self._sync
        warnings = []
        if self._floor_found is False:
            warnings.append("floor lost: no ground plane in the last frame")
        check = self._floor_check
        if check is not None and not check.agrees:
            warnings.append(check.describe())
        extra: dict[str, object] = {
            "frames_superseded": self._superseded,
            "unpaired_color": sync.stats.dropped_color if sync else 0,
            "unpaired_depth": sync.stats.dropped_depth if sync else 0,
            "sync_resets": sync.stats.resets if sync else 0,
            "camera_info_received": self._intrinsics is not None,
            "floor_found": self._floor_found if self._floor_found is not None else "no frame yet",
            "body_errors": self.pipeline.body_errors if self.pipeline is not None else 0,
            "rejected_thin_support": self.pipeline.thin_support_rejected if self.pipeline is not None else 0,
            "rejected_top_at_border": self.pipeline.cut_by_border_rejected if self.pipeline is not None else 0,
            "pose_agrees_with_floor": "not checked" if check is None else check.agrees,
        }
        extra.update(self.control_values())  # ~/change_state_sealed
        if check is not None:
            extra.update({"pose_camera_height_m": check.pose_height_m, "floor_camera_height_m": check.floor_height_m,
                          "pose_tilt_deg": check.pose_tilt_deg, "floor_tilt_deg": check.floor_tilt_deg})
        for reason in REJECT_REASONS:
            extra.setdefault(f"rejected_{reason}", health.rejected.get(reason, 0))
        stamp_drops = {r: health.rejected.get(r, 0) - self._stamp_drops_reported.get(r, 0) for r in DROP_REASONS}
        self._stamp_drops_reported = {r: health.rejected.get(r, 0) for r in DROP_REASONS}
        if any(stamp_drops.values()):
            warnings.append("images dropped for their stamps since the last report: " + ", ".join(
                f"{n} {r} ({DROP_MEANINGS[r]})" for r, n in stamp_drops.items() if n) +
                "; check the camera driver's stamps and this host's clock")
        errors = self._wall_steps.observe(time.time(), time.monotonic(), sum(health.rejected.values()))
        if errors:
            errors[0] += ": this camera's stamps and seals are off the other hosts' clocks (the master refuses " \
                         "what is beyond its limits)"
        extra.update(self._wall_steps.values())
        return health.report(now_s, extra, warnings, errors)


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    return run_node("face-reid-camera", USAGE, camera_params.TABLE, CameraNode, argv)


if __name__ == "__main__":
    sys.exit(main())
