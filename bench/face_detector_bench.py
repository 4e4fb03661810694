"""Latency of YuNetDetector.detect_in_rois for 1, 3, 5 head ROIs vs the raw ONNX Runtime run alone.

Prints one JSON object. Both timings are interleaved in the same loop on the same session so that load
from other processes affects them alike; compare the ratio more than the absolute numbers.
Usage: PYTHONPATH=. python bench/face_detector_bench.py [--repeats 300] [--roi-sizes 64 96 128]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import cv2
import numpy as np

from face_reid_camera.faces.detector import YuNetDetector

FACES_DIR = Path(__file__).resolve().parents[1] / "test" / "data" / "faces"
FACE_SIZE_PX = 60  # face box width in the synthetic frame, pixels
ROI_TO_FACE = 2.0  # a 0.35 m head ROI is about twice a face box


def _scene(detector: YuNetDetector, n_faces: int) -> tuple[np.ndarray, list[tuple[int, int, int, int]]]:
    """A 640x480 frame with n real faces (~60 px) pasted in a row, and a head-sized ROI on each."""
    frame = np.full((480, 640, 3), 114, dtype=np.uint8)
    rois = []
    photos = sorted(FACES_DIR.glob("lfw_*/*.jpg"))[:n_faces]
    for i, photo in enumerate(photos):
        image = cv2.imread(str(photo))
        face = detector.detect(image)[0]
        scale = FACE_SIZE_PX / float(face.box_xywh[2])
        small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        cx, cy = (face.box_xywh[:2] + face.box_xywh[2:] / 2) * scale
        half = FACE_SIZE_PX  # paste a head-and-shoulders window around the face
        x_src, y_src = max(0, int(cx) - half), max(0, int(cy) - half)
        patch = small[y_src : y_src + 2 * half, x_src : x_src + 2 * half]
        x, y = 8 + i * 126, 150
        frame[y : y + patch.shape[0], x : x + patch.shape[1]] = patch
        side = int(ROI_TO_FACE * FACE_SIZE_PX)
        centre_x, centre_y = x + cx - x_src, y + cy - y_src
        rois.append((int(centre_x - side / 2), int(centre_y - side / 2), side, side))
    return frame, rois


def _median_ms(samples: list[float]) -> float:
    return round(statistics.median(samples) * 1e3, 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=300)
    parser.add_argument("--roi-sizes", type=int, nargs="+", default=[96])
    args = parser.parse_args()
    cv2.setNumThreads(1)
    report: dict[str, object] = {"threads": 1, "repeats": args.repeats, "face_px": FACE_SIZE_PX}
    for roi_size in args.roi_sizes:
        detector = YuNetDetector(roi_input_size_px=roi_size, num_threads=1)
        session = detector._session  # same session the detector uses: the raw-inference baseline
        input_name = session.get_inputs()[0].name
        run_inside: list[float] = []
        detector_run = detector._run

        def timed_run(batch: np.ndarray, run=detector_run, log=run_inside) -> dict[str, np.ndarray]:
            start = time.perf_counter()
            outputs = run(batch)
            log.append(time.perf_counter() - start)
            return outputs

        detector._run = timed_run  # type: ignore[method-assign]
        for n_rois in (1, 3, 5):
            frame, rois = _scene(detector, n_rois)
            batch = np.random.default_rng(0).uniform(0, 255, (n_rois, 3, roi_size, roi_size))
            batch = batch.astype(np.float32)
            found = sum(d is not None for d in detector.detect_in_rois(frame, rois))
            total, raw = [], []
            run_inside.clear()
            for _ in range(args.repeats):
                start = time.perf_counter()
                detector.detect_in_rois(frame, rois)
                mid = time.perf_counter()
                session.run(None, {input_name: batch})
                total.append(mid - start)
                raw.append(time.perf_counter() - mid)
            pre_post = [t - r for t, r in zip(total, run_inside, strict=True)]
            report[f"roi{roi_size}_n{n_rois}"] = {
                "detect_in_rois_ms": _median_ms(total),
                "run_inside_call_ms": _median_ms(run_inside),
                "pre_post_processing_ms": _median_ms(pre_post),
                "separate_session_run_ms": _median_ms(raw),
                "faces_found": found,
            }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
