"""Aligning a robot's map to the camera network's map on a simulated room: the camera map is built from rendered
depth (four ceiling cameras, floor summaries fused), the robot map is the room's true outline drawn in a map frame
shifted and rotated by a known transform (as a lidar SLAM map would show it). ICP from guesses 0.5 m / 10 deg off
must recover the transform within 5 cm / 1 deg; the errors are reported."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.people.floor_occupancy import FloorOccupancyAccumulator, FloorOccupancyConfig
from face_reid_master.robot.camera_map import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    CameraMapConfig,
    CameraMapFusion,
    OccupancyGridMap,
    save_nav2_map,
)
from face_reid_master.robot.frames import PlanarTransform, load_world_to_map
from face_reid_master.robot.map_align import align_maps, align_points
from face_reid_master.sim.renderer import clutter_object, render_scene
from face_reid_master.tools import align_map

K = CameraIntrinsics.kinect_default(320, 240)
HALF = 3.0  # 6 x 6 m room
PILLAR_XY, PILLAR_R = (1.0, -0.8), 0.2
CABINET_XY, CABINET_HALF = (-1.5, 2.0), (0.3, 0.22)  # the room is square: these break its symmetry
TRUE = PlanarTransform(1.3, -0.7, math.radians(25.0))  # world -> map
_D = 0.5 / math.sqrt(2.0)
GUESS_OFFSETS = [(_D, -_D, 10.0), (-0.5, 0.0, -10.0), (0.0, 0.5, 10.0), (-_D, -_D, -10.0)]  # m, m, deg: 0.5 m off


def _camera_map() -> OccupancyGridMap:
    objects = clutter_object("cabinet", *CABINET_XY) + clutter_object("pillar", *PILLAR_XY)
    cfg = FloorOccupancyConfig(period_s=1.0, depth_stride_px=2, max_range_m=7.0, max_cells=100_000)
    fusion = CameraMapFusion(CameraMapConfig())
    for n, (x, y) in enumerate([(2.8, 2.8), (-2.8, -2.8), (2.8, -2.8), (-2.8, 2.8)]):
        pose = CameraPose.looking_at(np.array([x, y, 2.6]), np.array([-0.3 * x, -0.3 * y, 0.0]))
        acc = FloorOccupancyAccumulator(cfg, f"cam{n}", (x, y))
        for k in range(3):
            frame = render_scene([], K, pose, walls=True, floor_size_m=2 * HALF, objects=objects,
                                 rng=np.random.default_rng(k))
            acc.add_depth(frame.depth_mm.astype(np.float32) / 1000.0, K, pose, stamp_s=float(k))
        snap = acc.snapshot()
        assert snap is not None
        fusion.update(snap)
    grid = fusion.grid()
    assert grid is not None
    return grid


def _surface_points() -> np.ndarray:
    """World points every 1 cm along the room's walls, the pillar and the cabinet's outline."""
    s = np.arange(-HALF, HALF, 0.01)
    walls = [np.stack([s, np.full_like(s, v)], 1) for v in (-HALF, HALF)]
    walls += [np.stack([np.full_like(s, v), s], 1) for v in (-HALF, HALF)]
    a = np.linspace(0, 2 * np.pi, 130, endpoint=False)
    pillar = np.stack([PILLAR_XY[0] + PILLAR_R * np.cos(a), PILLAR_XY[1] + PILLAR_R * np.sin(a)], 1)
    u = np.arange(-1.0, 1.0, 0.02)
    (cx, cy), (hx, hy) = CABINET_XY, CABINET_HALF
    cabinet = [np.stack([cx + hx * u, np.full_like(u, cy + hy * sg)], 1) for sg in (-1, 1)]
    cabinet += [np.stack([np.full_like(u, cx + hx * sg), cy + hy * u], 1) for sg in (-1, 1)]
    return np.concatenate([*walls, pillar, *cabinet])


def _robot_map(world_to_map: PlanarTransform, resolution: float = 0.05) -> OccupancyGridMap:
    """The room drawn in the map frame: outline cells occupied, the inside free, the rest unknown."""
    pts = world_to_map.apply(_surface_points())
    ox, oy = np.floor((pts.min(axis=0) - 0.5) / resolution) * resolution
    w, h = (math.ceil((pts[:, k].max() + 0.5 - o) / resolution) for k, o in ((0, ox), (1, oy)))
    rows, cols = np.mgrid[0:h, 0:w]
    centres = np.stack([ox + (cols.ravel() + 0.5) * resolution, oy + (rows.ravel() + 0.5) * resolution], axis=1)
    world = world_to_map.inverse().apply(centres)
    data = np.where(np.all(np.abs(world) < HALF, axis=1), FREE, UNKNOWN).astype(np.int8).reshape(h, w)
    data[np.floor((pts[:, 1] - oy) / resolution).astype(int), np.floor((pts[:, 0] - ox) / resolution).astype(int)] \
        = OCCUPIED
    return OccupancyGridMap(data, resolution, float(ox), float(oy), frame="map")


def _errors(found: PlanarTransform) -> tuple[float, float, float]:
    """(translation error m, yaw error deg, largest displacement of the room's outline m) against TRUE."""
    yaw = math.degrees(math.remainder(found.yaw_rad - TRUE.yaw_rad, 2 * math.pi))
    outline = _surface_points()
    worst = float(np.max(np.linalg.norm(found.apply(outline) - TRUE.apply(outline), axis=1)))
    return math.hypot(found.x_m - TRUE.x_m, found.y_m - TRUE.y_m), abs(yaw), worst


@pytest.fixture(scope="module")
def maps() -> tuple[OccupancyGridMap, OccupancyGridMap]:
    return _robot_map(TRUE), _camera_map()


def test_camera_map_of_the_room_has_its_walls(maps) -> None:
    _, camera = maps
    occupied = camera.cell_centres()
    wall_dist = np.min(np.abs(np.abs(occupied) - HALF), axis=1)
    assert len(occupied) > 500 and np.mean(wall_dist < 0.1) > 0.7, "the camera map should be mostly walls"
    assert camera.value_at(np.array([[0.0, 0.0], [-0.5, 0.5]])).tolist() == [FREE, FREE]
    assert camera.value_at(np.array([PILLAR_XY[0] + PILLAR_R - 0.01, PILLAR_XY[1]]))[0] == OCCUPIED


@pytest.mark.parametrize("offset", GUESS_OFFSETS,
                         ids=[f"{dx:+.2f}m{dy:+.2f}m{dyaw:+.0f}deg" for dx, dy, dyaw in GUESS_OFFSETS])
def test_icp_recovers_the_shift_and_rotation_from_a_guess_half_a_metre_and_ten_degrees_off(maps, offset) -> None:
    robot, camera = maps
    dx, dy, dyaw = offset
    guess = PlanarTransform(TRUE.x_m + dx, TRUE.y_m + dy, TRUE.yaw_rad + math.radians(dyaw))
    assert _errors(guess)[0] == pytest.approx(0.5, abs=1e-9) and _errors(guess)[1] == pytest.approx(10.0)
    result = align_maps(robot, camera, guess)
    err_m, err_deg, worst_m = _errors(result.world_to_map)
    report = (f"translation error {100 * err_m:.1f} cm, yaw error {err_deg:.2f} deg, outline moved at most "
              f"{100 * worst_m:.1f} cm; {result.describe()}")
    print(report)
    assert result.converged and err_m < 0.05 and err_deg < 1.0 and worst_m < 0.05, report
    assert result.inlier_fraction > 0.9 and result.rms_residual_m < 0.06, report


def test_the_direction_is_world_to_map(maps) -> None:
    """A point on the room's wall in the world lands on the robot map's wall through the result."""
    robot, camera = maps
    result = align_maps(robot, camera, TRUE)
    wall_world = np.array([[HALF, 0.5], [-1.0, -HALF], [CABINET_XY[0] + CABINET_HALF[0], CABINET_XY[1]]])
    on_map = result.world_to_map.apply(wall_world)
    nearest = np.min(np.linalg.norm(robot.cell_centres()[:, None] - on_map[None], axis=2), axis=0)
    assert np.all(nearest < 0.05), f"world wall points land {nearest} m from the robot map's occupied cells"
    assert _errors(result.world_to_map)[2] < 0.05


def test_too_few_occupied_cells_are_refused(maps) -> None:
    robot, _ = maps
    few = OccupancyGridMap(np.pad(np.full((1, 10), OCCUPIED, dtype=np.int8), 2, constant_values=FREE), 0.05)
    with pytest.raises(ValueError, match="camera map has 10 occupied cells"):
        align_maps(robot, few, TRUE)
    with pytest.raises(ValueError, match="robot map has 10 occupied cells"):
        align_maps(few, robot, TRUE)
    line = np.stack([np.arange(100) * 0.05, np.zeros(100)], axis=1)
    with pytest.raises(ValueError, match="no overlap"):
        align_points(line, line + 50.0, PlanarTransform.identity())


def test_cli_end_to_end(maps, tmp_path: Path, capsys) -> None:
    robot, camera = maps
    save_nav2_map(robot, tmp_path / "robot.yaml")
    save_nav2_map(camera, tmp_path / "camera.yaml")
    out = tmp_path / "world_to_map.yaml"
    guess = [str(TRUE.x_m - 0.3), str(TRUE.y_m + 0.4), str(math.degrees(TRUE.yaw_rad) + 10.0)]
    status = align_map.main([str(tmp_path / "robot.yaml"), "--camera-map", str(tmp_path / "camera.yaml"),
                             "--guess", *guess, "-o", str(out)])
    printed = capsys.readouterr()
    assert status == 0, printed.err
    assert "residual" in printed.out and "inliers" in printed.out
    transform, world_frame, map_frame = load_world_to_map(out)
    err_m, err_deg, worst_m = _errors(transform)
    assert (world_frame, map_frame) == ("world", "map")
    assert err_m < 0.05 and err_deg < 1.0 and worst_m < 0.05, f"CLI: {100 * err_m:.1f} cm, {err_deg:.2f} deg"
    assert "residual_m" in out.read_text()
    # bad input: one line on stderr, exit 1, nothing written
    (tmp_path / "bad.yaml").write_text("image: nope.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    out.unlink()
    status = align_map.main([str(tmp_path / "bad.yaml"), "--camera-map", str(tmp_path / "camera.yaml"),
                             "--guess", "0", "0", "0", "-o", str(out)])
    err = capsys.readouterr().err
    assert status == 1 and "nope.pgm" in err and len(err.strip().splitlines()) == 1 and not out.exists()
    # a guess far off: nothing pairs, refused
    status = align_map.main([str(tmp_path / "robot.yaml"), "--camera-map", str(tmp_path / "camera.yaml"),
                             "--guess", "40", "40", "0", "-o", str(out)])
    assert status == 1 and "no overlap" in capsys.readouterr().err and not out.exists()
