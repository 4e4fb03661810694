"""The camera's floor occupancy summary on rendered rooms: walls, a person and a cabinet land in the obstacle band
at their world positions, the open floor is counted as floor only; the grid stays bounded."""

from __future__ import annotations

import numpy as np
import pytest

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.floor_snapshot import FloorOccupancySnapshot
from face_reid_camera.people.floor_occupancy import (
    FloorOccupancyAccumulator,
    FloorOccupancyConfig,
)
from face_reid_master.sim.renderer import SyntheticPerson, clutter_object, render_scene

K = CameraIntrinsics.kinect_default(320, 240)
HALF = 3.0  # the room is 6 x 6 m, walls on x, y = +-3 m
PERSON_XY = (0.8, 0.9)
CABINET_XY = (-1.5, 2.0)  # 0.6 x 0.44 m footprint
POSES = [CameraPose.looking_at(np.array([2.8, -2.8, 2.6]), np.array([-0.9, 0.9, 0.0])),
         CameraPose.looking_at(np.array([-2.8, -2.8, 2.6]), np.array([0.9, 0.9, 0.0]))]
CONFIG = FloorOccupancyConfig(period_s=5.0, depth_stride_px=2, max_range_m=7.0, max_cells=100_000)


def _room_snapshots() -> list[FloorOccupancySnapshot]:
    people = [SyntheticPerson(*PERSON_XY, height_m=1.75, facing_rad=2.0)]
    objects = clutter_object("cabinet", *CABINET_XY)
    snaps = []
    for n, pose in enumerate(POSES):
        acc = FloorOccupancyAccumulator(CONFIG, f"cam{n}", tuple(pose.translation[:2]))
        for k in range(2):
            frame = render_scene(people, K, pose, walls=True, floor_size_m=2 * HALF, objects=objects,
                                 rng=np.random.default_rng(k))
            acc.add_depth(frame.depth_mm.astype(np.float32) / 1000.0, K, pose, stamp_s=10.0 + k)
        snap = acc.snapshot()
        assert snap is not None and snap.frames == 2 and snap.stamp_s == 11.0
        snaps.append(snap)
    return snaps


def _centres(snap: FloorOccupancySnapshot, mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.stack([snap.origin_x_m + (cols + 0.5) * snap.resolution_m,
                     snap.origin_y_m + (rows + 0.5) * snap.resolution_m], axis=1)


def _distance_to_surfaces(xy: np.ndarray) -> np.ndarray:
    """Distance (m) of world points to the nearest wall, the cabinet's footprint or the person's axis (0.25 m)."""
    wall = np.min(np.abs(np.abs(xy) - HALF), axis=1)
    cab = np.hypot(np.maximum(np.abs(xy[:, 0] - CABINET_XY[0]) - 0.3, 0), np.maximum(np.abs(xy[:, 1] - CABINET_XY[1])
                                                                                     - 0.22, 0))
    person = np.maximum(np.hypot(xy[:, 0] - PERSON_XY[0], xy[:, 1] - PERSON_XY[1]) - 0.25, 0)
    return np.minimum(np.minimum(wall, cab), person)


@pytest.fixture(scope="module")
def snapshots() -> list[FloorOccupancySnapshot]:
    return _room_snapshots()


def test_band_cells_are_walls_people_and_objects_at_their_world_positions(snapshots) -> None:
    for snap in snapshots:
        band = snap.occupied_counts >= 3
        centres = _centres(snap, band)
        dist = _distance_to_surfaces(centres)
        assert len(centres) > 100, f"{snap.camera_id}: only {len(centres)} obstacle cells"
        # within 1.5 cells of a true surface (a cell centre is up to 0.035 m off it, plus depth noise)
        assert dist.max() <= 0.08, (
            f"{snap.camera_id}: obstacle cells off the true surfaces: p98 {np.percentile(dist, 98):.3f} m, "
            f"max {dist.max():.3f} m")
        # the far walls (x = -3 or +3 and y = +3, facing the camera) are seen along most of their length
        far_wall = centres[np.abs(centres[:, 1] - HALF) < 0.08]
        assert np.ptp(far_wall[:, 0]) > 2.0, f"{snap.camera_id}: the y = +3 m wall spans {np.ptp(far_wall[:, 0])} m"
        # the person and the cabinet are in the band
        near_person = np.hypot(centres[:, 0] - PERSON_XY[0], centres[:, 1] - PERSON_XY[1]) < 0.3
        near_cabinet = (np.abs(centres[:, 0] - CABINET_XY[0]) < 0.35) & (np.abs(centres[:, 1] - CABINET_XY[1]) < 0.3)
        assert near_person.sum() >= 2 and near_cabinet.sum() >= 3, (
            f"{snap.camera_id}: person cells {near_person.sum()}, cabinet cells {near_cabinet.sum()}")


def test_open_floor_is_counted_as_floor_only(snapshots) -> None:
    for snap in snapshots:
        floor_cells = _centres(snap, (snap.floor_counts > 0) & (snap.occupied_counts == 0))
        open_floor = floor_cells[_distance_to_surfaces(floor_cells) > 0.3]
        assert len(open_floor) > 2000, f"{snap.camera_id}: {len(open_floor)} floor-only cells in the open"
        mixed = _centres(snap, snap.occupied_counts > 0)
        assert _distance_to_surfaces(mixed).max() < 0.2, "band points over open floor"
        # the centre of the room is open floor (seen by both cameras)
        centre = _centres(snap, snap.floor_counts > 0)
        assert np.any(np.hypot(centre[:, 0] + 0.5, centre[:, 1] + 0.5) < 0.05)


def test_snapshots_are_on_one_world_lattice_and_bounded(snapshots) -> None:
    for snap in snapshots:
        r = snap.resolution_m
        assert snap.origin_x_m / r == pytest.approx(round(snap.origin_x_m / r), abs=1e-6)
        assert snap.origin_y_m / r == pytest.approx(round(snap.origin_y_m / r), abs=1e-6)
        assert snap.width * snap.height <= CONFIG.max_cells
        assert snap.floor_counts.dtype == np.uint16 and snap.floor_counts.shape == (snap.height, snap.width)
        # the room is 6 m: nothing is counted beyond its walls (plus depth noise)
        assert snap.origin_x_m >= -HALF - 0.2 and snap.origin_x_m + snap.width * r <= HALF + 0.2


def test_range_band_and_floor_tolerance_select_points() -> None:
    cfg = FloorOccupancyConfig(period_s=1.0, max_range_m=2.0, resolution_m=0.1, max_cells=2000)
    acc = FloorOccupancyAccumulator(cfg, "c", (0.0, 0.0))
    pts = np.array([[0.55, 0.55, 0.0],    # floor
                    [0.55, 0.55, 0.2],    # band
                    [0.55, 0.55, 0.07],   # between floor and band: ignored
                    [0.55, 0.55, 0.5],    # above the band: ignored
                    [2.5, 0.0, 0.2],      # beyond max_range_m: ignored
                    [-0.05, -0.05, 0.02],  # floor in cell (-1, -1)
                    [np.nan, 0.0, 0.0]])
    acc.add_points(pts, stamp_s=3.0)
    snap = acc.snapshot()
    assert snap is not None
    assert (snap.origin_x_m, snap.origin_y_m) == pytest.approx((-0.1, -0.1))
    assert (snap.width, snap.height) == (7, 7)
    assert snap.floor_counts.sum() == 2 and snap.occupied_counts.sum() == 1
    assert snap.floor_counts[6, 6] == 1 and snap.occupied_counts[6, 6] == 1 and snap.floor_counts[0, 0] == 1


def test_counts_halve_instead_of_overflowing() -> None:
    cfg = FloorOccupancyConfig(period_s=1.0, max_range_m=1.0, max_cells=2000)
    acc = FloorOccupancyAccumulator(cfg, "c", (0.0, 0.0))
    floor = np.tile([[0.01, 0.01, 0.0]], (30_000, 1))
    band = np.tile([[0.01, 0.01, 0.2]], (10_000, 1))
    for _ in range(4):
        acc.add_points(np.concatenate([floor, band]), 0.0)
    snap = acc.snapshot()
    assert snap is not None
    f, o = int(snap.floor_counts.max()), int(snap.occupied_counts.max())
    assert f <= 65535 and f > 30_000 and f == 3 * o


def test_every_nth_frame_and_off_by_default() -> None:
    assert not FloorOccupancyConfig().enabled
    acc = FloorOccupancyAccumulator(FloorOccupancyConfig(period_s=1.0, every_frames=3), "c", (0.0, 0.0))
    assert [acc.due() for _ in range(7)] == [True, False, False, True, False, False, True]
    assert acc.snapshot() is None


@pytest.mark.parametrize("kwargs,name", [
    ({"min_height_m": 0.3, "max_height_m": 0.1}, "min_height_m"),
    ({"floor_tolerance_m": 0.2}, "floor_tolerance_m"),
    ({"max_range_m": 20.0}, "max_cells"),
    ({"resolution_m": 0.0}, "resolution_m"),
    ({"period_s": -1.0}, "period_s"),
])
def test_bad_config_is_named(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        FloorOccupancyConfig(**kwargs)


def test_bad_snapshot_is_refused() -> None:
    ok = {"camera_id": "c", "stamp_s": 0.0, "resolution_m": 0.05, "origin_x_m": 0.0, "origin_y_m": 0.0,
          "min_height_m": 0.1, "max_height_m": 0.3, "frames": 1,
          "floor_counts": np.zeros((2, 3)), "occupied_counts": np.zeros((2, 3))}
    FloorOccupancySnapshot(**ok)
    with pytest.raises(ValueError, match="occupied_counts"):
        FloorOccupancySnapshot(**{**ok, "occupied_counts": np.zeros((3, 2))})
    with pytest.raises(ValueError, match="resolution_m"):
        FloorOccupancySnapshot(**{**ok, "resolution_m": -1.0})
    with pytest.raises(ValueError, match="floor_counts"):
        FloorOccupancySnapshot(**{**ok, "floor_counts": np.full((2, 3), 70_000)})
