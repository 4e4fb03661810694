"""Benchmark: PersonDetector.detect_depth latency on 640x480 frames, one thread.

Frames: a real Kinect desk frame (floor, laptop, box; no people), a synthetic 3-person frame and the
same with two 3 m walls (ray-cast by the test suite's analytic renderer), plus the real organized
``person.pcd`` cloud through ``detect_points``. Prints one JSON object: median/p95/mean latency
(ms) per frame, the median of each pipeline stage and the number of people found. The machine may
be shared: compare stages and frames more than absolute numbers.

Usage: python bench/person_detector_bench.py [--repeats 200]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "test"))

from test_person_detector import HIGH_POSE, THREE_PEOPLE, render_depth, scene  # noqa: E402

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose  # noqa: E402
from face_reid_camera.people.detector import PersonDetectionResult, PersonDetector  # noqa: E402
from face_reid_camera.tools.pcd_io import read_pcd  # noqa: E402

DATA = REPO / "test" / "data" / "rgbd"
WALLS = (
    ((8.0, -6.0, 0.0), (8.2, 6.0, 3.0)),
    ((0.0, 3.5, 0.0), (9.0, 3.7, 3.0)),
    ((0.0, -3.7, 0.0), (9.0, -3.5, 3.0)),
)


def measure(run: Callable[[], PersonDetectionResult], repeats: int) -> dict:
    for _ in range(10):
        run()
    latencies, stages = [], {}
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        latencies.append((time.perf_counter() - start) * 1e3)
        for name, value in result.timings_ms.items():
            stages.setdefault(name, []).append(value)
    return {
        "median_ms": round(float(np.median(latencies)), 3),
        "p95_ms": round(float(np.percentile(latencies, 95)), 3),
        "mean_ms": round(float(np.mean(latencies)), 3),
        "min_ms": round(float(np.min(latencies)), 3),
        "stage_median_ms": {k: round(float(np.median(v)), 3) for k, v in stages.items() if k != "total"},
        "people": len(result.people),
        "points": result.num_points,
        "voxels": result.num_voxels,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()

    kinect = CameraIntrinsics.kinect_default()
    desk_png = sorted((DATA / "pcl_desk").glob("*_depth_mm.png"))[0]
    desk = cv2.imread(str(desk_png), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
    three = render_depth(kinect, HIGH_POSE, **scene(THREE_PEOPLE))
    walls = render_depth(kinect, HIGH_POSE, **scene(THREE_PEOPLE, boxes=WALLS))
    cloud = read_pcd(DATA / "person.pcd")
    pcd_pose = CameraPose.from_xyz_rpy(0.0, 0.0, 1.5, 0.0, -0.05, 0.0)

    report = {"threads": 1, "image": "640x480", "repeats": args.repeats, "frames": {}}
    for name, depth in (
        ("desk_real", desk),
        ("three_people_synthetic", three),
        ("three_people_walls", walls),
    ):
        detector = PersonDetector()
        report["frames"][name] = measure(
            lambda d=depth, det=detector: det.detect_depth(d, kinect), args.repeats
        )
    detector = PersonDetector(camera_pose=pcd_pose)
    report["frames"]["person_pcd_detect_points"] = measure(
        lambda: detector.detect_points(cloud), args.repeats
    )
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
