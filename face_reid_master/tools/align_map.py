"""face-reid-align-map: align a robot's nav2 map to the camera network's map and write the world -> map transform.

    face-reid-align-map ROBOT_MAP.yaml --camera-map CAMERA_MAP.yaml --guess X Y YAW_DEG [-o world_to_map.yaml]

CAMERA_MAP.yaml is what ``face-reid-map --save`` wrote (world frame); ROBOT_MAP.yaml a nav2 map (map frame). The
guess is the world -> map transform (p_map = R(yaw) p_world + (x, y)) to within about 0.5 m and 10 degrees: where
the world origin is on the robot's map and how the world's x axis is turned there. 2-D ICP on the occupied cells
(face_reid_master/robot/map_align.py) refines it; the result, its RMS residual and inlier fraction are printed and
written with save_world_to_map for ``face-reid-goto`` and the people outputs.

Exit status: 0 written, 1 bad input or no alignment (one line on stderr).
"""

from __future__ import annotations

import argparse
import math
import sys

from face_reid_master.robot.camera_map import load_nav2_map
from face_reid_master.robot.frames import PlanarTransform, save_world_to_map
from face_reid_master.robot.map_align import MapAlignConfig, align_maps


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="face-reid-align-map", description=__doc__.split("\n\n")[0])
    parser.add_argument("robot_map", help="the robot's nav2 map YAML (map frame)")
    parser.add_argument("--camera-map", required=True, help="the camera network's map YAML (face-reid-map --save)")
    parser.add_argument("--guess", nargs=3, type=float, required=True, metavar=("X", "Y", "YAW_DEG"),
                        help="initial world -> map transform: x, y (m) and yaw (deg)")
    parser.add_argument("-o", "--output", default="world_to_map.yaml", help="where to write the transform")
    parser.add_argument("--map-frame", default="map", help="the robot map's frame id (written to the file)")
    parser.add_argument("--world-frame", default="world", help="the camera network's frame id")
    parser.add_argument("--max-distance", type=float, default=1.0,
                        help="first pairing distance (m): at least the guess's error")
    parser.add_argument("--min-inlier-fraction", type=float, default=0.5,
                        help="refuse (exit 1) when fewer camera-map cells than this match the robot map (0..1)")
    args = parser.parse_args(argv)
    try:
        x, y, yaw_deg = args.guess
        guess = PlanarTransform(x, y, math.radians(yaw_deg))
        config = MapAlignConfig(initial_max_distance_m=args.max_distance,
                                final_max_distance_m=min(MapAlignConfig().final_max_distance_m, args.max_distance))
        if not 0.0 <= args.min_inlier_fraction <= 1.0:
            raise ValueError(f"--min-inlier-fraction must be in [0, 1], got {args.min_inlier_fraction}")
        robot = load_nav2_map(args.robot_map, frame=args.map_frame)
        camera = load_nav2_map(args.camera_map, frame=args.world_frame)
        result = align_maps(robot, camera, guess, config)
    except (ValueError, OSError) as exc:
        print(f"face-reid-align-map: {exc}", file=sys.stderr)
        return 1
    print(result.describe())
    if result.inlier_fraction < args.min_inlier_fraction:
        print(f"face-reid-align-map: only {100 * result.inlier_fraction:.0f}% of the camera map matches the robot map "
              f"(< {100 * args.min_inlier_fraction:.0f}%): not written; try a better --guess", file=sys.stderr)
        return 1
    save_world_to_map(args.output, result.world_to_map, world_frame=args.world_frame, map_frame=args.map_frame,
                      residual_m=result.rms_residual_m,
                      note=f"ICP of {args.camera_map} onto {args.robot_map}: {100 * result.inlier_fraction:.0f}% "
                      f"inliers, {result.iterations} iterations")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
