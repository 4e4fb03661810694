"""A picture of a demo run seen from above: the room, its doors and cameras, where each person really walked
(grey) and where the master's published tracks were, coloured by the name or face it gave them."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from face_reid_master.demo.report import label as track_label
from face_reid_master.demo.scenario import DemoScenario
from face_reid_master.evaluation.published_tracks import TrackMessage
from face_reid_master.records import STATE_CONFIRMED

UNDECIDED = "undecided"


def published_points(messages: Sequence[TrackMessage]) -> dict[str, np.ndarray]:
    """label -> (N, 2) positions of the confirmed tracks published under that label."""
    points: dict[str, list[tuple[float, float]]] = {}
    for msg in messages:
        for tr in msg.tracks:
            if tr.state == STATE_CONFIRMED:
                xy = (float(tr.position_xy[0]), float(tr.position_xy[1]))
                points.setdefault(track_label(tr, UNDECIDED), []).append(xy)
    return {label: np.array(xy, dtype=np.float64) for label, xy in points.items()}


def draw_floor_plan(scenario: DemoScenario, messages: Sequence[TrackMessage], path: Path) -> None:
    """Write the picture as PNG to ``path`` (matplotlib, no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    room = scenario.world.room
    half = room.half_extents
    fig, ax = plt.subplots(figsize=(8.0, 8.0 * min(1.2, max(0.6, room.depth_m / room.width_m))), dpi=100)
    ax.add_patch(plt.Rectangle((-half[0], -half[1]), room.width_m, room.depth_m, fill=False, lw=2.0, color="0.2"))
    for door in scenario.world.doors:
        tangent = np.array([-door.inward_normal[1], door.inward_normal[0]]) * door.width_m / 2.0
        ends = np.array([door.centre_xy - tangent, door.centre_xy + tangent])
        ax.plot(ends[:, 0], ends[:, 1], color="white", lw=4.0, solid_capstyle="butt")
        ax.annotate("door", door.centre_xy - 0.45 * door.inward_normal, ha="center", va="center", fontsize=8)
    t = scenario.truth_times()
    xy, inside = scenario.true_xy(t)
    for p, person in enumerate(scenario.people):
        path_xy = np.where(inside[:, p, None], xy[:, p], np.nan)
        ax.plot(path_xy[:, 0], path_xy[:, 1], color="0.75", lw=1.0, zorder=1)
        first = np.flatnonzero(inside[:, p])
        if first.size:
            ax.annotate(person.name, path_xy[first[0]], fontsize=8, color="0.4", xytext=(3, 3),
                        textcoords="offset points")
    colours = plt.get_cmap("tab10")
    for k, (label, pts) in enumerate(sorted(published_points(messages).items(), key=lambda kv: kv[0] == UNDECIDED)):
        colour = "0.55" if label == UNDECIDED else colours(k % 10)
        ax.scatter(pts[:, 0], pts[:, 1], s=6, color=colour, label=label, zorder=2)
    for cam in scenario.cameras:
        x, y, yaw = cam.xyz_rpy[0], cam.xyz_rpy[1], cam.xyz_rpy[5]
        ax.scatter([x], [y], marker="s", s=60, color="black", zorder=3)
        ax.annotate("", (x + 0.8 * np.cos(yaw), y + 0.8 * np.sin(yaw)), (x, y),
                    arrowprops={"arrowstyle": "->", "color": "black"})
        ax.annotate(cam.camera_id, (x, y), xytext=(4, -10), textcoords="offset points", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlim(-half[0] - 1.0, half[0] + 1.0)
    ax.set_ylim(-half[1] - 1.0, half[1] + 1.0)
    ax.set_xlabel("x (m, world frame)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"face-reid-demo (seed {scenario.seed}) from above: /tracks_named by the name or face given;\n"
                 "grey lines: where the people really walked", fontsize=9)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, markerscale=2.5, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
