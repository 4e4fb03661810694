"""Latency of ``Tracker.update`` at 5 / 20 / 50 live tracks; prints one JSON object.

Steady state: N people on a grid walking in parallel, one camera at 30 Hz delivering
min(10, N) detections per frame (rotating through the people, so every track stays confirmed).
Also timed: a frame applied 50 ms late (out-of-order path), ``snapshots()`` and, as the baseline
that motivated the vectorised filter, one filterpy ``KalmanFilter`` object per track.

Run: python bench/tracker_bench.py [--frames 1500]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout, not an installed copy

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.kalman import ConstantVelocityModel
from face_reid_master.tracking.records import Detection
from face_reid_master.tracking.tracker import Tracker

RATE_HZ = 30.0
VELOCITY = np.array([0.5, 0.2])


def _grid(n: int) -> np.ndarray:
    side = int(np.ceil(np.sqrt(n)))
    return np.array([(1.5 * (k % side), 1.5 * (k // side)) for k in range(n)], dtype=float)


def _frame(start: np.ndarray, k: int, n_det: int, rng: np.random.Generator) -> tuple[float, list[Detection]]:
    t = k / RATE_HZ
    n = start.shape[0]
    idx = [(k * n_det + j) % n for j in range(n_det)]
    pos = start[idx] + VELOCITY * t + rng.normal(scale=0.05, size=(n_det, 2))
    return t, [Detection(p, 0.05) for p in pos]


def _stats_ms(samples: list[float]) -> dict[str, float]:
    a = np.asarray(samples) * 1e3
    return {"median_ms": round(float(np.median(a)), 4), "p95_ms": round(float(np.percentile(a, 95)), 4)}


def bench_tracker(n_tracks: int, n_frames: int) -> dict[str, object]:
    rng = np.random.default_rng(n_tracks)
    start = _grid(n_tracks)
    n_det = min(10, n_tracks)
    tracker = Tracker(TrackerConfig())
    frames = [_frame(start, k, n_det, rng) for k in range(n_frames + 60)]
    for t, dets in frames[:60]:  # 2 s warm-up: every track confirmed
        tracker.update(dets, t, "cam")
    assert tracker.num_tracks == n_tracks, tracker.num_tracks
    times, late_times = [], []
    for k, (t, dets) in enumerate(frames[60:]):
        t0 = time.perf_counter()
        tracker.update(dets, t, "cam")
        times.append(time.perf_counter() - t0)
        if k % 10 == 5:  # an extra frame from a second camera, 50 ms in the past
            t_late = t - 0.05
            late = [Detection(d.position_xy - VELOCITY * 0.05, 0.05) for d in dets]
            t0 = time.perf_counter()
            tracker.update(late, t_late, "cam2")
            late_times.append(time.perf_counter() - t0)
    snap_times = []
    for _ in range(100):
        t0 = time.perf_counter()
        tracker.snapshots()
        snap_times.append(time.perf_counter() - t0)
    s = tracker.stats
    assert tracker.num_tracks == n_tracks and s.tracks_created == n_tracks, s
    return {
        "tracks": n_tracks,
        "detections_per_frame": n_det,
        "update": _stats_ms(times),
        "update_late_frame_50ms": _stats_ms(late_times),
        "snapshots": _stats_ms(snap_times),
        "frames_out_of_order": s.frames_out_of_order,
    }


def bench_filterpy_baseline(n_tracks: int, n_det: int, n_frames: int) -> dict[str, float]:
    """Predict every track and update n_det of them with one filterpy KalmanFilter per track."""
    model = ConstantVelocityModel()
    rng = np.random.default_rng(0)
    kfs = [model.to_filterpy(rng.normal(size=2), 0.05) for _ in range(n_tracks)]
    times = []
    for _ in range(n_frames):
        z = rng.normal(size=(n_det, 2))
        t0 = time.perf_counter()
        for kf in kfs:
            model.filterpy_predict(kf, 1 / RATE_HZ)
        for j in range(n_det):
            kfs[j].update(z[j], R=0.0025 * np.eye(2))
        times.append(time.perf_counter() - t0)
    return _stats_ms(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1500)
    args = parser.parse_args()
    out: dict[str, object] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "frames_per_case": args.frames,
        "cases": [bench_tracker(n, args.frames) for n in (5, 20, 50)],
        "filterpy_per_track_objects_predict_update_only_50_tracks_10_det": bench_filterpy_baseline(
            50, 10, min(args.frames, 300)
        ),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
