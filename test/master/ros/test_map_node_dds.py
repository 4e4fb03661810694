"""face-reid-map over DDS: a camera's floor output (FloorMapOutput, as the camera node runs it, fed rendered depth)
publishes FloorOccupancy -> the map node discovers and fuses it -> an OccupancyGrid arrives on /camera_map; the
saved nav2 map holds the same grid; a malformed summary is refused and counted."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import spin_until

pytest.importorskip("rclpy")
pytest.importorskip("nav_msgs.msg")

pytestmark = pytest.mark.ros


def test_floor_summary_to_occupancy_grid(ros_context, tmp_path: Path) -> None:
    from nav_msgs.msg import OccupancyGrid
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.lifecycle import TransitionCallbackReturn
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
    from face_reid_camera.common.ros.floor_map import FLOOR_MAP_QOS, snapshot_from_msg, snapshot_to_msg
    from face_reid_camera.people.floor_occupancy import FloorOccupancyConfig
    from face_reid_camera.ros.floor_map_output import FloorMapOutput
    from face_reid_master.robot.camera_map import FREE, OCCUPIED, load_nav2_map
    from face_reid_master.ros.map_node import MapNode
    from face_reid_master.sim.renderer import render_scene
    from face_reid_msgs.msg import FloorOccupancy

    ctx = ros_context(["--ros-args", "-p", "publish_period_s:=0.1", "-p", "discovery_period_s:=0.1"])
    camera = Node("camera", namespace="cam1", context=ctx)
    probe = Node("probe", context=ctx)
    mapper = MapNode(str(tmp_path / "on_exit.yaml"), context=ctx)
    assert mapper.trigger_configure() == TransitionCallbackReturn.SUCCESS
    assert mapper.trigger_activate() == TransitionCallbackReturn.SUCCESS
    executor = SingleThreadedExecutor(context=ctx)
    for n in (camera, probe, mapper):
        executor.add_node(n)
    grids: list = []
    probe.create_subscription(OccupancyGrid, "/camera_map", grids.append,
                              QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                         durability=DurabilityPolicy.TRANSIENT_LOCAL))
    try:
        K = CameraIntrinsics.kinect_default(640, 480)
        pose = CameraPose.looking_at(np.array([2.8, -2.8, 2.6]), np.array([-0.9, 0.9, 0.0]))
        depth = render_scene([], K, pose, walls=True, floor_size_m=6.0).depth_mm.astype(np.float32) / 1000.0
        output = FloorMapOutput(camera, FloorOccupancyConfig(period_s=30.0, max_range_m=7.0, max_cells=100_000,
                                                             depth_stride_px=2),
                                "cam1", pose, "world")
        output.activate()
        output.frame(1.0, depth, K)  # the first counted frame is published at once
        assert output.published == 1
        assert spin_until(executor, lambda: len(grids) > 0, 20.0), "no OccupancyGrid on /camera_map"
        msg = grids[-1]
        assert msg.header.frame_id == "world" and mapper.fusion.cameras == ["cam1"]
        data = np.asarray(msg.data, dtype=np.int8).reshape(msg.info.height, msg.info.width)
        r, ox, oy = msg.info.resolution, msg.info.origin.position.x, msg.info.origin.position.y

        def value(x: float, y: float) -> int:
            return int(data[int(np.floor((y - oy) / r)), int(np.floor((x - ox) / r))])

        def occupied_near(x: float, y: float) -> bool:
            return any(value(x + dx, y + dy) == OCCUPIED for dx in (-0.05, 0.0, 0.05) for dy in (-0.05, 0.0, 0.05))

        assert occupied_near(-3.0, 0.0) and occupied_near(0.5, 3.0)  # the two far walls
        # open floor: free (sampled at cell centres, away from float32 rounding at cell borders)
        assert not occupied_near(0.0, 0.0) and value(0.025, 0.025) == FREE and value(-0.975, 1.025) == FREE

        # the saved nav2 map is the published grid
        saved = mapper.save(str(tmp_path / "cameras.yaml"))
        assert saved is not None
        loaded = load_nav2_map(saved)
        assert np.array_equal(loaded.data, data)
        assert (loaded.origin_x_m, loaded.origin_y_m) == pytest.approx((ox, oy))

        # message round trip, and a malformed summary is refused and counted
        snap = snapshot_from_msg(snapshot_to_msg(output._acc.snapshot(), "world"))
        assert snap.camera_id == "cam1" and snap.floor_counts.sum() > 0 and snap.stamp_s == 1.0
        bad = FloorOccupancy(camera_id="cam2", width=3, height=2, resolution_m=0.05)
        bad.floor_counts = [1, 2, 3]
        pub = camera.create_publisher(FloorOccupancy, "/cam2/face_reid/floor_occupancy", FLOOR_MAP_QOS)
        pub.publish(bad)
        assert spin_until(executor, lambda: mapper.rejected == 1, 20.0), "the malformed summary was not seen"
        assert mapper.fusion.cameras == ["cam1"]
        report = mapper.diagnostics(mapper.now_s())
        assert report.values["cameras"] == "1" and report.values["summaries_rejected"] == "1"
        assert int(report.values["grids_published"]) >= 1
        # a lifecycle node: deactivating saves the map to save_path and stops publishing
        assert mapper.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        assert np.array_equal(load_nav2_map(tmp_path / "on_exit.yaml").data, data) and mapper.publisher is None
    finally:
        for n in (camera, probe, mapper):
            executor.remove_node(n)
            n.destroy_node()
