"""Per-frame latency of the face identity layer (bayes_table.BayesIdentityManager), single thread.

One "frame" = every track reports one face embedding (add_observations) + one step(), i.e. the whole
per-camera-frame update including eq. 4 distances, likelihoods, Sinkhorn and decisions.  Wall-clock
median/p90/max and the median thread CPU time (less sensitive to other processes) are reported.
Scenarios per (tracks, learned faces), 50 features per face:
  * all_unassigned: every track is still unidentified (worst case: all need distances to all faces);
  * steady: 10% of the tracks (>= 1) unidentified, the others already carry a face (their observations
    only extend their own face's bounded feature set).
Synthetic embeddings with dlib-like statistics (same-person L2 ~0.45, different ~0.8).
Usage: PYTHONPATH=. python bench/face_table_bench.py [--frames N] [--out file.json]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from face_reid_master.identity.bayes_table import BayesIdentityManager  # noqa: E402
from face_reid_master.identity.records import LearnedFace  # noqa: E402
from face_reid_master.identity.sinkhorn import sinkhorn_with_slack  # noqa: E402

DIM = 128
CENTRE_SCALE = 0.8 / np.sqrt(2 * DIM)  # different-person distance ~0.8
NOISE_SCALE = 0.45 / np.sqrt(2 * DIM)  # same-person distance ~0.45
TARGET_MS = {(5, 20): 1.0, (20, 200): 2.0, (50, 2000): 10.0}


def _setup(n_tracks: int, n_faces: int, n_unassigned: int, feats_per_face: int, rng: np.random.Generator):
    centres = rng.normal(0.0, CENTRE_SCALE, (n_faces + n_tracks, DIM)).astype(np.float32)
    mgr = BayesIdentityManager(max_features_per_face=feats_per_face)
    mgr.faces.import_faces(
        LearnedFace(
            j + 1,
            (centres[j] + rng.normal(0.0, NOISE_SCALE, (feats_per_face, DIM))).astype(np.float32),
        )
        for j in range(n_faces)
    )
    # track t shows face t+1 (known person) for the assigned ones, a stranger for the unassigned ones
    person = [t if t >= n_unassigned else n_faces + t for t in range(n_tracks)]
    t_s = 0.0
    for _ in range(20):  # warm-up: let the known people be re-identified
        for t in range(n_unassigned, n_tracks):
            if mgr.face_id_of(t) is None:
                mgr.add_observations(t, _obs(centres, person[t], rng), t_s)
        mgr.step(t_s)
        t_s += 0.033
        if all(mgr.face_id_of(t) is not None for t in range(n_unassigned, n_tracks)):
            break
    assert all(mgr.face_id_of(t) is not None for t in range(n_unassigned, n_tracks)), "warm-up failed"
    mgr.min_observations = 10**9  # keep the strangers unidentified so every frame has the same work
    return mgr, centres, person, t_s


def _obs(centres: np.ndarray, p: int, rng: np.random.Generator) -> np.ndarray:
    return (centres[p] + rng.normal(0.0, NOISE_SCALE, (1, DIM))).astype(np.float32)


def run_case(n_tracks: int, n_faces: int, n_unassigned: int, frames: int, feats_per_face: int = 50) -> dict:
    rng = np.random.default_rng(0)
    mgr, centres, person, t_s = _setup(n_tracks, n_faces, n_unassigned, feats_per_face, rng)
    # pre-draw observations so the timing covers only the identity layer
    obs = [[_obs(centres, person[t], rng) for t in range(n_tracks)] for _ in range(frames + 5)]
    wall, cpu = [], []
    for f in range(frames + 5):
        t0, c0 = time.perf_counter(), time.thread_time()
        for t in range(n_tracks):
            mgr.add_observations(t, obs[f][t], t_s)
        mgr.step(t_s)
        dt, dc = time.perf_counter() - t0, time.thread_time() - c0
        t_s += 0.033
        if f >= 5:
            wall.append(dt * 1e3)
            cpu.append(dc * 1e3)
    arr = np.array(wall)
    return {
        "tracks": n_tracks,
        "learned_faces": n_faces,
        "unassigned_tracks": n_unassigned,
        "features_per_face": feats_per_face,
        "frames": frames,
        "median_ms": round(float(np.median(arr)), 3),
        "p90_ms": round(float(np.percentile(arr, 90)), 3),
        "max_ms": round(float(arr.max()), 3),
        "cpu_median_ms": round(float(np.median(cpu)), 3),  # thread CPU time: robust to a shared machine
        "sinkhorn_iterations_last": mgr.stats.last_sinkhorn_iterations,
        "shortlist_search": mgr.stats.shortlist_searches > 0,
        "target_ms": TARGET_MS.get((n_tracks, n_faces)),
    }


def sinkhorn_slow_case(n_rows: int, n_faces: int) -> dict:
    """Sinkhorn on a slow-converging table: every row has one clear match (0.999), the rest at the clamp
    floor, row 0 clamped low for the matched columns (default tolerance / iteration cap)."""
    k = np.full((n_rows + 1, n_faces + 1), 1e-3)
    k[0, 0] = 0.0
    k[0, 1:] = 0.999
    for i in range(1, n_rows + 1):
        k[i, i] = 0.999
        k[0, i] = 1e-3
    mgr = BayesIdentityManager()
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        res = sinkhorn_with_slack(k, mgr.sinkhorn_tolerance, mgr.sinkhorn_max_iterations)
        times.append(time.perf_counter() - t0)
    return {
        "rows": n_rows,
        "learned_faces": n_faces,
        "iterations": res.iterations,
        "converged": res.converged,
        "median_ms": round(float(np.median(times)) * 1e3, 3),
    }


def calibration_ms() -> float:
    """Median time of a fixed reference workload (float32 GEMM 64x128 @ 128x10000 + a Python loop),
    so results from different (or shared, noisy) machines can be compared as ratios."""
    rng = np.random.default_rng(1)
    a = rng.normal(size=(64, DIM)).astype(np.float32)
    b = rng.normal(size=(10_000, DIM)).astype(np.float32)
    times = []
    for _ in range(30):
        t0 = time.perf_counter()
        _ = a @ b.T
        total = 0
        for i in range(20_000):
            total += i
        times.append(time.perf_counter() - t0)
    return round(float(np.median(times)) * 1e3, 3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    cal_before = calibration_ms()
    results = []
    for n_tracks, n_faces in TARGET_MS:
        for scenario, n_un in (("all_unassigned", n_tracks), ("steady", max(1, n_tracks // 10))):
            r = run_case(n_tracks, n_faces, n_un, args.frames)
            r["scenario"] = scenario
            results.append(r)
            print(json.dumps(r), flush=True)
    doc = {
        "benchmark": "face_table per-frame update",
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "threads": 1,
        "calibration_ms_before": cal_before,
        "calibration_ms_after": calibration_ms(),
        "results": results,
        "sinkhorn_slow_case": [
            sinkhorn_slow_case(n, m) for n, m in ((5, 20), (20, 200), (50, 2000), (5, 2000))
        ],
    }
    text = json.dumps(doc, indent=2)
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    else:
        print(text)


if __name__ == "__main__":
    main()
