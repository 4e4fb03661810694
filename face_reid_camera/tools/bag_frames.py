"""RGB-D frames from a recording of the camera driver's topics (rosbag2 sqlite3 or MCAP, or a ROS 1 bag),
read with the pure-Python ``rosbags`` package: a site records its cameras once (``ros2 bag record``) and
replays them through the pipeline offline (``face-reid-replay BAG``).

Topics are found by type when not given: the depth image is the ``sensor_msgs/Image`` whose encoding is
16UC1 / 32FC1 (or whose name says depth), the colour image another Image topic, the camera info the
``CameraInfo`` next to the depth topic (else the only one). Colour and depth are paired by stamp as the
camera node pairs them (``StampSynchronizer``), with the recording's own clock (each message's record time:
when the recorder received it) as the receive clock: a stamp far ahead of it is dropped as the live node would
drop it (no age limit: offline nothing is late); a registered depth smaller than the colour is fine (the
pipeline scales the intrinsics).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_camera.common.stamps import stamp_to_seconds
from face_reid_camera.ros.frame_sync import DROP_MEANINGS, StampSynchronizer
from face_reid_camera.ros.image_codec import decode_image, depth_to_metres, to_bgr

__all__ = ["BagTopics", "bag_frames", "is_bag"]

_DEPTH_ENCODINGS = ("16UC1", "32FC1", "mono16")


def is_bag(path: Path) -> bool:
    """A rosbag2 folder (metadata.yaml), an .mcap / .db3 file or a ROS 1 .bag."""
    return (path.is_dir() and (path / "metadata.yaml").exists()) or path.suffix in (".mcap", ".db3", ".bag")


@dataclass(frozen=True)
class BagTopics:
    """The topics a replay reads ('' = found by type)."""

    color: str = ""
    depth: str = ""
    info: str = ""


def _choose(reader: Any, want: BagTopics) -> BagTopics:
    images = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/Image"]
    infos = [c.topic for c in reader.connections if c.msgtype == "sensor_msgs/msg/CameraInfo"]
    names = sorted({c.topic for c in images})
    depth = want.depth
    if not depth:
        depths = [t for t in names if "depth" in t]
        if len(depths) != 1:
            raise ValueError(f"cannot tell the depth topic among the Image topics {names}: give --depth-topic")
        depth = depths[0]
    color = want.color or next((t for t in names if t != depth and "depth" not in t), "")
    if not color:
        raise ValueError(f"no colour Image topic besides {depth!r} in {names}: give --color-topic")
    info = want.info
    if not info:
        near = [t for t in infos if t.rsplit("/", 1)[0] == depth.rsplit("/", 1)[0]]
        info = near[0] if near else (infos[0] if len(infos) == 1 else "")
        if not info:
            raise ValueError(f"cannot tell the depth image's CameraInfo among {sorted(infos)}: give --info-topic")
    for topic in (color, depth, info):
        if topic not in {c.topic for c in reader.connections}:
            raise ValueError(f"topic {topic!r} is not in the recording")
    return BagTopics(color, depth, info)


def bag_frames(path: Path, topics: BagTopics = BagTopics(), slop_s: float = 0.02) -> Iterator[Any]:
    """Yield ``face_reid_camera.tools.replay.ReplayFrame`` s of a recording, in time order (names: the stamp)."""
    from rosbags.highlevel import AnyReader

    from face_reid_camera.tools.replay import ReplayFrame

    with AnyReader([path]) as reader:
        chosen = _choose(reader, topics)
        wanted = [c for c in reader.connections if c.topic in (chosen.color, chosen.depth, chosen.info)]
        sync: StampSynchronizer[Any, Any] = StampSynchronizer(slop_s)
        intrinsics: CameraIntrinsics | None = None
        for conn, record_ns, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == chosen.info:
                k = [float(v) for v in msg.k]
                intrinsics = CameraIntrinsics(k[0], k[4], k[2], k[5], int(msg.width), int(msg.height))
                continue
            add = sync.add_color if conn.topic == chosen.color else sync.add_depth
            pair = add(stamp_to_seconds(msg.header.stamp), msg, record_ns * 1e-9)
            if pair is None or intrinsics is None:
                continue
            stamp, color_msg, depth_msg = pair
            color = to_bgr(_image(color_msg), str(color_msg.encoding))
            depth = depth_to_metres(_image(depth_msg), str(depth_msg.encoding))
            dh, dw = depth.shape[:2]
            hint = intrinsics if (intrinsics.width, intrinsics.height) == (dw, dh) else intrinsics.scaled(dw, dh)
            yield ReplayFrame(f"{stamp:.6f}", depth, color, hint)
        drops = {reason: n for reason, n in sync.stats.rejected.items() if n}
        if drops:
            print(f"face-reid-replay: recording {path}: images dropped for their stamps: " + ", ".join(
                f"{n} {reason} ({DROP_MEANINGS[reason]})" for reason, n in drops.items()),
                file=sys.stderr)


def _image(msg: Any) -> np.ndarray:
    return decode_image(str(msg.encoding), int(msg.height), int(msg.width), int(msg.step),
                        np.asarray(msg.data, dtype=np.uint8).tobytes(), bool(msg.is_bigendian))
