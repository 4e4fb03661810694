"""face-reid-master: the master ROS 2 node (thin: messages <-> MasterCore).

Subscribes to any number of camera topics (a fixed list and/or every discovered topic matching a
regex), feeds each ``face_reid_msgs/CameraFrame`` to :class:`~face_reid_master.core.MasterCore`
and publishes ``face_reid_msgs/NamedTrackArray`` on ``/tracks_named`` after every update (plus
RViz markers). Services: ``~/add_person``, ``~/forget_face``, ``~/list_faces``.
"""

from __future__ import annotations

import math
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_camera.ros.node_main import run_node
from face_reid_master.core import MasterCore
from face_reid_master.records import STATE_LOST, CameraFrameRecord, NamedTrackRecord, PersonRecord
from face_reid_master.ros import params as master_params

USAGE = """usage: face-reid-master [--ros-args --params-file config/master.yaml -p name:=value ...]

The face-reid master node: face_reid_msgs/CameraFrame in, named tracks on /tracks_named out.
Parameters (all declared with descriptions; `ros2 param describe` lists them):
"""


def frame_from_msg(msg: Any) -> CameraFrameRecord:
    """CameraFrame message -> core record (no validation: the core validates and counts)."""
    people = []
    for p in msg.people:
        emb = np.asarray(p.embedding, dtype=np.float32) if p.face_found and len(p.embedding) else None
        people.append(
            PersonRecord(
                np.array([p.position_world.x, p.position_world.y, p.position_world.z]),
                float(p.position_std_m), float(p.height_m), emb, float(p.face_score), float(p.face_quality),
            )
        )
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    return CameraFrameRecord(msg.camera_id, float(stamp), tuple(people), msg.header.frame_id)


def frame_record_to_msg(frame_cls: type, person_cls: type, frame: CameraFrameRecord, stamp_s: float) -> Any:
    """A core record -> face_reid_msgs/CameraFrame stamped ``stamp_s`` (the inverse of :func:`frame_from_msg`;
    replays recorded frames, e.g. ``face-reid-eval --live``)."""
    from face_reid_camera.ros.convert import stamp_from_seconds

    msg = frame_cls()
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp_from_seconds(stamp_s)
    msg.header.frame_id = frame.frame_id
    msg.camera_id = frame.camera_id
    for person in frame.people:
        m = person_cls()
        m.position_world.x, m.position_world.y, m.position_world.z = (float(v) for v in person.position_world)
        m.position_std_m = float(person.position_std_m)
        m.height_m = float(person.height_m)
        if person.embedding is not None:
            m.face_found = True
            m.face_score = float(person.face_score)
            m.face_quality = float(person.face_quality)
            m.embedding = np.asarray(person.embedding, dtype=np.float32).tolist()
        msg.people.append(m)
    return msg


def _time_msg(stamp_s: float, time_cls: type) -> Any:
    from face_reid_camera.ros.convert import stamp_from_seconds

    t = time_cls()
    t.sec, t.nanosec = stamp_from_seconds(max(0.0, stamp_s))
    return t


def tracks_to_msg(array_cls: type, track_cls: type, tracks: list[NamedTrackRecord], stamp_s: float,
                  frame_id: str) -> Any:
    """Core tracks -> face_reid_msgs/NamedTrackArray."""
    from builtin_interfaces.msg import Time

    out = array_cls()
    out.header.frame_id = frame_id
    out.header.stamp = _time_msg(stamp_s, Time)
    for tr in tracks:
        m = track_cls()
        m.track_id, m.face_id, m.name = int(tr.track_id), int(tr.face_id), tr.name
        m.identity_confidence = float(tr.identity_confidence)
        m.face_observations = int(tr.face_observations)
        m.position.x, m.position.y = float(tr.position_xy[0]), float(tr.position_xy[1])
        m.velocity.x, m.velocity.y = float(tr.velocity_xy[0]), float(tr.velocity_xy[1])
        m.covariance = [float(v) for v in np.asarray(tr.covariance, dtype=np.float64).reshape(16)]
        m.height_m = float(tr.height_m) if math.isfinite(tr.height_m) else 0.0
        m.state = int(tr.state)
        m.first_seen = _time_msg(tr.first_seen_s, Time)
        m.last_seen = _time_msg(tr.last_seen_s, Time)
        m.cameras = list(tr.cameras)
        out.tracks.append(m)
    return out


def markers_for(tracks: list[NamedTrackRecord], stamp_msg: Any, frame_id: str) -> Any:
    """RViz markers: a cylinder per person and a text label (name, face id or track id)."""
    from visualization_msgs.msg import Marker, MarkerArray

    arr = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    arr.markers.append(clear)
    for tr in tracks:
        height = tr.height_m if math.isfinite(tr.height_m) and tr.height_m > 0 else 1.7
        body = Marker()
        body.header.frame_id, body.header.stamp = frame_id, stamp_msg
        body.ns, body.id, body.type, body.action = "people", int(tr.track_id) * 2, Marker.CYLINDER, Marker.ADD
        body.pose.position.x, body.pose.position.y = float(tr.position_xy[0]), float(tr.position_xy[1])
        body.pose.position.z = height / 2
        body.pose.orientation.w = 1.0
        body.scale.x = body.scale.y = 0.4
        body.scale.z = height
        named, lost = bool(tr.name), tr.state == STATE_LOST
        body.color.r, body.color.g, body.color.b = (0.1, 0.8, 0.2) if named else (0.2, 0.5, 0.9)
        body.color.a = 0.3 if lost else 0.8
        label = Marker()
        label.header = body.header
        label.ns, label.id, label.type, label.action = "labels", int(tr.track_id) * 2 + 1, Marker.TEXT_VIEW_FACING, 0
        label.pose.position.x, label.pose.position.y = body.pose.position.x, body.pose.position.y
        label.pose.position.z = height + 0.3
        label.pose.orientation.w = 1.0
        label.scale.z = 0.25
        label.color.r = label.color.g = label.color.b = label.color.a = 1.0
        who = tr.name or (f"face {tr.face_id}" if tr.face_id else f"track {tr.track_id}")
        label.text = f"{who} ({tr.identity_confidence:.2f})" if tr.face_id else who
        arr.markers.extend([body, label])
    return arr


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    return run_node("face-reid-master", USAGE, master_params.TABLE, lambda: _make_node_class()(),
                    (ValueError, FileNotFoundError, OSError), argv)


def _make_node_class() -> type:
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from visualization_msgs.msg import MarkerArray

    from face_reid_msgs.msg import CameraFrame, NamedTrack, NamedTrackArray
    from face_reid_msgs.srv import AddPerson, ForgetFace, ListFaces

    class _MasterNode(Node):
        def __init__(self) -> None:
            super().__init__(master_params.NODE_NAME)
            values: dict[str, Any] = {}
            for spec in master_params.MASTER_PARAMS:
                self.declare_parameter(spec.name, spec.default, ParameterDescriptor(description=spec.description))
                values[spec.name] = master_params.TABLE.check_value(spec.name, self.get_parameter(spec.name).value)
            self.values = values
            config = master_params.master_config(values)
            self.store = self._open_store() if values["persist_faces"] else None
            gallery = self._load_gallery(str(values["gallery_path"]))
            likelihood = None
            if values["likelihood_path"]:
                from face_reid_master.identity.likelihood import load_likelihood_model

                likelihood = load_likelihood_model(str(values["likelihood_path"]))  # missing / bad file: clear error
            self.core = MasterCore(config, likelihood, self.store, gallery)
            self._subscribed: dict[str, Any] = {}
            self._rejections: dict[str, tuple[int, float]] = {}
            qos = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
            self._frame_qos = qos
            self.tracks_pub = self.create_publisher(NamedTrackArray, str(values["tracks_topic"]), qos)
            markers_topic = str(values["markers_topic"])
            self.markers_pub = self.create_publisher(MarkerArray, markers_topic, 10) if markers_topic else None
            rate = float(values["max_publish_rate_hz"])
            self._min_publish_interval_s = 1.0 / rate if rate > 0 else 0.0
            self._last_publish = -float("inf")
            for topic in master_params.clean_list(values["camera_topics"]):
                self._subscribe(topic)
            self._regex = re.compile(str(values["camera_topic_regex"])) if values["camera_topic_regex"] else None
            if self._regex is not None:
                self._discover()
                self.create_timer(float(values["topic_discovery_period_s"]), self._discover)
            self.create_timer(1.0 / float(values["tick_rate_hz"]), self._tick)
            self.create_timer(float(values["stats_log_period_s"]), self._log_stats)
            self.create_service(AddPerson, "~/add_person", self._add_person)
            self.create_service(ForgetFace, "~/forget_face", self._forget_face)
            self.create_service(ListFaces, "~/list_faces", self._list_faces)
            self.get_logger().info(
                f"master: method={config.method}, {len(self.core.identity.face_ids())} learned faces loaded, "
                f"{len(self.core.people.names())} predefined people, publishing {self.tracks_pub.topic_name}"
            )

        # --- set-up ------------------------------------------------------------------------
        def _open_store(self) -> Any:
            from face_reid_master.storage.face_store import FaceStore, default_db_path

            path = Path(str(self.values["db_path"])) if self.values["db_path"] else default_db_path()
            retention = float(self.values["retention_unnamed_s"]) or None
            store = FaceStore(path, retention_unnamed_s=retention)
            if store.recovered_from is not None:
                self.get_logger().error(
                    f"face database {path} was corrupt: moved to {store.recovered_from}, started a fresh one"
                )
            return store

        def _load_gallery(self, path: str) -> dict[str, np.ndarray]:
            if not path:
                return {}
            from face_reid_camera.faces.photos import PhotoEmbedder
            from face_reid_master.storage.gallery import load_gallery

            result = load_gallery(Path(path), PhotoEmbedder())
            skipped = len(result.skipped_unreadable) + len(result.skipped_no_face)
            if skipped:
                self.get_logger().warning(
                    f"gallery {path}: skipped {len(result.skipped_unreadable)} unreadable photos and "
                    f"{len(result.skipped_no_face)} without a detectable face"
                )
            return dict(result.people)

        # --- camera topics -------------------------------------------------------------------
        def _subscribe(self, topic: str) -> None:
            if topic in self._subscribed:
                return
            self._subscribed[topic] = self.create_subscription(CameraFrame, topic, self._on_frame, self._frame_qos)
            self.get_logger().info(f"subscribed to camera topic {topic}")

        def _discover(self) -> None:
            assert self._regex is not None
            for name, types in self.get_topic_names_and_types():
                if "face_reid_msgs/msg/CameraFrame" in types and self._regex.search(name):
                    self._subscribe(name)

        def _now_s(self) -> float:
            return self.get_clock().now().nanoseconds * 1e-9

        def _on_frame(self, msg: Any) -> None:
            try:
                record = frame_from_msg(msg)
            except (ValueError, TypeError) as exc:
                self._reject("malformed", f"malformed CameraFrame: {exc}")
                return
            if record.frame_id != self.values["world_frame_id"]:
                self._reject(
                    "frame_id",
                    f"frame from {record.camera_id!r} is in frame {record.frame_id!r}, "
                    f"expected {self.values['world_frame_id']!r}",
                )
                return
            now = self._now_s() if self.values["check_stamps_against_clock"] else None
            outcome = self.core.process_frame(record, now)
            if not outcome.accepted:
                reason = outcome.reason.split(" ")[0]
                self._reject(reason, f"frame from {record.camera_id!r} rejected: {outcome.reason}")
                return
            for ev in outcome.identity_events:
                self.get_logger().info(
                    f"track {ev.track_id}: {ev.kind.value} face {ev.face_id} (p={ev.confidence:.2f})"
                )
            if self._min_publish_interval_s and time.monotonic() - self._last_publish < self._min_publish_interval_s:
                return  # rate cap: the next frame or tick publishes the (then newer) state
            self._publish(record.stamp_s)

        def _tick(self) -> None:
            now = self._now_s()
            if self.values["check_stamps_against_clock"]:
                # Lag by the tracker's delay bound so that frames in flight still arrive in order.
                self.core.tick(now - float(self.values["tracker.max_detection_delay_s"]))
            self._publish(now)

        def _publish(self, stamp_s: float) -> None:
            tracks = self.core.tracks()
            frame_id = str(self.values["world_frame_id"])
            msg = tracks_to_msg(NamedTrackArray, NamedTrack, tracks, stamp_s, frame_id)
            self.tracks_pub.publish(msg)
            self._last_publish = time.monotonic()
            # Markers are for a person looking at RViz: building them for nobody costs the master time.
            if self.markers_pub is not None and self.markers_pub.get_subscription_count() > 0:
                self.markers_pub.publish(markers_for(tracks, msg.header.stamp, frame_id))

        def _reject(self, reason: str, message: str) -> None:
            count, last = self._rejections.get(reason, (0, -1e9))
            now = time.monotonic()
            if now - last >= 5.0:
                self.get_logger().warning(f"{message} [{count + 1} so far]")
                last = now
            self._rejections[reason] = (count + 1, last)

        def _log_stats(self) -> None:
            stats = {k: v for k, v in self.core.stats.as_dict().items() if v}
            self.get_logger().info(f"stats: {stats}")

        # --- services --------------------------------------------------------------------------
        def _add_person(self, request: Any, response: Any) -> Any:
            name = request.name.strip()
            rows: list[np.ndarray] = []
            notes: list[str] = []
            try:
                if not name:
                    raise ValueError("name must not be empty")
                emb = np.asarray(request.embeddings, dtype=np.float32)
                if emb.size % 128:
                    raise ValueError(f"embeddings must hold k x 128 values, got {emb.size}")
                if emb.size:
                    rows.extend(emb.reshape(-1, 128))
                if request.image_paths:
                    from face_reid_camera.faces.photos import PhotoEmbedder, PhotoError

                    embedder = PhotoEmbedder()
                    for path in request.image_paths:
                        try:
                            found = embedder.embed_photo(Path(path))
                        except (PhotoError, OSError) as exc:
                            notes.append(f"skipped {path}: {exc}")
                            continue
                        if found is None:
                            notes.append(f"skipped {path}: no face found")
                        else:
                            rows.append(found.embedding)
                if not rows:
                    raise ValueError("no usable face embedding")
                self.core.add_person(name, np.stack(rows))
                response.success, response.num_embeddings = True, len(rows)
                response.message = "; ".join([f"added {name} with {len(rows)} embeddings", *notes])
            except ValueError as exc:
                response.success, response.message = False, "; ".join([str(exc), *notes])
            self.get_logger().info(f"add_person: {response.message}")
            return response

        def _forget_face(self, request: Any, response: Any) -> Any:
            ids = [int(request.face_id)] if request.face_id else [
                fid for fid in self.core.identity.face_ids() if self.core.face_name(fid) == request.name
            ]
            if not request.face_id and not request.name:
                response.success, response.message = False, "give a face_id or a name"
                return response
            forgotten = [fid for fid in ids if self.core.forget_face(fid)]
            response.forgotten_face_ids = forgotten
            response.success = bool(forgotten)
            response.message = f"forgot faces {forgotten}" if forgotten else "no such face"
            self.get_logger().info(f"forget_face: {response.message}")
            return response

        def _list_faces(self, request: Any, response: Any) -> Any:
            for face in self.core.identity.export_faces():
                response.face_ids.append(face.face_id)
                response.names.append(self.core.face_name(face.face_id))
                response.num_features.append(int(face.features.shape[0]))
                response.last_seen_s.append(float(face.last_seen_s))
            return response

        def shutdown(self) -> None:
            self.core.flush()
            if self.store is not None:
                self.store.close()

    return _MasterNode


if __name__ == "__main__":
    sys.exit(main())
