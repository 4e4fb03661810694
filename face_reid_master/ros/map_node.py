"""face-reid-map: the camera network's floor map (thin: FloorOccupancy messages -> CameraMapFusion -> OccupancyGrid).

Subscribes to every discovered face_reid_msgs/FloorOccupancy topic whose name matches ``topic_regex`` (the cameras'
``face_reid/floor_occupancy``, published when their ``floor_map_period_s`` > 0), keeps each camera's latest summary,
and publishes the fused nav_msgs/OccupancyGrid on ``output_topic`` (transient local) every ``publish_period_s``.
``save_path`` (or ``--save PATH``) saves it as a nav2 map (YAML + PGM) when the node is deactivated or stopped;
``--save PATH --once`` waits until every camera of ``--cameras`` (or, without it, the first camera plus
``--settle`` seconds) reported, saves and exits. A lifecycle node like the others, with counts on /diagnostics.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from pathlib import Path
from typing import Any

from nav_msgs.msg import OccupancyGrid
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from face_reid_camera.common.diagnostics import DiagnosticLevel, DiagnosticReport
from face_reid_camera.common.param_table import ParamSpec, ParamTable, config_from_values, config_specs
from face_reid_camera.common.ros.floor_map import FLOOR_MAP_QOS, snapshot_from_msg
from face_reid_camera.common.ros.lifecycle import ManagedNode, fatal_start, run_node, start_node
from face_reid_camera.common.stamps import set_stamp
from face_reid_master.robot.camera_map import CameraMapConfig, CameraMapFusion, OccupancyGridMap, save_nav2_map
from face_reid_msgs.msg import FloorOccupancy

NODE_NAME = "face_reid_map"
USAGE = """usage: face-reid-map [--save PATH [--once [--cameras ID,ID] [--timeout S] [--settle S]]]
                     [--ros-args -p name:=value ...]

The camera network's floor map: fuses the cameras' face_reid_msgs/FloorOccupancy summaries (camera parameter
floor_map_period_s > 0) into a nav_msgs/OccupancyGrid on /camera_map; --save writes a nav2 map (YAML + PGM).
Parameters:
"""
_TYPE = "face_reid_msgs/msg/FloorOccupancy"

TABLE = ParamTable(NODE_NAME, (
    ParamSpec("autostart", True, "Configure and activate at start (false: wait for a lifecycle manager).",
              read_only=True),
    ParamSpec("topic_regex", r"^(/.*)?/face_reid/floor_occupancy$",
              "Subscribe to every FloorOccupancy topic whose full name matches this regular expression."),
    ParamSpec("discovery_period_s", 1.0, "Look for new camera topics this often (s).", low=0.05, high=3600.0),
    ParamSpec("output_topic", "/camera_map", "Where the fused nav_msgs/OccupancyGrid is published (transient local)."),
    ParamSpec("publish_period_s", 2.0, "Publish the fused grid this often when a summary changed (s).",
              low=0.05, high=3600.0),
    ParamSpec("world_frame_id", "world", "Frame id of the grid (the cameras' shared world frame, z up)."),
    ParamSpec("save_path", "", "Save the map here as a nav2 map (YAML + PGM next to it) when the node is deactivated "
              "or stopped ('' = do not)."),
    ParamSpec("no_summary_warning_s", 30.0, "/diagnostics warns when no floor summary arrived for this long (s).",
              low=0.1, high=86400.0),
    ParamSpec("network_key_path", "",
              "The network's key file (face-reid-keys new): this node then offers no lifecycle or parameter "
              "services; transitions only through ~/change_state_sealed, sealed with the key (face-reid-state) "
              "('' = unsecured: the standard services, open to the DDS domain).", read_only=True),
    *config_specs(CameraMapConfig),
), "the face-reid camera map node (face-reid-map)", "face-reid-map --ros-args -p save_path:=maps/cameras.yaml")


def grid_to_msg(grid: OccupancyGridMap, stamp_s: float) -> Any:
    """A nav_msgs/OccupancyGrid of ``grid`` (row-major, origin = corner of cell (0, 0))."""
    msg = OccupancyGrid()
    set_stamp(msg.header.stamp, stamp_s)
    msg.header.frame_id = grid.frame
    set_stamp(msg.info.map_load_time, stamp_s)
    msg.info.resolution = float(grid.resolution_m)
    msg.info.width, msg.info.height = grid.width, grid.height
    msg.info.origin.position.x, msg.info.origin.position.y = float(grid.origin_x_m), float(grid.origin_y_m)
    msg.info.origin.orientation.z = math.sin(grid.origin_yaw_rad / 2)
    msg.info.origin.orientation.w = math.cos(grid.origin_yaw_rad / 2)
    msg.data = grid.data.reshape(-1)
    return msg


class MapNode(ManagedNode):
    """The map node (a lifecycle node, like the others); see the module docstring."""

    def __init__(self, save_path: str | None = None, **kwargs: Any) -> None:
        super().__init__(TABLE, **kwargs)
        self._save_override = save_path  # --save on the command line wins over the save_path parameter
        self.values: dict[str, Any] = {}
        self._regex: re.Pattern[str] | None = None
        self.fusion = CameraMapFusion()
        self.rejected = 0
        self.received = 0
        self.published = 0
        self._changed = False
        self._last_summary_s: float | None = None
        self._started_s = 0.0
        self._subs: dict[str, Any] = {}
        self._own_timers: list[Any] = []
        self.publisher: Any = None

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        values = self.parameter_values()
        try:
            self._regex = re.compile(str(values["topic_regex"]))
        except re.error as exc:
            raise ValueError(f"parameter 'topic_regex' is not a regular expression: {exc}") from None
        self.values = values
        self.fusion = CameraMapFusion(config_from_values(CameraMapConfig, values), str(values["world_frame_id"]))

    def activate(self) -> None:
        qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.publisher = self.create_publisher(OccupancyGrid, str(self.values["output_topic"]), qos)
        self._own_timers = [self.create_steady_timer(float(self.values["discovery_period_s"]), self.discover),
                            self.create_steady_timer(float(self.values["publish_period_s"]), self.publish_grid)]
        self._started_s = self.now_s()
        self.discover()

    def deactivate(self) -> None:
        path = self.save_path
        if path and self.fusion.cameras:
            try:
                self.save(path)
            except (OSError, ValueError) as exc:
                self.log(f"cannot save the camera map to {path}: {exc}", "error", private=True)
        for sub in self._subs.values():
            self.destroy_subscription(sub)
        for timer in self._own_timers:
            self.destroy_timer(timer)
        self._subs, self._own_timers = {}, []
        if self.publisher is not None:
            self.destroy_publisher(self.publisher)
            self.publisher = None

    @property
    def save_path(self) -> str:
        return self._save_override or str(self.values.get("save_path", ""))

    # ------------------------------------------------------------------ work
    def discover(self) -> None:
        """Subscribe to FloorOccupancy topics not yet subscribed whose names match ``topic_regex``."""
        if self._regex is None:
            return
        for name, types in self.get_topic_names_and_types():
            if name in self._subs or _TYPE not in types or not self._regex.search(name):
                continue
            self._subs[name] = self.create_subscription(FloorOccupancy, name, self._on_summary, FLOOR_MAP_QOS)
            self.get_logger().info(f"floor summaries from {name}")

    def _on_summary(self, msg: Any) -> None:
        self.received += 1
        self._last_summary_s = self.now_s()
        try:
            self._changed |= self.fusion.update(snapshot_from_msg(msg))
        except ValueError as exc:
            self.rejected += 1
            self.log_throttled("summary", f"floor summary rejected: {exc}", self.rejected, warn=True)

    def publish_grid(self, force: bool = False) -> OccupancyGridMap | None:
        """Fuse and publish when a summary changed (or ``force``); returns the grid."""
        if not (self._changed or force) or self.publisher is None:
            return None
        try:
            grid = self.fusion.grid()
        except ValueError as exc:
            self.log_throttled("fuse", f"cannot fuse the floor summaries: {exc}")
            return None
        if grid is None:
            return None
        self._changed = False
        self.publisher.publish(grid_to_msg(grid, self.now_s()))
        self.published += 1
        return grid

    def save(self, path: str) -> Path | None:
        """Save the fused map as a nav2 map; None (and a log line) when no camera reported."""
        grid = self.fusion.grid()
        if grid is None:
            self.log(f"no floor summary received: nothing saved to {path}", "warn", private=True)
            return None
        ypath, ipath = save_nav2_map(grid, path)
        print(f"saved {ypath} and {ipath.name}: {grid.width} x {grid.height} cells of {grid.resolution_m} m from "
              f"cameras {', '.join(self.fusion.cameras)}", file=sys.stderr)
        return ypath

    def diagnostics(self, now_s: float) -> DiagnosticReport:
        since = self._last_summary_s if self._last_summary_s is not None else self._started_s
        quiet = now_s - since > float(self.values["no_summary_warning_s"])
        warning = (f"no floor summary for {now_s - since:.0f} s (is floor_map_period_s > 0 on the cameras?)"
                   if quiet else "")
        values = {"cameras": str(len(self.fusion.cameras)), "summaries_received": str(self.received),
                  "summaries_rejected": str(self.rejected), "grids_published": str(self.published),
                  "subscribed_topics": str(len(self._subs)),
                  **{k: str(v) for k, v in self.control_values().items()}}  # ~/change_state_sealed
        return DiagnosticReport(self.get_name(), self.get_fully_qualified_name(),
                                DiagnosticLevel.WARN if quiet else DiagnosticLevel.OK, warning or "ok", values)


def _wait_once(node: MapNode, cameras: list[str], timeout_s: float, settle_s: float) -> str:
    """Spin until every camera of ``cameras`` (or the first one + ``settle_s``) reported; '' or why not."""
    import rclpy

    deadline = time.monotonic() + timeout_s
    first_at: float | None = None
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        have = set(node.fusion.cameras)
        if cameras and set(cameras) <= have:
            return ""
        if not cameras and have:
            first_at = first_at if first_at is not None else time.monotonic()
            if time.monotonic() - first_at >= settle_s:
                return ""
    missing = sorted(set(cameras) - set(node.fusion.cameras)) if cameras else ["any camera"]
    return f"no floor summary from {', '.join(missing)} within {timeout_s:g} s (is floor_map_period_s > 0 there?)"


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    argv = list(sys.argv if argv is None else argv)
    ros_at = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    own, ros_args = argv[1:ros_at], argv[ros_at:]
    if any(a in ("-h", "--help") for a in own):
        print(USAGE + TABLE.help_text())
        return 0
    parser = argparse.ArgumentParser(prog="face-reid-map", add_help=False)
    parser.add_argument("--save", default="", help="nav2 map YAML to write (with --once: then exit)")
    parser.add_argument("--once", action="store_true")
    parser.add_argument("--cameras", default="", help="comma-separated camera ids --once waits for")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--settle", type=float, default=3.0)
    args = parser.parse_args(own)
    if args.once and not args.save:
        print("face-reid-map: --once needs --save PATH", file=sys.stderr)
        return 2
    if not args.once:
        return run_node("face-reid-map", USAGE, TABLE, lambda: MapNode(args.save or None), [argv[0], *ros_args])
    return _run_once(args, [argv[0], *ros_args])


def _run_once(args: argparse.Namespace, ros_argv: list[str]) -> int:
    """``--save PATH --once``: configure, activate, wait for the cameras, save, stop."""
    import rclpy

    node = start_node("face-reid-map", ros_argv, lambda: MapNode(args.save))
    if isinstance(node, int):
        return node
    status = 0
    try:
        node.quiet_failures = True
        if node.trigger_configure() != TransitionCallbackReturn.SUCCESS or \
                node.trigger_activate() != TransitionCallbackReturn.SUCCESS:
            return fatal_start("face-reid-map", node.failure)
        why = _wait_once(node, [c for c in args.cameras.split(",") if c], args.timeout, args.settle)
        if why:
            print(f"face-reid-map: {why}", file=sys.stderr)
            status = 1
        else:
            node.publish_grid(force=True)
            if node.save(args.save) is None:
                status = 1
    except KeyboardInterrupt:
        status = 130
    finally:
        node._save_override = ""  # saved above (or nothing to save): not again on the way out
        node.values["save_path"] = ""
        node.release()
        node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == "__main__":
    sys.exit(main())
