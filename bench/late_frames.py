"""How late camera frames reach the tracker, and what a reorder buffer of N ms would cost instead of exact replay.

Offline evaluation feeds frames in stamp order (no frame is late there); live, each camera's frame reaches the
master after its camera pipeline (which depends on the faces and people in it), DDS, and its host's clock offset.
This takes a scenario's frames (camera, stamp, faces, people) and a delay model per frame:
``base_ms + face_ms * min(faces, budget_faces) + body_ms * people`` scaled by a log-normal jitter, plus the DDS
latency and a per-camera clock offset, and reports:

- today (exact late-frame replay, each frame applied on arrival): how many frames are older than the newest
  applied stamp when they arrive, and by how much (histogram, ms);
- a reorder buffer of N ms (frames released in stamp order once the master's clock is N ms past their stamp):
  the latency it adds (frame arrival to application) and the frames still late (delay > N: they would need
  the replay, or be dropped).

With ``--tracker-cost`` it also runs the tracker alone over the scenario's detections in stamp order and in the
modelled arrival order (exact replay of the late ones) and reports the time per frame and the tracks created.

Usage: python bench/late_frames.py SCENARIO_DIR [--base-ms 25 --face-ms 9 ...] [--tracker-cost] (prints JSON).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

EDGES_MS = (0, 1, 2, 5, 10, 20, 33, 50, 66, 100, 200, 300, 1e9)


def frame_table(directory: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(camera, stamp_s, faces, people) per frame of a scenario's frames.npz (in stamp order)."""
    z = np.load(directory / "frames.npz")
    offsets = z["frame_offsets"]
    has_face = (z["det_face"] >= 0).astype(np.int64)
    faces = np.add.reduceat(np.append(has_face, 0), offsets[:-1]) * (np.diff(offsets) > 0)
    return z["frame_camera"].astype(np.int64), z["frame_stamp_s"], faces, np.diff(offsets)


def delays_ms(camera: np.ndarray, faces: np.ndarray, people: np.ndarray, args: argparse.Namespace,
              rng: np.random.Generator) -> np.ndarray:
    """Stamp-to-arrival delay of each frame on the master's clock (ms), by the model in the module doc."""
    pipeline = args.base_ms + args.face_ms * np.minimum(faces, args.budget_faces) + args.body_ms * people
    pipeline = pipeline * rng.lognormal(0.0, args.jitter, size=pipeline.shape)
    dds = args.dds_ms + rng.exponential(args.dds_tail_ms, size=pipeline.shape)
    offset = rng.normal(0.0, args.clock_ms, size=int(camera.max()) + 1)  # each camera host's clock error
    return pipeline + dds - offset[camera]


def lateness_ms(stamp_s: np.ndarray, arrival_s: np.ndarray) -> np.ndarray:
    """Applied on arrival (ties: stamp order): how far each frame's stamp is behind the newest applied (ms, 0 when
    in order)."""
    order = np.lexsort((stamp_s, arrival_s))
    s = stamp_s[order]
    newest = np.maximum.accumulate(s)
    late = np.empty_like(s)
    late[0] = 0.0
    late[1:] = np.maximum(0.0, newest[:-1] - s[1:]) * 1e3
    out = np.empty_like(late)
    out[order] = late
    return out


def with_buffer(stamp_s: np.ndarray, arrival_s: np.ndarray, buffer_ms: float) -> dict[str, float]:
    """A reorder buffer: a frame is released at max(arrival, stamp + N) in stamp order; those arriving after their
    release time are late if a newer stamp was released before them."""
    release = np.maximum(arrival_s, stamp_s + buffer_ms * 1e-3)
    late = lateness_ms(stamp_s, release)
    added = (release - arrival_s) * 1e3
    n = len(stamp_s)
    return {"buffer_ms": buffer_ms, "added_latency_ms_median": round(float(np.median(added)), 1),
            "added_latency_ms_p95": round(float(np.percentile(added, 95)), 1),
            "stamp_to_apply_ms_median": round(float(np.median((release - stamp_s) * 1e3)), 1),
            "late_frames": int((late > 0).sum()), "late_share": round(float((late > 0).sum()) / n, 4),
            "late_ms_max": round(float(late.max()), 1)}


def histogram(late: np.ndarray) -> dict[str, int]:
    counts, _ = np.histogram(late[late > 0], bins=np.asarray(EDGES_MS, dtype=float))
    return {f"({EDGES_MS[i]:g},{EDGES_MS[i + 1]:g}]" if EDGES_MS[i + 1] < 1e9 else f">{EDGES_MS[i]:g}": int(c)
            for i, c in enumerate(counts)}


def tracker_cost(directory: Path, order: np.ndarray) -> dict[str, float]:
    """The tracker alone over the scenario's detections, frames in ``order``: time per frame, late frames applied
    (replayed), tracks created."""
    import time

    from face_reid_master.tracking.tracker import Tracker

    z = np.load(directory / "frames.npz")
    offsets, stamps, cameras = z["frame_offsets"], z["frame_stamp_s"], z["frame_camera"]
    pos, std, height = z["det_position"][:, :2].copy(), z["det_std_m"].astype(np.float64), \
        z["det_height_m"].astype(np.float64)
    tracker = Tracker()
    t0 = time.perf_counter()
    for i in order.tolist():
        a, b = offsets[i], offsets[i + 1]
        tracker.update_arrays(pos[a:b], std[a:b], height[a:b], float(stamps[i]), f"cam{cameras[i]}")
    elapsed = time.perf_counter() - t0
    st = tracker.stats
    return {"us_per_frame": round(elapsed / len(order) * 1e6, 1), "frames_applied_late": st.frames_out_of_order,
            "frames_rejected_late": st.frames_rejected_late, "tracks_created": st.tracks_created}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenario", type=Path)
    parser.add_argument("--base-ms", type=float, default=25.0, help="camera pipeline without faces or people")
    parser.add_argument("--face-ms", type=float, default=9.0, help="per face embedded")
    parser.add_argument("--budget-faces", type=int, default=4, help="faces embedded per frame at most (budget)")
    parser.add_argument("--body-ms", type=float, default=1.5, help="body description per person")
    parser.add_argument("--jitter", type=float, default=0.15, help="log-normal sigma of the pipeline time")
    parser.add_argument("--dds-ms", type=float, default=2.0, help="DDS latency floor")
    parser.add_argument("--dds-tail-ms", type=float, default=0.5, help="mean of DDS latency beyond the floor")
    parser.add_argument("--clock-ms", type=float, default=0.5, help="std of each camera host's clock offset")
    parser.add_argument("--buffers-ms", default="0,5,10,20,33,50,66,100")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tracker-cost", action="store_true", help="time the tracker in stamp / arrival order")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    camera, stamp, faces, people = frame_table(args.scenario)
    delay = delays_ms(camera, faces, people, args, rng)
    arrival = stamp + delay * 1e-3
    late = lateness_ms(stamp, arrival)
    result = {
        "scenario": str(args.scenario), "frames": len(stamp), "cameras": int(camera.max()) + 1,
        "model": {k: v for k, v in vars(args).items() if k not in ("scenario", "buffers_ms")},
        "delay_ms": {"median": round(float(np.median(delay)), 1), "p95": round(float(np.percentile(delay, 95)), 1),
                     "max": round(float(delay.max()), 1)},
        "today_exact_replay": {"late_frames": int((late > 0).sum()), "late_share": round(float((late > 0).mean()), 4),
                               "late_ms_median": round(float(np.median(late[late > 0])), 1) if (late > 0).any()
                               else 0.0, "late_ms_max": round(float(late.max()), 1),
                               "beyond_max_detection_delay_300ms": int((late > 300).sum()),
                               "histogram_ms": histogram(late)},
        "reorder_buffer": [with_buffer(stamp, arrival, float(n)) for n in args.buffers_ms.split(",")],
    }
    if args.tracker_cost:
        arrival_order = np.lexsort((stamp, arrival))
        stamp_order = np.arange(len(stamp))
        runs = {"stamp_order": [], "arrival_order": []}
        for _ in range(2):  # alternated: both see the same load
            runs["stamp_order"].append(tracker_cost(args.scenario, stamp_order))
            runs["arrival_order"].append(tracker_cost(args.scenario, arrival_order))
        result["tracker_cost"] = {k: min(v, key=lambda r: r["us_per_frame"]) for k, v in runs.items()}
    json.dump(result, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
