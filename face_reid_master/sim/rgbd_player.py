"""RGB-D player: one simulated camera sensor rendering a scripted scene in real time (used by the demo).

A player process IS one camera's sensor: it renders the colour + registered depth frames of its camera
from deterministic trajectories (:func:`face_reid_master.sim.renderer.render_scene`, real face photos
pasted on the heads) at ``rate_hz`` and publishes them, stamped with the capture time, only on its own
camera node's input topics (``color/image_raw`` bgr8, ``depth_registered/image_raw`` 16UC1,
``color/camera_info``, relative to its namespace). Face images never leave the camera's processes.

Protocol with the parent (``face-reid-demo``): the spec is a JSON file (:class:`PlayerSpec`); once its
camera node subscribes, the player prints ``{"event": "ready", ...}`` on stdout and waits for a line
``start T0`` on stdin (T0: scene time 0 in seconds since the epoch, the clock of the stamps); it then
plays ``duration_s`` seconds of scene, prints ``{"event": "done", ...}`` and writes its ground truth
(stamps, true positions, rendered faces) to ``--truth`` (npz). EOF on stdin before the start exits.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_master.sim.motion import Trajectory
from face_reid_master.sim.world import Room

__all__ = ["PhotoSpan", "PlayedPerson", "PlayerSpec", "main"]

SPEC_FORMAT = "face-reid-player-spec"


def _colour(value: Any, name: str) -> tuple[int, int, int]:
    vals = tuple(int(v) for v in value)
    if len(vals) != 3 or not all(0 <= v <= 255 for v in vals):
        raise ValueError(f"{name} must be 3 integers in [0, 255], got {value!r}")
    return vals  # type: ignore[return-value]


def _clothes(value: Any) -> tuple[tuple[int, int, int], tuple[int, int, int], bool] | None:
    if value is None:
        return None
    shirt, trousers, stripes = value
    return _colour(shirt, "clothes shirt"), _colour(trousers, "clothes trousers"), bool(stripes)


@dataclass(frozen=True)
class PhotoSpan:
    """The face photo a person shows this camera during scene time [start_s, end_s)."""

    start_s: float
    end_s: float
    path: str


@dataclass(frozen=True)
class PlayedPerson:
    """One person of the scene: ground-truth id, motion, face photos over time and clothes (BGR): flat colours, or
    with ``clothes`` (shirt, trousers, stripes) a made-up textured crop
    (:func:`~face_reid_master.sim.renderer.synthetic_clothes`) on the body."""

    gt_id: int
    trajectory: Trajectory
    photos: tuple[PhotoSpan, ...]
    body_bgr: tuple[int, int, int] = (150, 80, 40)
    legs_bgr: tuple[int, int, int] = (60, 50, 45)
    hair_bgr: tuple[int, int, int] = (30, 40, 55)
    clothes: tuple[tuple[int, int, int], tuple[int, int, int], bool] | None = None

    def photo_at(self, t_s: float) -> str | None:
        """Path of the photo shown at scene time ``t_s`` (None: no face)."""
        for span in self.photos:
            if span.start_s <= t_s < span.end_s:
                return span.path
        return None


@dataclass(frozen=True)
class PlayerSpec:
    """Everything one player needs: its camera, the room, the people and the timing."""

    camera_id: str
    intrinsics: CameraIntrinsics
    xyz_rpy: tuple[float, float, float, float, float, float]
    room_size_m: tuple[float, float]
    people: tuple[PlayedPerson, ...]
    duration_s: float
    rate_hz: float = 5.0
    phase_s: float = 0.0
    floor_size_m: float = 14.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.camera_id:
            raise ValueError("camera_id must not be empty")
        if len(self.xyz_rpy) != 6 or not all(math.isfinite(float(v)) for v in self.xyz_rpy):
            raise ValueError(f"xyz_rpy must be 6 finite numbers, got {self.xyz_rpy!r}")
        for name, low, high in (("duration_s", 0.0, 86400.0), ("rate_hz", 0.0, 60.0)):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and low < value <= high):
                raise ValueError(f"{name} must be in ({low}, {high}], got {value!r}")
        if not (math.isfinite(self.phase_s) and self.phase_s >= 0):
            raise ValueError(f"phase_s must be >= 0, got {self.phase_s!r}")
        Room(*self.room_size_m)  # validates

    @property
    def pose(self) -> CameraPose:
        return CameraPose.from_xyz_rpy(*self.xyz_rpy)

    def to_json(self) -> dict[str, Any]:
        intr = self.intrinsics
        return {
            "format": SPEC_FORMAT, "camera_id": self.camera_id,
            "intrinsics": [intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height],
            "xyz_rpy": list(self.xyz_rpy), "room_size_m": list(self.room_size_m), "duration_s": self.duration_s,
            "rate_hz": self.rate_hz, "phase_s": self.phase_s, "floor_size_m": self.floor_size_m, "seed": self.seed,
            "people": [
                {"gt_id": p.gt_id, "t_s": p.trajectory.t_s.tolist(), "xy": p.trajectory.xy.tolist(),
                 "facing_rad": p.trajectory.facing_rad.tolist(), "height_m": p.trajectory.height_m,
                 "photos": [[s.start_s, s.end_s, s.path] for s in p.photos],
                 "body_bgr": list(p.body_bgr), "legs_bgr": list(p.legs_bgr), "hair_bgr": list(p.hair_bgr),
                 "clothes": None if p.clothes is None else [list(p.clothes[0]), list(p.clothes[1]),
                                                            bool(p.clothes[2])]}
                for p in self.people
            ],
        }

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> PlayerSpec:
        """Parse (and validate) a spec; ValueError with the offending field on bad input."""
        if not isinstance(doc, dict) or doc.get("format") != SPEC_FORMAT:
            raise ValueError(f"not a player spec (format must be {SPEC_FORMAT!r})")
        try:
            fx, fy, cx, cy, w, h = doc["intrinsics"]
            people = tuple(
                PlayedPerson(
                    int(p["gt_id"]),
                    Trajectory(np.asarray(p["t_s"], float), np.asarray(p["xy"], float).reshape(-1, 2),
                               np.asarray(p["facing_rad"], float), float(p["height_m"])),
                    tuple(PhotoSpan(float(a), float(b), str(path)) for a, b, path in p["photos"]),
                    _colour(p["body_bgr"], "body_bgr"), _colour(p["legs_bgr"], "legs_bgr"),
                    _colour(p["hair_bgr"], "hair_bgr"), _clothes(p.get("clothes")),
                )
                for p in doc["people"]
            )
            xyz_rpy = tuple(float(v) for v in doc["xyz_rpy"])
            return cls(
                str(doc["camera_id"]), CameraIntrinsics(float(fx), float(fy), float(cx), float(cy), int(w), int(h)),
                xyz_rpy,  # type: ignore[arg-type]
                (float(doc["room_size_m"][0]), float(doc["room_size_m"][1])), people, float(doc["duration_s"]),
                float(doc["rate_hz"]), float(doc["phase_s"]), float(doc["floor_size_m"]), int(doc["seed"]),
            )
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"malformed player spec: {type(exc).__name__}: {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> PlayerSpec:
        try:
            doc = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"cannot read player spec {path}: {exc}") from None
        return cls.from_json(doc)


class ScenePlayer:
    """Renders the spec's scene at any scene time (pure: no ROS). Face crops are prepared once."""

    def __init__(self, spec: PlayerSpec, detector: Any | None = None) -> None:
        from face_reid_camera.faces.detector import YuNetDetector
        from face_reid_camera.faces.photos import PhotoError, read_photo
        from face_reid_master.sim.renderer import crop_face_for_rendering, synthetic_clothes

        self.spec = spec
        self.room = Room(*spec.room_size_m)
        self.pose = spec.pose
        self.crops: dict[str, NDArray[np.uint8] | None] = {}
        self.warnings: list[str] = []
        # one texture per person, the same in every camera's player (its noise seeded by the person)
        self.textures = {p.gt_id: synthetic_clothes(*p.clothes, np.random.default_rng([p.gt_id]))
                         for p in spec.people if p.clothes is not None}
        det = detector if detector is not None else YuNetDetector()
        for person in spec.people:
            for span in person.photos:
                if span.path in self.crops:
                    continue
                try:
                    photo = read_photo(span.path)
                except PhotoError as exc:
                    raise ValueError(str(exc)) from None
                faces = det.detect(photo)
                if not faces:
                    self.warnings.append(f"no face found in {span.path}: that person is shown without a face")
                    self.crops[span.path] = None
                    continue
                best = max(faces, key=lambda d: float(d.box_xywh[2] * d.box_xywh[3]))
                self.crops[span.path] = crop_face_for_rendering(photo, best.box_xywh)

    def render(self, scene_t_s: float, frame_index: int) -> tuple[Any, NDArray[np.float64], NDArray[np.bool_],
                                                                   NDArray[np.bool_]]:
        """(RenderedFrame, true xy (P, 2), in room (P,), face rendered visible (P,)) at scene time ``scene_t_s``."""
        from face_reid_master.sim.renderer import SyntheticPerson, render_scene

        spec = self.spec
        n = len(spec.people)
        xy = np.zeros((n, 2))
        inside = np.zeros(n, dtype=bool)
        people, index = [], []
        for p, person in enumerate(spec.people):
            pos, facing = person.trajectory.sample(np.array([scene_t_s]))
            xy[p] = pos[0]
            inside[p] = bool(self.room.contains(pos[0]))
            if not inside[p]:
                continue
            path = person.photo_at(scene_t_s)
            face = self.crops.get(path) if path is not None else None
            people.append(SyntheticPerson(float(pos[0, 0]), float(pos[0, 1]), person.trajectory.height_m,
                                          float(facing[0]), face_image_bgr=face, body_color_bgr=person.body_bgr,
                                          legs_color_bgr=person.legs_bgr, hair_color_bgr=person.hair_bgr,
                                          body_texture_bgr=self.textures.get(person.gt_id)))
            index.append(p)
        frame = render_scene(people, spec.intrinsics, self.pose, rng=np.random.default_rng([spec.seed, frame_index]),
                             floor_size_m=spec.floor_size_m)
        face_visible = np.zeros(n, dtype=bool)
        face_visible[index] = frame.face_visible
        return frame, xy, inside, face_visible


def _say(event: str, **fields: Any) -> None:
    print(json.dumps({"event": event, **fields}), flush=True)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="face_reid_master.sim.rgbd_player",
        description="Play one simulated RGB-D camera of a scripted scene in real time (started by face-reid-demo).",
    )
    p.add_argument("--spec", required=True, type=Path, help="player spec (JSON) written by the demo")
    p.add_argument("--truth", required=True, type=Path, help="where to write the ground truth (npz)")
    p.add_argument("--wait-s", type=float, default=120.0, help="give up if the camera node does not subscribe")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Player process entry point (ROS arguments after ``--ros-args``, e.g. a namespace remap)."""
    args_all = list(sys.argv[1:] if argv is None else argv)
    ros_args = args_all[args_all.index("--ros-args"):] if "--ros-args" in args_all else []
    own = args_all[: len(args_all) - len(ros_args)]
    args = _parser().parse_args(own)
    try:
        spec = PlayerSpec.load(args.spec)
        player = ScenePlayer(spec)
    except ValueError as exc:
        _say("error", message=f"cannot start the player: {exc}")
        return 2
    for warning in player.warnings:
        print(f"[rgbd_player {spec.camera_id}] WARNING: {warning}", file=sys.stderr, flush=True)

    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import CameraInfo, Image

    from face_reid_camera.ros.image_codec import encode_image

    rclpy.init(args=["rgbd_player", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("rgbd_player")
    try:
        qos = QoSProfile(depth=2, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        pub_c = node.create_publisher(Image, "color/image_raw", qos)
        pub_d = node.create_publisher(Image, "depth_registered/image_raw", qos)
        pub_i = node.create_publisher(CameraInfo, "color/camera_info", qos)
        deadline = time.monotonic() + args.wait_s
        while min(pub_c.get_subscription_count(), pub_d.get_subscription_count(), pub_i.get_subscription_count()) < 1:
            if time.monotonic() > deadline:
                _say("error", message=f"camera node never subscribed to {pub_c.topic_name} within {args.wait_s:g} s")
                return 1
            rclpy.spin_once(node, timeout_sec=0.05)
        _say("ready", camera_id=spec.camera_id, topic=pub_c.topic_name)
        line = sys.stdin.readline()
        if not line.startswith("start "):
            return 0  # the demo went away before the start
        t0 = float(line.split()[1])
        return _play(node, player, t0, pub_c, pub_d, pub_i, Image, CameraInfo, encode_image, args.truth)
    except KeyboardInterrupt:
        return 130
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def _play(node: Any, player: ScenePlayer, t0: float, pub_c: Any, pub_d: Any, pub_i: Any, image_cls: Any,
          info_cls: Any, encode_image: Any, truth_path: Path) -> int:
    """The real-time loop: one frame per slot, slots whose time has passed are skipped (counted)."""
    from face_reid_camera.common.stamps import set_stamp

    spec = player.spec
    intr = spec.intrinsics
    frame_id = f"{spec.camera_id}_optical"
    period = 1.0 / spec.rate_hz
    stamps, xys, insides, faces, render_ms = [], [], [], [], []
    skipped = 0
    k = 0
    while True:
        slot = t0 + spec.phase_s + k * period
        if slot >= t0 + spec.duration_s:
            break
        now = time.time()
        if now < slot:
            time.sleep(slot - now)
        elif now - slot > 0.5 * period:  # behind: skip to the next slot still ahead
            behind = int((now - slot) / period)
            skipped += max(1, behind)
            k += max(1, behind)
            continue
        stamp_s = node.get_clock().now().nanoseconds * 1e-9
        r0 = time.perf_counter()
        frame, xy, inside, face_visible = player.render(stamp_s - t0, k)
        render_ms.append(1000.0 * (time.perf_counter() - r0))
        info = info_cls()
        set_stamp(info.header.stamp, stamp_s)
        info.header.frame_id = frame_id
        info.width, info.height = intr.width, intr.height
        info.k = [intr.fx, 0.0, intr.cx, 0.0, intr.fy, intr.cy, 0.0, 0.0, 1.0]
        info.p = [intr.fx, 0.0, intr.cx, 0.0, 0.0, intr.fy, intr.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
        info.distortion_model = "plumb_bob"
        info.d = [0.0] * 5
        pub_i.publish(info)
        for pub, image, encoding in ((pub_c, frame.rgb_bgr, "bgr8"), (pub_d, frame.depth_mm, "16UC1")):
            msg = image_cls()
            set_stamp(msg.header.stamp, stamp_s)
            msg.header.frame_id = frame_id
            msg.height, msg.width, msg.step, msg.data = encode_image(image, encoding)
            msg.encoding = encoding
            pub.publish(msg)
        stamps.append(stamp_s)
        xys.append(xy)
        insides.append(inside)
        faces.append(face_visible)
        k += 1
    n_people = len(spec.people)
    np.savez(
        truth_path, stamp_s=np.asarray(stamps, dtype=np.float64),
        gt_id=np.array([p.gt_id for p in spec.people], dtype=np.int32),
        xy=np.asarray(xys, dtype=np.float64).reshape(-1, n_people, 2),
        in_room=np.asarray(insides, dtype=bool).reshape(-1, n_people),
        face_visible=np.asarray(faces, dtype=bool).reshape(-1, n_people),
    )
    _say("done", camera_id=spec.camera_id, frames=len(stamps), skipped=skipped,
         mean_render_ms=round(float(np.mean(render_ms)), 1) if render_ms else 0.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
