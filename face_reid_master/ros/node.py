"""face-reid-master: the master ROS 2 lifecycle node (thin: messages <-> MasterCore).

configure opens the face database, reads the gallery and the likelihood and builds
:class:`~face_reid_master.core.MasterCore` (and the ``~/add_person``, ``~/forget_face``, ``~/list_faces``
services); activate subscribes to the camera topics (a fixed list and/or every discovered topic matching a
regex) and, once per cycle, applies every frame received since the last cycle in stamp order (the oldest
dropped and counted when more arrived than ``cycle_budget_ms`` allows), publishes
``face_reid_msgs/NamedTrackArray`` on ``/tracks_named`` (serialized by :mod:`~face_reid_master.ros.track_cdr`;
plus RViz markers while someone looks), then, at most once per ``identity_period_s``, one identity update for
the frames applied since the last; and publishes
``/diagnostics``; deactivate / cleanup undo it (cleanup saves every face). Faces are committed by the store's
worker thread (:mod:`~face_reid_master.storage.write_behind`).
"""

from __future__ import annotations

import gc
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import MarkerArray

from face_reid_camera.common.checks import shown
from face_reid_camera.common.clock_step import ClockStepDetector
from face_reid_camera.common.diagnostics import DiagnosticReport, NodeHealth
from face_reid_camera.common.embedding_spaces import embedder_for_space, space_dim
from face_reid_camera.common.ros.lifecycle import ManagedNode, run_node
from face_reid_camera.common.ros.sealed import seal_payload
from face_reid_camera.common.stamps import set_stamp
from face_reid_master.core import MasterCore
from face_reid_master.cycle_schedule import CycleSchedule
from face_reid_master.health import MasterHealthWatch
from face_reid_master.identity.predefined_people import with_kept_people
from face_reid_master.output_stamps import OutputStamps
from face_reid_master.records import CameraFrameRecord
from face_reid_master.ros import params as master_params
from face_reid_master.ros.admin_services import AdminServices
from face_reid_master.ros.camera_topics import CameraTopics
from face_reid_master.ros.convert import markers_for
from face_reid_master.ros.frame_receiver import FrameReceiver
from face_reid_master.ros.people_topics import PeopleTopics
from face_reid_master.ros.track_cdr import tracks_to_cdr
from face_reid_master.ros.tracks_in import OwnTopicListener
from face_reid_master.tracks_auth import TRACKS_PURPOSE, sealed_topic
from face_reid_msgs.msg import NamedTrackArray, Sealed

USAGE = """usage: face-reid-master [--ros-args --params-file config/master.yaml -p name:=value ...]

The face-reid master node (a lifecycle node; autostart:=false waits for a lifecycle manager):
face_reid_msgs/CameraFrame in, named tracks on /tracks_named out, status on /diagnostics.
Parameters (all declared with descriptions and ranges; `ros2 param describe` lists them):
"""

_MAX_LOG_CHARS = 300  # log lines about a frame are cut to this


def _markers_topic(topic: str, secured: bool, log: Callable[[str], None]) -> str:
    """Where RViz markers go: nowhere on a secured network (markers are plain: names and positions in clear)."""
    if topic and secured:
        log(f"secured network: no RViz markers on {topic[:200]} (they would carry names and positions in clear)")
        return ""
    return topic


class MasterNode(ManagedNode):
    """The master node; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(master_params.TABLE, **kwargs)
        self.values: dict[str, Any] = {}
        self.core: MasterCore | None = None
        self._photos: Any = None  # PhotoEmbedder of the master's space, loaded on first use
        self.store: Any = None
        self.health: NodeHealth | None = None
        self._watch = MasterHealthWatch()  # store failures, faces lost at open, overload, another master
        self.admin = AdminServices(self)  # ~/list_faces, ~/add_person, ~/forget_face
        self.cameras = CameraTopics(self, self._on_camera_message, self._reject)
        self._openers: dict[str, Any] = {}  # purpose -> Opener, when the network has a key
        self._own_timers: list[Any] = []
        self.tracks_pub: Any = None  # /tracks_named, or <tracks_topic>_sealed on a secured network
        self._tracks_sealer: Any = None  # seals the tracks (purpose "tracks") when the network has a key
        self._own_topic = OwnTopicListener(self)  # a second master, or a keyless participant, on the tracks topic?
        self._stamps = OutputStamps()  # output stamps: not ahead of this master's clock, never backwards
        self.markers_pub: Any = None
        self.people_topics: PeopleTopics | None = None  # /people and REP-155 (optional outputs)
        self.receiver = FrameReceiver(None, {}, self._reject, self.log_throttled)  # messages into the next cycle
        self.receiver.camera_ids = self.cameras.camera_ids  # which topics each camera id's frames come on
        self.schedule = CycleSchedule()  # cycles, identity steps and publishes (monotonic clock: time.monotonic)
        self._wall_steps = ClockStepDetector()  # this host's wall clock stepping (an ERROR while it lasts)

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        from face_reid_master.identity.size_likelihood import default_face_likelihood, load_face_likelihood

        values = self.parameter_values()
        config = master_params.master_config(values)
        regex = re.compile(str(values["camera_topic_regex"])) if values["camera_topic_regex"] else None
        likelihood = (load_face_likelihood(values["likelihood_path"]) if values["likelihood_path"]  # clear errors
                      else default_face_likelihood(str(values["embedding_space"])))
        self.values = values
        self.people_topics = PeopleTopics(self, values)  # checks its parameters and the world->map file first
        self.store = self._open_store() if values["persist_faces"] else None
        gallery = _gallery_people(self, str(values["gallery_path"]))
        if self.store is not None:  # the people named at run time (face-reid-faces add) win over the folder's
            gallery, both = with_kept_people(gallery, self.store.load_people())
            if both:
                self.log(f"named at run time, used instead of the gallery folder's: {', '.join(both)[:300]}",
                         private=True)
        body_metric = None
        if config.body_appearance_tracking and values["body_metric_path"]:
            from face_reid_master.body.metric_file import load_body_metric

            body_metric = load_body_metric(str(values["body_metric_path"]))
        confidence_map = None
        if values["confidence_map_path"]:
            from face_reid_master.identity.confidence_map import load_confidence_map

            confidence_map = load_confidence_map(str(values["confidence_map_path"]))
        self.core = MasterCore(config, likelihood, self.store, gallery, body_metric, confidence_map)
        self.cameras.configure(re.compile(str(values["sealed_topic_regex"])) if values["network_key_path"] else regex,
                               int(values["max_camera_topics"]),
                               frozenset(master_params.clean_list(values["known_camera_ids"])),
                               sealed=bool(values["network_key_path"]))
        self._openers, self._tracks_sealer = {}, None
        if values["network_key_path"]:
            from face_reid_camera.common.sealing import Opener, Sealer, load_network_key

            key = load_network_key(str(values["network_key_path"]))
            age = float(values["max_seal_age_s"])
            started = time.time()  # nothing sealed before this configure is accepted (replays across restarts)
            self._openers = {purpose: Opener(key, purpose, age, started) for purpose in ("frames", "requests")}
            self._tracks_sealer = Sealer(key, self.get_fully_qualified_name(), TRACKS_PURPOSE)
            self._own_topic.configure(key, self.get_fully_qualified_name(), age)
            self.get_logger().info("secured: only frames and admin requests sealed with the network key are accepted; "
                                   "tracks are published sealed with it")
            clear = [name for name in ("publish_people", "publish_hri") if values[name]]
            if clear:  # standard message types: they cannot carry a seal
                self.get_logger().warning(
                    f"secured, but {', '.join(clear)} on: those outputs carry names and positions in clear and "
                    "any participant could forge them; robots should act on the sealed tracks")
        else:
            self.get_logger().warning(
                "UNSECURED: no network_key_path: camera frames (face embeddings, biometric data) travel in clear "
                "and any participant of this DDS domain can read them or inject frames")
        self.schedule = CycleSchedule(float(values["min_cycle_period_s"]), float(values["identity_period_s"]),
                                      float(values["max_publish_rate_hz"]), float(values["cycle_budget_ms"]))
        self.health = NodeHealth(self.get_name(), self.get_fully_qualified_name(), float(values["no_input_warning_s"]))
        self.receiver.health, self.receiver.openers = self.health, self._openers
        self.admin.create(bool(values["admin_services"]), secured=bool(values["network_key_path"]))
        self.get_logger().info(
            f"master: method={config.method}, {len(self.core.identity.face_ids())} learned faces loaded, "
            f"{len(self.core.people.names())} predefined people, body appearance "
            f"{self.core.body_metric.space if self.core.body_metric else 'off'}"
        )

    def activate(self) -> None:
        values = self.values
        qos = QoSProfile(depth=50, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        self.cameras.qos = qos
        # secured: the tracks only sealed (so that no consumer takes a spoof on the plain topic for the master's)
        self.tracks_pub = (self.create_publisher(Sealed, sealed_topic(str(values["tracks_topic"])), qos)
                           if self._tracks_sealer is not None else
                           self.create_publisher(NamedTrackArray, str(values["tracks_topic"]), qos))
        self._stamps.reset()
        markers_topic = _markers_topic(str(values["markers_topic"]), self._tracks_sealer is not None,
                                       self.get_logger().info)
        self.markers_pub = self.create_publisher(MarkerArray, markers_topic, 10) if markers_topic else None
        if self.people_topics is not None:
            self.people_topics.activate()
        for topic in master_params.clean_list(values["camera_topics"]):
            self.cameras.subscribe(topic)
        if self.cameras.regex is not None:
            self.cameras.discover()
        self._own_timers.append(self.create_steady_timer(float(values["topic_discovery_period_s"]),
                                                         self.cameras.discover))
        self._own_timers.append(self.create_steady_timer(1.0 / float(values["tick_rate_hz"]), self._tick))
        if self.schedule.publish_interval_s:
            self._own_timers.append(self.create_steady_timer(self.schedule.publish_interval_s, self._flush))
        self._own_timers.append(self.create_steady_timer(float(values["stats_log_period_s"]), self._log_stats))
        assert self.health is not None
        self.health.start(self.now_s())
        # What exists now (modules, models, loaded faces) lives as long as the node: out of the collector's full
        # passes, which would otherwise scan it all and stall a cycle for tens of ms.
        gc.freeze()
        self.get_logger().info(f"master: publishing {self.tracks_pub.topic_name}")

    def deactivate(self) -> None:
        self.finish_frames()  # the face table as the applied frames leave it (no tick runs while inactive)
        for timer in self._own_timers:
            self.destroy_timer(timer)
        self._own_timers = []
        self.cameras.destroy()
        self.receiver.intake.clear()  # frames of a cycle that will not run
        for pub in (self.tracks_pub, self.markers_pub):
            if pub is not None:
                self.destroy_publisher(pub)
        self.tracks_pub = self.markers_pub = None
        self._own_topic.listen("", False)
        if self.people_topics is not None:
            self.people_topics.deactivate()

    def cleanup(self) -> None:
        self.admin.destroy()
        if self.core is not None:
            self.core.flush()
        if self.store is not None:
            self.store.close()
        self.core = self.store = None

    def configured_core(self) -> MasterCore:
        if self.core is None:
            raise ValueError("the master is not configured")
        return self.core

    # ------------------------------------------------------------------ set-up
    def _open_store(self) -> Any:
        from face_reid_master.storage.face_store import FaceStore, default_db_path
        from face_reid_master.storage.write_behind import WriteBehindStore

        path = Path(str(self.values["db_path"])) if self.values["db_path"] else default_db_path()
        retention = float(self.values["retention_unnamed_s"]) or None
        space = str(self.values["embedding_space"])
        # commits (fsync) on a worker thread: a cycle never waits for the disk
        store = WriteBehindStore(lambda: FaceStore(path, retention_unnamed_s=retention, embedding_dim=space_dim(space),
                                                   embedding_space=space))
        if store.recovered_from is not None:
            self.log(f"face database {path} was corrupt: moved to {store.recovered_from}, started a fresh one",
                     "error", private=True)
        if retention is not None:  # a shorter retention than before deletes faces on the first cycle: say so now
            doomed = len(store.prunable_unnamed(time.time()))
            if doomed:
                self.log(f"retention_unnamed_s={retention:g} s: {doomed} of the {len(store.list_faces())} stored "
                         f"faces (unnamed, not seen for longer) will be deleted from {path} once frames arrive",
                         "warn", private=True)
        self._watch.store_opened(store.lost_face_ids, store.recovered_from, store.salvaged_face_ids)
        return store

    def photo_embedder(self) -> Any:
        """Photos -> embeddings of the master's space (gallery folder, add-person service)."""
        from face_reid_camera.faces.embedder import load_embedder
        from face_reid_camera.faces.photos import PhotoEmbedder

        if self._photos is None:
            choice = embedder_for_space(str(self.values["embedding_space"]))
            self._photos = PhotoEmbedder(embedder=load_embedder(choice))
        return self._photos

    # ------------------------------------------------------------------ camera messages
    def _on_camera_message(self, message: bytes, topic: str = "") -> bool:
        """A camera topic's message (CDR bytes; sealed on a secured network): whether it was received."""
        if self._openers:
            return self._on_sealed(message, topic)
        return self._on_frame(message, topic)

    def _on_frame(self, frame: bytes | Any, topic: str = "") -> bool:
        """A camera message (its CDR bytes, or a CameraFrame): a cycle with it and everything else already waiting
        (the cycle drains every camera subscription, so the executor finds nothing left for the messages that came
        meanwhile), no sooner than min_cycle_period_s after the last cycle began."""
        self._wait_for_cycle()
        now = self.now_s()
        received = self.receiver.receive(frame, now, topic=topic)
        self._cycle(now)
        return received

    @property
    def frames_dropped_overload(self) -> int:
        """Frames dropped for overload since start (oldest first, fairly across cameras)."""
        return self.receiver.intake.dropped

    def _wait_for_cycle(self) -> None:
        """Sleep out what is left of min_cycle_period_s since the last cycle began (messages queue meanwhile)."""
        wait = self.schedule.wait_s(time.monotonic())
        if wait > 0.0:
            time.sleep(wait)

    def _on_sealed(self, sealed: bytes, topic: str = "") -> bool:
        """A sealed camera message's CDR bytes (secured network): opened, then queued like a plain one (True)."""
        self._wait_for_cycle()
        now = self.now_s()
        if received := self.receiver.receive_sealed(sealed, now, topic):
            self._cycle(now)
        return received

    def _cycle(self, now: float) -> None:
        """One master cycle: everything received since the last one (by ``now``, the node clock's seconds), in
        stamp order, then one publish."""
        core, health = self.core, self.health
        if core is None or health is None or self.tracks_pub is None:
            return
        limit = self.schedule.begin_cycle(time.monotonic())
        self.receiver.drain(self.cameras.subscribed.values(), now, self.cameras.heard)
        frames, dropped = self.receiver.intake.take(limit)
        if dropped:
            self.log_throttled("overload", f"overloaded: dropped the {dropped} oldest frames of this cycle "
                                           f"({len(frames)} applied, budget {self.schedule.budget.budget_ms:g} ms)",
                               self.frames_dropped_overload, warn=True)
        t_cycle = time.perf_counter()
        newest = -float("inf")
        publish_s = 0.0
        try:
            for pending in frames:
                stamp = self._apply(core, health, pending.payload, now)
                if stamp is not None:
                    newest = max(newest, stamp)
            if newest > -float("inf"):  # positions go out before the identity update: names follow a cycle later
                t_publish = time.perf_counter()
                self._publish_cycle(newest)
                publish_s = time.perf_counter() - t_publish
        finally:  # one identity update for the frames applied since the last one, at most every identity_period_s
            t_identity = time.perf_counter()
            if self.schedule.identity_due(time.monotonic()):
                self.finish_frames()
        t_end = time.perf_counter()
        self.schedule.cycle_cost(len(frames), (t_end - t_cycle - publish_s) * 1e3, (t_end - t_identity) * 1e3)

    def finish_frames(self) -> None:
        """The identity update of the frames applied since the last one (MasterCore.finish_frames), its events
        logged."""
        if self.core is not None:
            self.schedule.identity_ran(time.monotonic())
            self._log_identity_events(self.core.finish_frames())

    def _publish_cycle(self, newest: float) -> None:
        """Publish the state after a cycle's frames (``newest``: the newest stamp applied), within the rate cap."""
        now = self.now_s()
        if self.schedule.may_publish(now, newest):
            self._publish(newest, now)

    def _flush(self) -> None:
        """Timer at max_publish_rate_hz: publish the state a capped cycle left unpublished."""
        now = self.now_s()
        stamp = self.schedule.due_publish(now)
        if stamp is not None:
            self._publish(stamp, now)

    def _apply(self, core: MasterCore, health: NodeHealth, record: CameraFrameRecord, now: float) -> float | None:
        """One camera frame received by ``now`` into the core; its stamp when applied, None when refused
        (counted, logged)."""
        if record.frame_id != self.values["world_frame_id"]:
            self._reject("frame_id", f"frame from {shown(record.camera_id, 64)} is in frame "
                                     f"{shown(record.frame_id, 64)}, "
                                     f"expected {self.values['world_frame_id']!r}")
            return None
        t0 = time.perf_counter()
        outcome = core.process_frame(record, now if self.values["check_stamps_against_clock"] else None,
                                     defer_identity=True)
        if not outcome.accepted:
            self._reject(outcome.code, f"frame from {shown(record.camera_id, 64)} rejected: {outcome.reason}")
            return None
        health.frame_processed((time.perf_counter() - t0) * 1e3, len(record.people),
                               sum(1 for p in record.people if p.embedding is not None))
        for notice in outcome.notices:
            self.get_logger().warning(notice[:_MAX_LOG_CHARS])
        return record.stamp_s

    def _log_identity_events(self, events: list[Any]) -> None:
        for ev in events:
            self.log(f"track {ev.track_id}: {ev.kind.value} face {ev.face_id} (p={ev.confidence:.2f})", private=True)

    def _tick(self) -> None:
        if self.core is None:
            return
        self.finish_frames()  # what waits for the identity update (frames stopped within identity_period_s)
        now = self.now_s()
        if self.values["check_stamps_against_clock"]:
            # Lag by the tracker's delay bound so that frames in flight still arrive in order.
            self.core.tick(now - float(self.values["tracker.max_detection_delay_s"]))
        self._publish(self.core.time_s, now)  # stamped with the tracker's time (now_s before any frame)

    def _publish(self, stamp_s: float, now_s: float) -> None:
        """The tracks on /tracks_named (sealed on a secured network) stamped ``stamp_s`` (the tracker's time),
        bounded by ``now_s`` and never behind the previous stamp (:class:`OutputStamps`)."""
        if self.core is None or self.tracks_pub is None:
            return
        stamp_s = self._stamps.next(stamp_s, now_s)
        tracks = self.core.tracks()
        frame_id = str(self.values["world_frame_id"])
        cdr = tracks_to_cdr(tracks, stamp_s, frame_id)  # serialized here: see track_cdr
        self.tracks_pub.publish(cdr if self._tracks_sealer is None else seal_payload(self._tracks_sealer, cdr))
        self.schedule.published()
        if self.health is not None:
            self.health.published()
        # Markers are for a person looking at RViz: building them for nobody costs the master time.
        markers = self.markers_pub is not None and self.markers_pub.get_subscription_count() > 0
        if self.people_topics is None and not markers:
            return
        stamp = set_stamp(Time(), max(0.0, stamp_s))
        if self.people_topics is not None:
            self.people_topics.publish(tracks, stamp, now_s)
        if markers:
            self.markers_pub.publish(markers_for(tracks, stamp, frame_id))

    def _reject(self, reason: str, message: str) -> None:
        total = self.health.reject(reason) if self.health is not None else 0
        self.log_throttled(reason, message, total, warn=True)

    def _log_stats(self) -> None:
        if self.core is not None:
            stats = {k: v for k, v in self.core.stats.as_dict().items() if v}
            if self.frames_dropped_overload:
                stats["frames_dropped_overload"] = self.frames_dropped_overload
            if self.health is not None:
                stats.update({f"rejected_{k}": v for k, v in sorted(self.health.rejected.items())})
            stats.update({f"{k}_refused": v for k, v in self.admin.refusals.items()})
            self.get_logger().info(f"stats: {stats}")

    def diagnostics(self, now_s: float) -> DiagnosticReport:
        core, health = self.configured_core(), self.health
        assert health is not None
        tracks = core.tracks()
        stats = core.stats.as_dict()
        extra: dict[str, object] = {
            "learned_faces": len(core.identity.face_ids()),
            "tracks": len(tracks),
            "tracks_identified": sum(1 for t in tracks if t.face_id),
            "tracks_static_clutter": core.static_clutter_tracks,
            "frames_applied": stats["frames_applied"],
            "frames_dropped_overload": self.frames_dropped_overload,
            "frames_dropped_overload_fraction": self.frames_dropped_overload / max(1, health.frames_in),
            "cycle_frame_cost_ms": self.schedule.budget.mean_cost_ms,
            "cycle_fixed_cost_ms": self.schedule.budget.mean_cycle_ms,
        }
        extra.update({k: v for k, v in stats.items() if k.startswith(("frames_rejected", "frames_future", "clock_",
                                                                       "embeddings_rejected", "faces_", "store_",
                                                                       "detections_rejected", "bodies_", "body_"))})
        extra.update({f"{k}_calls": v for k, v in self.admin.calls.items()})
        extra.update({f"{k}_refused": v for k, v in self.admin.refusals.items()}, **self.control_values())
        health.frames_dropped = stats["frames_received"] - stats["frames_applied"] + self.frames_dropped_overload
        topics, warnings = self.cameras.status()
        extra.update(topics)
        limit = float(self.values["clock_offset_warning_s"])
        off = self.receiver.clocks.beyond(limit)
        extra["cameras_clock_off"] = len(off)
        for cam, offset in list(off.items())[:5]:
            extra[f"clock_offset_ms_{shown(cam, 64)}"] = round(offset * 1e3, 1)
        if off:
            cam, offset = next(iter(off.items()))
            warnings.append(f"{len(off)} camera clock(s) off by more than {limit:g} s, e.g. {shown(cam, 64)}: frames "
                            f"arrive {offset:+.2f} s after their capture stamp (+ behind, - ahead of this host's "
                            "clock; transport included): synchronise the hosts' clocks (chrony / NTP)")
            self.log_throttled("clock_offset", warnings[-1], len(off), warn=True)
        verdict = self._health_verdict(now_s, core, health)
        extra.update(verdict.values)
        clock_errors = self._wall_steps.observe(time.time(), time.monotonic(), sum(health.rejected.values()))
        extra.update(self._wall_steps.values())
        return health.report(now_s, extra, warnings + verdict.warnings, clock_errors + verdict.errors)

    def _health_verdict(self, now_s: float, core: MasterCore, health: NodeHealth) -> Any:
        """The store's, the overload's and the domain's part of the status (face_reid_master.health)."""
        store = self.store
        # another master (or anything) publishing our output topic
        others = self._own_topic.others(self.tracks_pub.topic_name if self.tracks_pub is not None else "")
        return self._watch.verdict(
            now_s, frames_in=health.frames_in, frames_dropped_overload=self.frames_dropped_overload,
            store_write_failures=getattr(store, "write_failures", core.stats.store_errors),
            store_last_write_ok=getattr(store, "last_write_ok", None),
            store_last_error=getattr(store, "last_error", ""), faces_refused_no_id=core.stats.faces_refused_no_id,
            face_id_error=core.memory.id_error, other_publishers=others,
            output_topic=self.tracks_pub.topic_name if self.tracks_pub is not None else "/tracks_named",
            others_opened=self._own_topic.opened, others_unopened=self._own_topic.unopened)


def _gallery_people(node: MasterNode, path: str) -> dict[str, np.ndarray]:
    """The predefined people of the gallery folder ``path`` ('' = none), with a warning for skipped photos."""
    if not path:
        return {}
    from face_reid_master.storage.gallery import load_gallery

    result = load_gallery(Path(path), node.photo_embedder())
    skipped = result.skipped_summary(path)
    if skipped:
        node.log(f"gallery {path}: {skipped}", "warn", private=True)
    return dict(result.people)


# The store's worker thread takes the GIL whenever the main thread waits for DDS, and the main thread then waits up
# to Python's switch interval (5 ms by default) to get it back: cycles stretched while faces were being saved.
_GIL_SWITCH_INTERVAL_S = 0.0005


_DDS_PROFILE = Path(__file__).with_name("fastdds_master.xml")
_M_MMAP_THRESHOLD = -3  # glibc mallopt: allocations above the threshold are mmapped, and unmapped when freed
_MMAP_THRESHOLD_BYTES = 128 * 1024


def bound_dds_memory() -> None:
    """Before rclpy starts: the master's Fast DDS profile (samples freed once taken) unless the user gives one, and
    a fixed glibc mmap threshold (glibc raises it after large frees, and then keeps freed messages in its heap):
    memory that refused traffic took goes back to the system."""
    import ctypes
    import os

    if "FASTDDS_DEFAULT_PROFILES_FILE" not in os.environ and _DDS_PROFILE.is_file():
        os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(_DDS_PROFILE)
        os.environ["RMW_FASTRTPS_USE_QOS_FROM_XML"] = "1"  # rmw_fastrtps then takes the memory policy from it
    try:
        ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_BYTES)
    except (OSError, AttributeError):  # not glibc: its allocator's own policy applies
        pass


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    sys.setswitchinterval(_GIL_SWITCH_INTERVAL_S)
    bound_dds_memory()
    return run_node("face-reid-master", USAGE, master_params.TABLE, MasterNode, argv)


if __name__ == "__main__":
    sys.exit(main())
