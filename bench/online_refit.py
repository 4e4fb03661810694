"""Benchmark: does the online body-metric re-fit delay frames? One thread for the frames.

Two master cores get the same camera frames, alternately (so machine load hits both alike): 20 tracks with
a face and a body on every detection, 200 learned faces each with a full gallery of recent bodies (64). The
first core never re-fits; in the second a re-fit is always due (a new pair before every frame, no minimum
interval): its worker thread re-fits and converts the 12,800 gallery embeddings while frames go on, and
each finished re-fit is installed between two frames. Reports per-frame median / p99 / max of both, their
differences, how many re-fits were installed and the time of the installing step itself (median / p99 / max;
target: the delay a re-fit causes a frame <= 1 ms). Prints one JSON object.

Usage: python bench/online_refit.py [--frames N]
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

N_TRACKS, N_FACES, GALLERY = 20, 200, 64
TARGET_DELAY_MS = 1.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1000)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    space = MasterConfig().embedding_space
    faces = FaceSpace.of(space)  # different people 1.33, one person 0.75 times the decision distance apart
    centres = faces.people(N_FACES, rng)
    metric = default_body_metric()
    looks = rng.normal(0.0, 0.3, (N_TRACKS, metric.length)).astype(np.float32)
    geometry = np.array([1.75, 0.25, 0.42, 0.38, 0.15, 0.36], dtype=np.float32)
    grid = np.array([[1.0 * (k % 10), 1.0 * (k // 10)] for k in range(N_TRACKS)])

    def make(online: bool) -> MasterCore:
        core = MasterCore(MasterConfig(embedding_space=space, body_online_update=online,
                                       body_online_interval_s=0.0, body_online_min_new_pairs=1))
        core.identity.import_faces(
            LearnedFace(j + 1, faces.observe(np.repeat(centres[j:j + 1], 50, axis=0), rng) * faces.weights)
            for j in range(N_FACES))
        body = core.identity.body_evidence
        assert body is not None
        fused = metric.features["fused"]
        for j in range(N_FACES):  # everybody was seen lately: full galleries of recent bodies
            body.add_face_bodies(j + 1, fused.embed(rng.normal(0.0, 0.3, (GALLERY, metric.length))), 0.0,
                                 track_id=10_000 + j, heights=np.full(GALLERY, 1.75))
        return core

    def frame(i: int) -> CameraFrameRecord:
        people = tuple(
            PersonRecord(np.array([*(grid[k] + rng.normal(0, 0.02, 2)), 0.0]), 0.05, 1.75,
                         faces.observe(centres[k][None, :], rng)[0],
                         0.9, 0.9, space,
                         body=BodyRecord((looks[k] + rng.normal(0.0, 0.02, metric.length)).astype(np.float32),
                                         metric.space, 0.9, geometry))
            for k in range(N_TRACKS))
        return CameraFrameRecord(("cam_0", "cam_1", "cam_2")[i % 3], i / 30.0, people)

    cores = {"without_refits": make(False), "refitting": make(True)}
    online = cores["refitting"].online_metric
    assert online is not None
    installs: list[float] = []  # time of each frame's re-fit step that installed a metric (ms)
    refitting, install_step = cores["refitting"], cores["refitting"]._online_metric_step

    def timed_step(stamp: float) -> None:
        before, t0 = refitting.stats.body_metric_refits, time.perf_counter()
        install_step(stamp)
        if refitting.stats.body_metric_refits != before:
            installs.append((time.perf_counter() - t0) * 1e3)

    refitting._online_metric_step = timed_step  # type: ignore[method-assign]
    r = online.base.metric.metric.shape[0]
    times: dict[str, list[float]] = {k: [] for k in cores}
    for i in range(300 + args.frames):
        f = frame(i)
        online.pool.add(rng.normal(size=r), bool(i % 2), (1, 1 + i % 2), (-i - 1, -i - 2), f.stamp_s)
        for name, core in cores.items():
            t0 = time.perf_counter()
            core.process_frame(f)
            if i >= 300:  # after the warm-up (tracks confirmed, people identified)
                times[name].append((time.perf_counter() - t0) * 1e3)
    online.close()
    out: dict[str, object] = {"threads_for_frames": 1, "tracks": N_TRACKS, "faces": N_FACES,
                              "bodies_per_face": GALLERY, "frames": args.frames}
    stats = {}
    for name, t in times.items():
        a = np.asarray(t)
        stats[name] = {"median_ms": round(float(np.median(a)), 3), "p99_ms": round(float(np.percentile(a, 99)), 3),
                       "max_ms": round(float(a.max()), 3)}
    out.update(stats)
    out["refits_installed"] = int(cores["refitting"].stats.body_metric_refits)
    ins = np.asarray(installs)
    out["install_ms"] = {"median": round(float(np.median(ins)), 3), "p99": round(float(np.percentile(ins, 99)), 3),
                         "max": round(float(ins.max()), 3)}
    out["identified_tracks"] = len([t for t in cores["refitting"].tracks() if t.face_id])
    delay = {k: round(stats["refitting"][k] - stats["without_refits"][k], 3) for k in ("median_ms", "p99_ms")}
    out["delay_ms"] = delay
    out["target_delay_ms"] = TARGET_DELAY_MS
    out["meets_target"] = bool(ins.max() <= TARGET_DELAY_MS and delay["median_ms"] <= TARGET_DELAY_MS)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
