"""Tests of the simulator's world: the reference room and its scaling, cameras on the walls, doors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from face_reid_master.sim.visibility import coverage_fraction
from face_reid_master.sim.world import Room, make_world, room_size_for


def test_reference_room_is_10_by_8_and_scales_with_cameras() -> None:
    room = room_size_for(3)
    assert (room.width_m, room.depth_m) == (10.0, 8.0)
    big = room_size_for(6)
    assert big.width_m * big.depth_m == pytest.approx(160.0, rel=0.03)
    with pytest.raises(ValueError, match="num_cameras"):
        room_size_for(0)
    with pytest.raises(ValueError, match="width_m"):
        Room(1.0, 8.0)


def test_world_cameras_hang_on_walls_and_look_into_the_room() -> None:
    world = make_world(3, np.random.default_rng(5))
    half = world.room.half_extents
    assert len(world.cameras) == 3 and len(world.doors) == 2
    for cam in world.cameras:
        x, y, z, roll, pitch, yaw = cam.xyz_rpy
        on_wall = min(half[0] - abs(x), half[1] - abs(y))
        assert 0.0 <= on_wall <= 0.06
        assert 2.2 <= z <= 2.6 and math.radians(15) <= pitch <= math.radians(25) and roll == 0.0
        # the optical axis points into the room: 2 m ahead is inside
        ahead = np.array([x, y]) + 2.0 * np.array([math.cos(yaw), math.sin(yaw)])
        assert world.room.contains(ahead)
        # the camera sees part of the room
        assert coverage_fraction(type(world)(world.room, (cam,), world.doors)) > 0.1
    for door in world.doors:
        assert not world.room.contains(door.outside_xy) and world.room.contains(door.inside_xy)
        # doors keep away from the cameras
        assert min(np.linalg.norm(door.centre_xy - c.position[:2]) for c in world.cameras) > 1.5
    assert 0.45 <= coverage_fraction(world) <= 0.9
    again = make_world(3, np.random.default_rng(5))
    assert [c.xyz_rpy for c in again.cameras] == [c.xyz_rpy for c in world.cameras]

