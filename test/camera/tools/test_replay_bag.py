"""face-reid-replay on recordings of a camera driver's topics: the real Kinect desk frames written into a
rosbag2 (sqlite3 and MCAP) the way a RealSense-style driver publishes them (bgr8 colour, 16UC1 aligned depth,
its CameraInfo, driver topic names) give the same floor and people as the folder of PNGs."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import RGBD_DIR

from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_camera.tools.replay import main

pytest.importorskip("rosbags")

COLOR, DEPTH, INFO = "/camera/color/image_raw", "/camera/aligned_depth_to_color/image_raw", \
    "/camera/aligned_depth_to_color/camera_info"


def _write_bag(path: Path, storage: str, shuffle: bool = False, forged: dict[int, float] | None = None) -> int:
    """The desk frames 0.1 s apart, recorded at their stamps (+ 0-2 us); ``forged``: frame -> seconds added to the
    stamps of its colour and depth images (not to their record time)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    Image, CameraInfo = store.types["sensor_msgs/msg/Image"], store.types["sensor_msgs/msg/CameraInfo"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    RegionOfInterest = store.types["sensor_msgs/msg/RegionOfInterest"]
    kinect = CameraIntrinsics.kinect_default(640, 480)
    frames = sorted((RGBD_DIR / "pcl_desk").glob("*_depth_mm.png"))
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage]) as writer:
        conns = {t: writer.add_connection(t, m.__msgtype__, typestore=store)
                 for t, m in ((COLOR, Image), (DEPTH, Image), (INFO, CameraInfo))}
        for k, depth_path in enumerate(frames):
            t_ns = 1_700_000_000_000_000_000 + k * 100_000_000
            header = Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="camera_color_optical_frame")
            f_ns = t_ns + int((forged or {}).get(k, 0.0) * 1e9)
            image_header = Header(stamp=Time(sec=f_ns // 10**9, nanosec=f_ns % 10**9), frame_id=header.frame_id)
            depth = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)
            color = cv2.imread(str(depth_path).replace("_depth_mm.png", "_rgb.png"), cv2.IMREAD_COLOR)
            k_matrix = np.array([kinect.fx, 0, kinect.cx, 0, kinect.fy, kinect.cy, 0, 0, 1.0])
            msgs = [
                (INFO, CameraInfo(header=header, height=480, width=640, distortion_model="plumb_bob",
                                  d=np.zeros(5), k=k_matrix,
                                  r=np.eye(3).reshape(-1), p=np.zeros(12), binning_x=0, binning_y=0,
                                  roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))),
                (DEPTH, Image(header=image_header, height=480, width=640, encoding="16UC1", is_bigendian=0, step=1280,
                              data=np.frombuffer(depth.astype("<u2").tobytes(), np.uint8))),
                (COLOR, Image(header=image_header, height=480, width=640, encoding="bgr8", is_bigendian=0, step=1920,
                              data=np.frombuffer(color.tobytes(), np.uint8))),
            ]
            if shuffle:
                msgs = [msgs[0], msgs[2], msgs[1]]
            for j, (topic, msg) in enumerate(msgs):
                writer.write(conns[topic], t_ns + j * 1000, store.serialize_cdr(msg, msg.__msgtype__))
    return len(frames)


def _lines(out: str) -> list[dict]:
    return [json.loads(line) for line in out.splitlines() if line.strip()]


@pytest.mark.parametrize("storage", ["SQLITE3", "MCAP"])
def test_a_recording_replays_like_the_folder_of_frames(tmp_path: Path, storage: str,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    n = _write_bag(tmp_path / "bag", storage, shuffle=storage == "MCAP")
    assert main([str(RGBD_DIR / "pcl_desk"), "--no-faces", "--no-bodies"]) == 0
    folder = _lines(capsys.readouterr().out)
    assert main([str(tmp_path / "bag"), "--no-faces", "--no-bodies"]) == 0
    bag = _lines(capsys.readouterr().out)
    assert len(bag) == len(folder) == n
    for a, b in zip(folder, bag, strict=True):
        assert b["num_people"] == a["num_people"] == 0
        assert b["floor"]["camera_height_m"] == pytest.approx(a["floor"]["camera_height_m"], abs=0.01)
        assert b["floor"]["camera_tilt_down_deg"] == pytest.approx(a["floor"]["camera_tilt_down_deg"], abs=0.5)
    assert float(bag[1]["frame"]) - float(bag[0]["frame"]) == pytest.approx(0.1, abs=1e-6)  # named by stamp


def test_topics_can_be_named_and_wrong_ones_are_explained(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _write_bag(tmp_path / "bag", "SQLITE3")
    assert main([str(tmp_path / "bag"), "--no-faces", "--no-bodies", "--color-topic", COLOR, "--depth-topic", DEPTH,
                 "--info-topic", INFO]) == 0
    assert len(_lines(capsys.readouterr().out)) == 3
    assert main([str(tmp_path / "bag"), "--no-faces", "--no-bodies", "--depth-topic", "/nope"]) == 1
    err = capsys.readouterr().err
    assert "topic '/nope' is not in the recording" in err and "no frame could be read" in err


def test_one_pair_stamped_an_hour_ahead_of_its_recording_does_not_silence_the_replay(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The record time is the replay's receive clock: the forged first pair is dropped and said so on stderr, the
    frames after it replay (the code before replayed only the forged one: its stamp stayed the pairing's last)."""
    n = _write_bag(tmp_path / "bag", "SQLITE3", forged={0: 3600.0})
    assert main([str(tmp_path / "bag"), "--no-faces", "--no-bodies"]) == 0
    out = capsys.readouterr()
    names = [float(line["frame"]) for line in _lines(out.out)]
    assert names == pytest.approx([1_700_000_000.0 + 0.1 * k for k in range(1, n)], abs=1e-6)
    assert "images dropped for their stamps: 2 stamp_future (stamped more than 2 s after they were received)" \
        in out.err
