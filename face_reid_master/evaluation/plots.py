"""Figures of one evaluated run: tracks per person over time, a top-down map of true paths and tracks, and the
reliability diagram of its identity decisions."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_master.evaluation.calibration import run_decisions, save_reliability_plot
from face_reid_master.evaluation.metrics import track_outcomes
from face_reid_master.evaluation.runner import RunLog

__all__ = ["save_plots"]

_COLOURS = {"success": "tab:green", "failure": "tab:red", "pending": "0.6"}
_DAY_GAP_PLOT_S = 10.0  # gap drawn between consecutive days on the timeline


def save_plots(run: RunLog, scenario: Any, prefix: str, title: str = "") -> list[Path]:
    """PREFIX_timeline.png (tracks per person over time), PREFIX_map.png (top-down view) and
    PREFIX_reliability.png (are the identity posteriors right as often as they say)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch, Rectangle, Wedge

    base = Path(prefix)
    base.parent.mkdir(parents=True, exist_ok=True)
    names = {int(i["gt_id"]): str(i["name"]) for i in scenario.identities}
    outcomes = {o.track_id: o for o in track_outcomes(run)}
    persons = sorted(names)
    row = {p: k for k, p in enumerate(persons)}
    colours = plt.get_cmap("tab10" if len(persons) <= 10 else "tab20")

    # timeline; later days are shifted left to follow the previous day after a short gap
    days = sorted(scenario.days, key=lambda d: d["day"])
    shifts: list[tuple[float, float]] = []  # (day start, shift)
    shift = 0.0
    for k, day in enumerate(days):
        if k:
            shift += float(day["start_s"]) - float(days[k - 1]["end_s"]) - _DAY_GAP_PLOT_S
        shifts.append((float(day["start_s"]), shift))

    def tx(t: float) -> float:
        return t - max((sh for start, sh in shifts if t >= start - _DAY_GAP_PLOT_S / 2), default=0.0)

    fig, ax = plt.subplots(figsize=(12, 1.0 + 0.45 * len(persons)))
    for k, day in enumerate(days[1:], start=2):
        x = tx(float(day["start_s"])) - _DAY_GAP_PLOT_S / 2
        ax.axvline(x, color="k", ls=":", lw=1)
        ax.text(x, -0.55, f" day {k}", fontsize=7, va="top")
    for day in scenario.summary.get("per_day", []):
        for gt, segs in (day.get("segments") or {}).items():
            for a, b in segs:
                ax.plot([tx(a), tx(b)], [row[int(gt)] - 0.32] * 2, color="k", lw=1.0)
    lane: dict[int, int] = {}
    for o in sorted(outcomes.values(), key=lambda o: o.birth_s):
        t = run.tracks[o.track_id]
        y = row.get(o.person)
        if y is None:
            continue
        lane[o.person] = (lane.get(o.person, -1) + 1) % 3
        yy = y - 0.18 + 0.16 * lane[o.person]
        decided = o.decided_s if o.decided_s is not None else t.last_seen_s
        ax.plot([tx(t.birth_s), tx(min(decided, t.last_seen_s))], [yy, yy], color=_COLOURS["pending"], lw=4,
                solid_capstyle="butt")
        if o.decided_s is not None:
            ax.plot([tx(o.decided_s), tx(max(o.decided_s, t.last_seen_s))], [yy, yy], color=_COLOURS[o.outcome],
                    lw=4, solid_capstyle="butt")
            ax.text(tx(o.decided_s), yy + 0.05, str(o.face_id), fontsize=6, va="bottom")
    ax.set_yticks(range(len(persons)), [f"{p}: {names[p]}" for p in persons], fontsize=7)
    ax.set_ylim(-0.6, len(persons) - 0.4)
    ax.invert_yaxis()
    ax.set_xlabel("time [s]" + (" (later days shifted to follow the previous one)" if len(days) > 1 else ""))
    ax.set_title(f"{title}  tracks per person (label: face id; black: true visible segments)", fontsize=9)
    ax.legend(handles=[Patch(color=_COLOURS["success"], label="correct face id"),
                       Patch(color=_COLOURS["failure"], label="wrong face id"),
                       Patch(color=_COLOURS["pending"], label="pending / none")], fontsize=7, loc="upper right")
    fig.tight_layout()
    timeline = base.parent / f"{base.name}_timeline.png"
    fig.savefig(timeline, dpi=120)
    plt.close(fig)

    # map
    doc = scenario.document
    w, d = float(doc["room"]["width_m"]), float(doc["room"]["depth_m"])
    fig, ax = plt.subplots(figsize=(8, 8 * d / w + 0.5))
    ax.add_patch(Rectangle((-w / 2, -d / 2), w, d, fill=False, lw=1.5, color="k"))
    for door in doc.get("doors", []):
        cx, cy = door["centre_xy"]
        ax.plot([cx], [cy], marker="s", color="saddlebrown", ms=8)
    max_range = float(doc.get("parameters", {}).get("visibility", {}).get("max_range_m", 6.0))
    for cam in scenario.cameras:
        pos = cam.pose.translation
        fwd = cam.pose.rotation[:, 2]
        heading = math.degrees(math.atan2(fwd[1], fwd[0]))
        half = math.degrees(math.atan2(cam.intrinsics.width / 2.0, cam.intrinsics.fx))
        ax.add_patch(Wedge((pos[0], pos[1]), max_range, heading - half, heading + half, alpha=0.08, color="tab:blue"))
        ax.plot([pos[0]], [pos[1]], marker="^", color="tab:blue", ms=9)
        ax.text(pos[0], pos[1], f" {cam.camera_id}", fontsize=7)
    gt = scenario.ground_truth
    for p in persons:
        xy = gt.xy[p]
        ax.plot(xy[:, 0], xy[:, 1], lw=0.6, color=colours(row[p] % colours.N), alpha=0.5)
    for t in run.tracks.values():
        if not t.path or t.true_person < 0:
            continue
        arr = np.asarray(t.path)
        ax.plot(arr[:, 1], arr[:, 2], lw=1.0, ls="--", color=colours(row.get(t.true_person, 0) % colours.N))
    ax.legend(handles=[Patch(color=colours(row[p] % colours.N), label=f"{p}: {names[p]}") for p in persons],
              fontsize=6, loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlim(-w / 2 - 2, w / 2 + 2)
    ax.set_ylim(-d / 2 - 2, d / 2 + 2)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{title}  true paths (solid) and tracks (dashed, colour = true person)", fontsize=9)
    fig.tight_layout()
    map_path = base.parent / f"{base.name}_map.png"
    fig.savefig(map_path, dpi=120)
    plt.close(fig)

    reliability = base.parent / f"{base.name}_reliability.png"
    save_reliability_plot(run_decisions(run), str(reliability), thresholds=run.decision_thresholds, title=title)
    return [timeline, map_path, reliability]
