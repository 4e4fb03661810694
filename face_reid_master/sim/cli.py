"""``face-reid-sim``: simulate a camera-network scenario with real face photos and write it to a directory.

Example: ``face-reid-sim --faces FACES --people 6 --cameras 3 --duration 200 --seed 1 --out S``.
The directory format is documented in :mod:`face_reid_master.sim.scenario_files`. Progress goes to stderr, the
summary (JSON) to stdout. ``--bodies CROPS`` adds bodies (:mod:`face_reid_master.sim.bodies`): clothes from a
folder of person crops, described with the cameras' body projection (``--body-projection``, default the
shipped one). ``--oracle-evidence`` replaces every face embedding and body descriptor of a person by one fixed
real vector of theirs plus a little noise (:mod:`face_reid_master.sim.oracle`): the identity logic's floor.
Exit status: 0 done, 2 bad arguments or unusable faces / crops folder, 1 other errors (e.g.
missing models or body projection).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from face_reid_camera.body.projection import BODY_PROJECTION_FILE, load_body_projection
from face_reid_camera.common.resources import model_path
from face_reid_master.sim.bodies import BodySimConfig, InsufficientBodiesError
from face_reid_master.sim.motion import PASSING_DISTANCE_RANGE_M, MotionConfig
from face_reid_master.sim.oracle import ORACLE_NOISE_STD
from face_reid_master.sim.photos import InsufficientFacesError
from face_reid_master.sim.scenario_files import write_scenario
from face_reid_master.sim.simulate import LEVELS, SimConfig, simulate


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="face-reid-sim",
        description="Simulate people walking in a room watched by RGB-D cameras (faces from real photos) and "
                    "write the camera messages and the ground truth to a scenario directory.",
    )
    p.add_argument("--faces", required=True, type=Path, help="folder with one sub-folder of face photos per identity")
    p.add_argument("--out", required=True, type=Path, help="scenario directory to write (created if needed)")
    p.add_argument("--people", type=int, default=6, help="people per day (default 6)")
    p.add_argument("--cameras", type=int, default=3, help="number of cameras (default 3)")
    p.add_argument("--duration", type=float, default=None,
                   help="seconds per day (default 200 at feature level, 60 at pixel level)")
    p.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives identical files")
    p.add_argument("--level", choices=LEVELS, default="feature",
                   help="feature: camera messages from photo embeddings (fast); pixel: rendered RGB-D frames "
                        "through the real camera pipeline (slow)")
    p.add_argument("--rate-hz", type=float, default=None, help="frames per second per camera (default 15 / 5)")
    p.add_argument("--second-day", action="store_true",
                   help="add a second day: the same room, other photos, some people replaced by new ones")
    p.add_argument("--day-gap", type=float, default=SimConfig.day_gap_s, metavar="S",
                   help="seconds between the end of day 1 and the start of day 2 (default %(default)g: "
                        "overnight, longer than the body evidence's window, so day-1 clothes do not count on day 2)")
    p.add_argument("--new-people", type=int, default=None,
                   help="people on day 2 who were not there on day 1 (default people // 3)")
    p.add_argument("--room", type=str, default=None, metavar="WxD",
                   help="room size in metres, e.g. 10x8 (default: scaled with the number of cameras)")
    p.add_argument("--embedder", choices=("dlib", "sface", "both"), default="both",
                   help="the cameras' face embedder (default both: 256-value embeddings, the joint space the "
                        "default master compares; such a scenario also serves the dlib and SFace spaces, "
                        "face-reid-eval --space)")
    p.add_argument("--color-resolution", type=str, default=None, metavar="WxH",
                   help="colour image size in pixels, e.g. 1920x1080 (default: the depth camera's 640x480); "
                        "faces get proportionally more pixels (feature level: each face's photo is down-sampled to "
                        "the eye distance this gives at its range and angle)")
    p.add_argument("--bodies", type=Path, default=None, metavar="DIR",
                   help="folder with one sub-folder of person crops per identity (e.g. PKU-Reid, Market-1501): "
                        "every person wears one crop identity per day (another one on day 2) and detections carry "
                        "body descriptors, visibility and geometry")
    p.add_argument("--body-projection", type=Path, default=None, metavar="FILE",
                   help=f"the cameras' body descriptor projection (default: the shipped models/{BODY_PROJECTION_FILE}"
                        ", made by face-reid-fit-body)")
    p.add_argument("--passing-distance", type=float, default=MotionConfig.passing_distance_m, metavar="M",
                   help=f"people pass each other at least this far apart (centre to centre, metres; "
                        f"{PASSING_DISTANCE_RANGE_M[0]:g}-{PASSING_DISTANCE_RANGE_M[1]:g}, default "
                        f"{MotionConfig.passing_distance_m:g}); 0: they walk through each other")
    p.add_argument("--oracle-evidence", action="store_true",
                   help="oracle evidence, the identity logic's floor: every face embedding of a person becomes one "
                        "fixed real embedding of theirs (the medoid of their photos' embeddings, per embedder) plus "
                        "N(0, --oracle-noise) per value, and every body descriptor one fixed real descriptor of "
                        "theirs for the day plus the same noise: no two people's faces are confusable (their clothes "
                        "still may be; recorded in scenario.json as \"oracle\": true)")
    p.add_argument("--oracle-noise", type=float, default=ORACLE_NOISE_STD, metavar="STD",
                   help=f"--oracle-evidence: the noise's standard deviation per value (default {ORACLE_NOISE_STD:g})")
    p.add_argument("--cache", type=Path, default=None,
                   help="npz file caching the photo embeddings and their camera-true views (keyed by path, "
                        "mtime and size; a view also by frame change and eye distance)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def _room(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.lower().split("x")
    if len(parts) != 2:
        raise ValueError(f"--room must look like 10x8 (metres), got {text!r}")
    return float(parts[0]), float(parts[1])


def _resolution(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise ValueError(f"--color-resolution must look like 1920x1080 (pixels), got {text!r}")
    return int(parts[0]), int(parts[1])


def main(argv: Sequence[str] | None = None) -> int:
    """Run the simulator; returns the exit status."""
    parser = _parser()
    args = parser.parse_args(list(argv) if argv is not None else None)
    log = None if args.quiet else sys.stderr
    duration = args.duration if args.duration is not None else (200.0 if args.level == "feature" else 60.0)
    try:
        config = SimConfig(
            num_people=args.people, num_cameras=args.cameras, duration_s=duration, seed=args.seed, level=args.level,
            rate_hz=args.rate_hz, second_day=args.second_day, new_people=args.new_people,
            day_gap_s=args.day_gap,
            room_size_m=_room(args.room), embedder=args.embedder, color_resolution=_resolution(args.color_resolution),
            bodies=BodySimConfig() if args.bodies is not None else None,
            motion=MotionConfig(passing_distance_m=args.passing_distance),
            oracle_noise_std=args.oracle_noise if args.oracle_evidence else None,
        )
    except ValueError as exc:
        parser.print_usage(sys.stderr)
        print(f"face-reid-sim: error: {exc}", file=sys.stderr)
        return 2
    if args.new_people is not None and not args.second_day:
        print("face-reid-sim: note: --new-people has no effect without --second-day", file=sys.stderr)
    if args.oracle_noise != ORACLE_NOISE_STD and not args.oracle_evidence:
        print("face-reid-sim: note: --oracle-noise has no effect without --oracle-evidence", file=sys.stderr)
    if args.body_projection is not None and args.bodies is None:
        print("face-reid-sim: note: --body-projection has no effect without --bodies", file=sys.stderr)
    t0 = time.perf_counter()
    try:
        projection = None
        if args.bodies is not None:
            projection = load_body_projection(args.body_projection if args.body_projection is not None
                                              else model_path(BODY_PROJECTION_FILE))
        result = simulate(args.faces, config, cache_path=args.cache, log=log, bodies_dir=args.bodies,
                          body_projection=projection)
    except (InsufficientFacesError, InsufficientBodiesError) as exc:
        print(f"face-reid-sim: error: {exc}", file=sys.stderr)
        return 2
    except (FileNotFoundError, RuntimeError) as exc:  # missing / broken models
        print(f"face-reid-sim: error: {exc}", file=sys.stderr)
        return 1
    out = write_scenario(result, args.out)
    summary = dict(result.document["summary"])
    if log is not None:
        skipped = len(summary["skipped_unreadable"]) + len(summary["skipped_no_face"])
        if skipped:
            log.write(f"skipped {len(summary['skipped_unreadable'])} unreadable files and "
                      f"{len(summary['skipped_no_face'])} photos without a detectable face (listed in scenario.json)\n")
        log.write(f"wrote {out} in {time.perf_counter() - t0:.1f} s\n")
    brief = {k: v for k, v in summary.items() if k not in ("per_day", "skipped_unreadable", "skipped_no_face")}
    brief["skipped_unreadable"] = len(summary["skipped_unreadable"])
    brief["skipped_no_face"] = len(summary["skipped_no_face"])
    brief["losses_per_day"] = [d["losses"] for d in summary["per_day"]]
    brief["out"] = str(out)
    print(json.dumps(brief, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
