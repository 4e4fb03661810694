"""Benchmark: master core time per camera-frame update, one thread.

For (tracks, learned faces) = (5, 20), (20, 200), (50, 2000) with 50 features per face: every
camera frame carries all tracks' detections, each with a face embedding; 10 % of the tracks (>= 1)
are strangers still being classified against every learned face, the others are re-identified
people (steady state). Reports median / p95 per update, sustained detections per second, and the
ratio to a reference workload timed in the same run (eq. 4 brute force: one observation against
all stored features), so numbers from a loaded machine stay comparable. With ``--bodies`` every scenario
runs again with a body descriptor (the shipped body metric's space) on every detection, the master
tracking by appearance too: its time and its ratio to the run without bodies. Prints one JSON object.

Usage: python bench/master_update.py [--frames N] [--space SPACE] [--bodies]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from plausible_faces import FaceSpace  # noqa: E402

from face_reid_master.body.metric_file import default_body_metric  # noqa: E402
from face_reid_master.core import MasterConfig, MasterCore  # noqa: E402
from face_reid_master.identity.records import LearnedFace  # noqa: E402
from face_reid_master.records import BodyRecord, CameraFrameRecord, PersonRecord  # noqa: E402

TARGET_MS = {(5, 20): 1.0, (20, 200): 2.0, (50, 2000): 10.0}
CAMERAS = ("cam_0", "cam_1", "cam_2")


def _scenario(sp: FaceSpace, n_tracks: int, n_faces: int, frames: int, rng: np.random.Generator,
              body_space: tuple[str, int] | None = None) -> dict[str, float]:
    centres = sp.people(n_faces + n_tracks, rng)
    core = MasterCore(MasterConfig(embedding_space=sp.name, body_appearance_tracking=body_space is not None))
    looks = None if body_space is None else rng.normal(0.0, 0.3, (n_tracks, body_space[1])).astype(np.float32)
    geometry = np.array([1.75, 0.25, 0.42, 0.38, 0.15, 0.36], dtype=np.float32)

    def body(k: int) -> BodyRecord | None:
        if looks is None or body_space is None:
            return None
        return BodyRecord((looks[k] + rng.normal(0.0, 0.02, looks.shape[1])).astype(np.float32), body_space[0], 0.9,
                          geometry)

    core.identity.faces.import_faces(
        LearnedFace(j + 1, sp.observe(np.repeat(centres[j:j + 1], 50, axis=0), rng) * sp.weights)
        for j in range(n_faces)
    )
    n_strangers = max(1, n_tracks // 10)
    # track k shows learned face k (known) or, for the first n_strangers, a person never seen
    person = [n_faces + k if k < n_strangers else k % n_faces for k in range(n_tracks)]
    grid = np.array([[1.0 * (k % 10), 1.0 * (k // 10)] for k in range(n_tracks)])

    def frame(i: int, strangers_show_faces: bool) -> CameraFrameRecord:
        people = tuple(
            PersonRecord(
                np.array([*(grid[k] + rng.normal(0, 0.02, 2)), 0.0]), 0.05, 1.75,
                sp.observe(centres[person[k]][None, :], rng)[0]
                if (k >= n_strangers or strangers_show_faces) else None,
                0.9, 0.9, sp.name, body=body(k),
            )
            for k in range(n_tracks)
        )
        return CameraFrameRecord(CAMERAS[i % len(CAMERAS)], i / 30.0, people)

    i = 0
    for _ in range(300):  # warm-up: tracks confirmed, known people re-identified (strangers faceless)
        core.process_frame(frame(i, False))
        i += 1
        known = [t for t in core.tracks() if t.face_id]
        if len(known) >= n_tracks - n_strangers:
            break
    # From now on the strangers show faces but can never be decided: every frame classifies them
    # against all learned faces (the expensive, steady case).
    core.identity.min_observations = 10**9
    times = []
    t_all = time.perf_counter()
    for _ in range(frames):
        f = frame(i, True)
        t0 = time.perf_counter()
        core.process_frame(f)
        times.append((time.perf_counter() - t0) * 1e3)
        i += 1
    wall = time.perf_counter() - t_all
    assert len(core.tracks()) == n_tracks, "tracks were lost during the benchmark"
    assert len([t for t in core.tracks() if not t.face_id]) == n_strangers, "strangers were decided"
    arr = np.asarray(times)
    return {
        "median_ms": round(float(np.median(arr)), 3),
        "p95_ms": round(float(np.percentile(arr, 95)), 3),
        "detections_per_s": round(n_tracks * frames / wall, 1),
        "identified_tracks": len([t for t in core.tracks() if t.face_id]),
    }


def _reference_ms(sp: FaceSpace, n_features: int, rng: np.random.Generator) -> float:
    """Eq. 4 brute force for ONE observation against ``n_features`` stored features (numpy, median)."""
    feats = sp.people(n_features, rng) * sp.weights
    obs = sp.people(1, rng)[0] * sp.weights
    times = []
    for _ in range(30):
        t0 = time.perf_counter()
        float(np.sqrt(((feats - obs) ** 2).sum(axis=1)).min())
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--space", default=MasterConfig().embedding_space,
                        help="the master's embedding space (default: the default master's)")
    parser.add_argument("--bodies", action="store_true",
                        help="also run every scenario with a body descriptor on every detection")
    args = parser.parse_args()
    body_space = None
    if args.bodies:
        metric = default_body_metric()
        body_space = (metric.space, metric.length)
    sp = FaceSpace.of(args.space)
    rng = np.random.default_rng(0)
    out: dict[str, object] = {"threads": 1, "features_per_face": 50, "embedding_space": sp.name}
    for (n_tracks, n_faces), target in TARGET_MS.items():
        res = _scenario(sp, n_tracks, n_faces, args.frames, rng)
        ref = _reference_ms(sp, n_faces * 50, rng)
        res["reference_eq4_brute_force_ms"] = round(ref, 3)
        res["ratio_to_reference"] = round(res["median_ms"] / ref, 2)
        res["target_ms"] = target
        res["meets_target"] = res["median_ms"] <= target
        if body_space is not None:
            with_bodies = _scenario(sp, n_tracks, n_faces, args.frames, rng, body_space)
            with_bodies["ratio_to_without_bodies"] = round(with_bodies["median_ms"] / res["median_ms"], 2)
            with_bodies["meets_target"] = with_bodies["median_ms"] <= target
            res["with_bodies"] = with_bodies
        out[f"tracks_{n_tracks}_faces_{n_faces}"] = res
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
