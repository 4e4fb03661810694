"""The master's optional robot-stack people topics: people_msgs/People on ``/people`` and the ROS4HRI REP-155
person topics (thin: messages <-> :class:`~face_reid_master.robot.people_outputs.PeopleOutputs`).

people_msgs and hri_msgs are not on PyPI: each output is published only when its message package imports (and
its type support loads); otherwise the node logs one warning and carries on without it.
"""

from __future__ import annotations

import importlib
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from face_reid_camera.common.param_table import config_from_values
from face_reid_master.records import NamedTrackRecord
from face_reid_master.robot.people_outputs import HriUpdate, PeopleOutputConfig, PeopleOutputs, PersonOut

HRI_PREFIX = "/humans/persons"
# REP-155: the per-person sub-topics are latched (a late subscriber gets the current value)
_LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


class PeopleTopics:
    """Made on configure (parameters checked, world->map file read, message packages looked for), publishers made
    on :meth:`activate` and dropped on :meth:`deactivate`; :meth:`publish` runs with every /tracks_named."""

    def __init__(self, node: Any, values: dict[str, Any]) -> None:
        self.node = node
        self.config: PeopleOutputConfig = config_from_values(PeopleOutputConfig, values)
        self.outputs = PeopleOutputs(self.config)
        self.world_frame_id = str(values.get("world_frame_id", "world"))
        self.warnings: list[str] = []
        self._people_msgs = self._messages("publish_people", "people_msgs", "/people") \
            if self.config.publish_people else None
        self._hri_msgs = self._messages("publish_hri", "hri_msgs", "the REP-155 person topics") \
            if self.config.publish_hri else None
        self._std_msgs: Any = None
        self.people_pub: Any = None
        self.tracked_pub: Any = None
        self.known_pub: Any = None
        self._person_pubs: dict[str, dict[str, Any]] = {}  # person id -> sub-topic -> publisher
        self._sent: dict[str, dict[str, Any]] = {}  # person id -> sub-topic -> last value published (latched)
        self._known: tuple[str, ...] | None = None

    def _warn(self, message: str) -> None:
        self.warnings.append(message)
        self.node.get_logger().warning(message)

    def _messages(self, parameter: str, package: str, what: str) -> Any:
        """``package.msg``, or None with one warning when it is not installed."""
        try:
            return importlib.import_module(f"{package}.msg")
        except ImportError as exc:
            self._warn(f"{parameter} is set but {package} is not installed: {what} not published ({exc})")
            return None

    # ------------------------------------------------------------------ lifecycle
    def activate(self) -> None:
        """Make the publishers of the outputs that are on (an output whose type support fails is turned off)."""
        node = self.node
        if self._people_msgs is not None:
            try:
                self.people_pub = node.create_publisher(self._people_msgs.People, self.config.people_topic, 10)
            except Exception as exc:  # the package imports but its type support does not load
                self._warn(f"publish_people is set but people_msgs cannot be used: /people not published ({exc})")
                self._people_msgs = None
        if self._hri_msgs is not None:
            try:
                self._std_msgs = importlib.import_module("std_msgs.msg")
                self.tracked_pub = node.create_publisher(self._hri_msgs.IdsList, f"{HRI_PREFIX}/tracked", 10)
                self.known_pub = node.create_publisher(self._hri_msgs.IdsList, f"{HRI_PREFIX}/known", _LATCHED)
            except Exception as exc:
                self._warn(f"publish_hri is set but hri_msgs cannot be used: REP-155 topics not published ({exc})")
                self._hri_msgs = None
        if self.people_pub is not None:
            node.get_logger().info(f"publishing people_msgs/People on {self.people_pub.topic_name} "
                                   f"(frame {self.outputs.frame_id(self.world_frame_id)})")
        if self.tracked_pub is not None:
            node.get_logger().info(f"publishing REP-155 persons under {HRI_PREFIX}/")

    def deactivate(self) -> None:
        for pub in (self.people_pub, self.tracked_pub, self.known_pub):
            if pub is not None:
                self.node.destroy_publisher(pub)
        for person_id in list(self._person_pubs):
            self._drop_person(person_id)
        self.people_pub = self.tracked_pub = self.known_pub = None
        self._known = None

    # ------------------------------------------------------------------ publishing
    def publish(self, tracks: list[NamedTrackRecord], stamp_msg: Any, now_s: float) -> None:
        """/people and the REP-155 topics for the tracks just published on /tracks_named (never raises: a failure
        is logged, throttled)."""
        if self.people_pub is None and self.tracked_pub is None:
            return
        try:
            people = self.outputs.people(tracks)
            if self.people_pub is not None:
                self.people_pub.publish(self._people_msg(people, stamp_msg))
            if self.tracked_pub is not None:
                self._publish_hri(self.outputs.hri(people, now_s), stamp_msg)
        except Exception as exc:  # an output must never take the master down
            self.node.log_throttled("people_topics", f"people topics failed: {type(exc).__name__}: {exc}", warn=True)

    def _people_msg(self, people: list[PersonOut], stamp_msg: Any) -> Any:
        m = self._people_msgs
        msg = m.People()
        msg.header.stamp = stamp_msg
        msg.header.frame_id = self.outputs.frame_id(self.world_frame_id)
        for p in people:
            person = m.Person()
            person.name = p.name
            person.position.x, person.position.y, person.position.z = p.position_xyz_m
            person.velocity.x, person.velocity.y, person.velocity.z = p.velocity_xyz_mps
            person.reliability = float(p.reliability)
            person.tagnames, person.tags = list(p.tagnames), list(p.tags)
            msg.people.append(person)
        return msg

    def _publish_hri(self, update: HriUpdate, stamp_msg: Any) -> None:
        ids = self._hri_msgs.IdsList()
        ids.header.stamp = stamp_msg
        ids.ids = list(update.tracked)
        self.tracked_pub.publish(ids)
        std = self._std_msgs
        for person_id in update.removed:
            self._drop_person(person_id)
        for p in update.persons:
            self._latch(p.person_id, "anonymous", std.Bool, p.anonymous)
            if p.face_id:
                self._latch(p.person_id, "face_id", std.String, p.face_id)
            if p.name:
                self._latch(p.person_id, "name", std.String, p.name)
            self._latch(p.person_id, "location_confidence", std.Float32, float(p.location_confidence))
        for old, new in update.aliases.items():
            if old in update.removed:  # hri_forget_after_s 0: its topics are gone already
                continue
            self._latch(old, "alias", std.String, new)
            self._latch(old, "location_confidence", std.Float32, 0.0)  # it is now tracked as the other person
        known = self.outputs.hri_known
        if known != self._known:
            msg = self._hri_msgs.IdsList()
            msg.header.stamp = stamp_msg
            msg.ids = list(known)
            self.known_pub.publish(msg)
            self._known = known

    def _latch(self, person_id: str, sub_topic: str, msg_type: Any, value: Any) -> None:
        """Publish ``value`` on ``/humans/persons/<id>/<sub_topic>`` when it changed (publisher made on first use)."""
        sent = self._sent.setdefault(person_id, {})
        if sub_topic in sent and sent[sub_topic] == value:
            return
        pubs = self._person_pubs.setdefault(person_id, {})
        if sub_topic not in pubs:
            pubs[sub_topic] = self.node.create_publisher(msg_type, f"{HRI_PREFIX}/{person_id}/{sub_topic}", _LATCHED)
        pubs[sub_topic].publish(msg_type(data=value))
        sent[sub_topic] = value

    def _drop_person(self, person_id: str) -> None:
        for pub in self._person_pubs.pop(person_id, {}).values():
            self.node.destroy_publisher(pub)
        self._sent.pop(person_id, None)

    @property
    def person_topics(self) -> int:
        """How many per-person publishers exist (bounded by hri_max_persons x 5)."""
        return sum(len(p) for p in self._person_pubs.values())
