"""Ground truth of a simulated scenario: who is where, facing where, seen by which camera, and the track losses."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.sim.crowd import closest_approach
from face_reid_master.sim.motion import sample_trajectories
from face_reid_master.sim.visibility import camera_views, count_losses
from face_reid_master.sim.world import World

if TYPE_CHECKING:
    from face_reid_master.sim.simulate import Day, SimConfig

__all__ = ["sample_ground_truth"]


def sample_ground_truth(cfg: SimConfig, world: World, days: list[Day], heights_all: NDArray[np.float64]
                        ) -> tuple[dict[str, NDArray[Any]], list[dict[str, Any]]]:
    """The ``ground_truth.npz`` arrays (trajectories and visibility sampled at ``ground_truth_rate_hz``) and the
    losses per day (for the scenario summary), with the closest two people in the room came and how they gave way."""
    n_id, n_cam = heights_all.size, len(world.cameras)
    parts_t, parts_day, parts_xy, parts_fac, parts_room, parts_view, parts_face = [], [], [], [], [], [], []
    loss_info = []
    for day in days:
        t = day.start_s + np.arange(0.0, cfg.duration_s, 1.0 / cfg.ground_truth_rate_hz)
        xy, facing = sample_trajectories(day.trajectories, t)
        in_room = world.room.contains(xy)
        heights = heights_all[day.gt_ids]
        view, face = camera_views(world.cameras, xy, facing, heights, in_room, cfg.visibility)
        losses = count_losses(t, view.any(axis=2).T, cfg.loss_gap_s)
        loss_info.append({
            "day": day.day,
            "losses": losses.total_losses,
            "visible_segments": losses.total_segments,
            "losses_per_person": {str(gt): int(n) for gt, n in zip(day.gt_ids, losses.losses, strict=True)},
            "segments": {str(gt): [[round(a, 3), round(b, 3)] for a, b in seg]
                         for gt, seg in zip(day.gt_ids, losses.segments, strict=True)},
            "exits": int(((~in_room[1:]) & in_room[:-1]).sum()),
            "in_view_fraction": round(float(view.any(axis=2).mean()), 4),
            "face_visible_fraction": round(float(face.any(axis=2).mean()), 4),
        })
        closest = closest_approach(xy, in_room)  # two people in the room at once, at the ground truth's samples
        loss_info[-1]["closest_approach_m"] = round(closest, 4) if np.isfinite(closest) else None
        if day.crowd is not None:
            loss_info[-1]["giving_way"] = {  # how people kept the passing distance (face_reid_master.sim.crowd)
                "slowed_share": round(day.crowd.slowed_share, 4),
                "aside_share": round(day.crowd.aside_share, 4),
                "max_delay_s": round(day.crowd.max_delay_s, 2),
                "blocked_steps": day.crowd.stood_steps,
            }
        full_xy = np.full((n_id, t.size, 2), np.nan, dtype=np.float32)
        full_fac = np.full((n_id, t.size), np.nan, dtype=np.float32)
        full_room = np.zeros((n_id, t.size), dtype=bool)
        full_view = np.zeros((n_id, t.size, n_cam), dtype=bool)
        full_face = np.zeros_like(full_view)
        ids = np.asarray(day.gt_ids)
        full_xy[ids] = xy.transpose(1, 0, 2)
        full_fac[ids] = facing.T
        full_room[ids] = in_room.T
        full_view[ids] = view.transpose(1, 0, 2)
        full_face[ids] = face.transpose(1, 0, 2)
        parts_t.append(t)
        parts_day.append(np.full(t.size, day.day, dtype=np.int8))
        parts_xy.append(full_xy)
        parts_fac.append(full_fac)
        parts_room.append(full_room)
        parts_view.append(full_view)
        parts_face.append(full_face)
    arrays = {
        "t_s": np.concatenate(parts_t),
        "day": np.concatenate(parts_day),
        "gt_id": np.arange(n_id, dtype=np.int32),
        "xy": np.concatenate(parts_xy, axis=1),
        "facing_rad": np.concatenate(parts_fac, axis=1),
        "in_room": np.concatenate(parts_room, axis=1),
        "in_view": np.concatenate(parts_view, axis=1),
        "face_visible": np.concatenate(parts_face, axis=1),
    }
    return arrays, loss_info
