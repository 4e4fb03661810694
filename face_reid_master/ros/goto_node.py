"""face-reid-goto: send a robot to a named person (thin: messages <-> :class:`StandoffGoal`).

Subscribes /tracks_named (sealed with the network key when ``network_key_path`` is set:
:mod:`face_reid_master.ros.tracks_in`); the target comes from the command line (``face-reid-goto NAME``), the
``target_name`` parameter, the ``~/go_to`` service (face_reid_msgs/GoToPerson) or the ``~/target`` topic
(std_msgs/String).
Publishes geometry_msgs/PoseStamped goals on /goal_pose (what nav2's navigator takes) in the robot's map frame,
and one line per goal or refusal on ``~/status`` (std_msgs/String). Known names also come from the master's
``~/list_faces``, so that a learned person who is away is "not tracked" rather than "unknown name". A refusal
does not cancel a goal the navigator already has (a nav2 action cancel is the robot application's call).

Secured (a network key): only a holder of the key may set the target, and the target's name goes out only sealed.
No ``~/target`` topic (a String cannot carry a seal); ``~/go_to`` does only a request sealed with the key for this
node (others are refused, plainly, and counted: ``go_to_refused``) and answers it sealed; the status goes out
sealed on ``~/status_sealed`` (face_reid_msgs/Sealed, purpose "status", sender this node's name; re-sealed every
``_STATUS_RESEAL_S`` so that a late reader finds a fresh one) and nothing on ``~/status``. The goals stay plain: the
navigation stack takes a PoseStamped (a position, no name). Clients: :mod:`face_reid_master.ros.goto_client`.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any

from geometry_msgs.msg import PoseStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from face_reid_camera.common.checks import shown
from face_reid_camera.common.diagnostics import DiagnosticLevel, DiagnosticReport
from face_reid_camera.common.param_table import ParamSpec, ParamTable, config_from_values, config_specs
from face_reid_camera.common.ros.lifecycle import ManagedNode, run_node
from face_reid_camera.common.sealing import Sealer, SealError, load_network_key
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, STATE_TENTATIVE, NamedTrackRecord
from face_reid_master.robot.frames import PlanarTransform, load_world_to_map
from face_reid_master.robot.standoff_goal import (
    Decision,
    DecisionKind,
    StandoffGoal,
    StandoffGoalConfig,
)
from face_reid_master.ros.convert import track_from_msg
from face_reid_master.ros.goto_client import STATUS_PURPOSE
from face_reid_master.ros.tracks_in import TracksSubscription
from face_reid_msgs.msg import Sealed as SealedMsg
from face_reid_msgs.srv import GoToPerson, ListFaces

NODE_NAME = "face_reid_goto"
USAGE = """usage: face-reid-goto [NAME] [--ros-args -p world_to_map_path:=world_to_map.yaml -p name:=value ...]

       face-reid-goto --send NAME [--key KEY] [--node /face_reid_goto]   (a running goto's ~/go_to)
       face-reid-goto --status [--key KEY] [--node /face_reid_goto]      (its current status line)

Sends the robot to the named person: goals (geometry_msgs/PoseStamped, map frame) on /goal_pose, a stand-off
distance in front of the person and facing them, re-issued as they move; one status line per goal or refusal
on ~/status. NAME (or the target_name parameter, the ~/go_to service, the ~/target topic) picks the person.
With network_key_path: no ~/target topic, ~/go_to takes only requests sealed with the key (--send ... --key),
and the status is sealed on ~/status_sealed (--status --key reads it).
Parameters (`ros2 param describe` lists them):
"""

_NODE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("autostart", True, "Configure and activate at start (false: wait for a lifecycle manager).",
              read_only=True),
    ParamSpec("target_name", "", "Person to go to from the start ('' = nobody; NAME on the command line wins)."),
    ParamSpec("tracks_topic", "/tracks_named", "The master's face_reid_msgs/NamedTrackArray."),
    ParamSpec("network_key_path", "",
              "The camera network's key file: only tracks sealed with it (on <tracks_topic>_sealed, what a secured "
              "master publishes) are taken, the target only from a ~/go_to request sealed with it (no ~/target "
              "topic: face-reid-goto --send NAME --key KEY), the status is published sealed (~/status_sealed), and "
              "the node offers no lifecycle or parameter services (transitions through ~/change_state_sealed: "
              "face-reid-state) ('' = unsecured: plain tracks, which any participant could forge, a target anyone "
              "can set, a status anyone can read, and the standard services, open to the DDS domain).",
              read_only=True),
    ParamSpec("goal_topic", "/goal_pose", "Where the goals (geometry_msgs/PoseStamped, map frame) are published."),
    ParamSpec("world_to_map_path", "",
              "The world -> map transform file of face-reid-align-map ('' = none: the map frame is the world "
              "frame).", read_only=True),
    ParamSpec("map_frame_id", "",
              "frame_id of the goals ('' = the transform file's map_frame; without a file: 'map')."),
    ParamSpec("robot_pose_topic", "",
              "The robot's geometry_msgs/PoseStamped in the map frame: a standing person is faced from the robot's "
              "side ('' = none: their last heading)."),
    ParamSpec("names_service", "/face_reid_master/list_faces",
              "The master's face_reid_msgs/ListFaces: its learned names are known names ('' = only the names seen "
              "on /tracks_named)."),
    ParamSpec("names_refresh_period_s", 10.0, "How often the known names are asked for again (s).",
              low=0.5, high=86400.0),
    ParamSpec("no_tracks_warning_s", 5.0, "/diagnostics warns when no /tracks_named arrived for this long (s).",
              low=0.1, high=3600.0),
)

TABLE = ParamTable(NODE_NAME, (*_NODE_PARAMS, *config_specs(StandoffGoalConfig)),
                   "the go-to-a-named-person node (face-reid-goto)", "face-reid-goto NAME --ros-args "
                   "--params-file config/goto.yaml")

_MAX_STATUS_CHARS = 400
_NAMES_REPLY_AGE_S = 30.0  # a sealed names reply stamped further than this from this host's clock is not taken
_STATUS_RESEAL_S = 10.0  # a secured goto seals its (latched) status again this often: a late reader gets a fresh one


def tracks_from_msg(msg: Any) -> tuple[list[NamedTrackRecord], int]:
    """The tracks of a NamedTrackArray as records, and how many were malformed (skipped; e.g. an unknown state)."""
    out, bad = [], 0
    for t in msg.tracks:
        try:
            record = track_from_msg(t)
        except (ValueError, TypeError, AttributeError):
            bad += 1
            continue
        if record.state in (STATE_TENTATIVE, STATE_CONFIRMED, STATE_LOST):
            out.append(record)
        else:
            bad += 1
    return out, bad


class GotoNode(ManagedNode):
    """The face-reid-goto node; see the module docstring."""

    def __init__(self, target: str | None = None, **kwargs: Any) -> None:
        super().__init__(TABLE, **kwargs)
        self._cli_target = target
        self.values: dict[str, Any] = {}
        self.core: StandoffGoal | None = None
        self.map_frame = "map"
        self.world_frame = ""  # expected frame of the tracks ('' = not checked: no transform file)
        self._tracks: list[NamedTrackRecord] = []
        self._robot_xy: tuple[float, float] | None = None
        self._last_status = ""
        self._last_tracks_s: float | None = None
        self._started_s = 0.0
        self._names_future: Any = None
        self._names_asked_s = -math.inf
        self._names_loaded = False
        self.counts = {"tracks_msgs": 0, "goals": 0, "refusals": 0, "requests": 0, "go_to_refused": 0}
        self.rejected: dict[str, int] = {}
        self._subs: list[Any] = []
        self._tracks_sub: TracksSubscription | None = None
        self._own_timers: list[Any] = []
        self._service: Any = None
        self.goal_pub: Any = None
        self.status_pub: Any = None
        self._names_client: Any = None
        self._names_master = ""  # the master's full name: what a sealed names request is for
        self._names_sealer: Any = None  # with a network key: names requests sealed, replies opened
        self._names_opener: Any = None
        self._names_request: Any = None  # the request of the call in flight (its reply is sealed for it)
        self._status_sealer: Sealer | None = None  # with a network key: the status goes out sealed
        self._status_sealed_s = -math.inf  # when the status was last sealed (monotonic)
        self._said_secured = False

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        values = self.parameter_values()
        transform, world, mapf = PlanarTransform.identity(), "", "map"
        if values["world_to_map_path"]:
            transform, world, mapf = load_world_to_map(str(values["world_to_map_path"]))
        self.world_frame = world
        self.map_frame = str(values["map_frame_id"]) or mapf
        self.core = StandoffGoal(config_from_values(StandoffGoalConfig, values), transform)
        target = self._cli_target if self._cli_target is not None else str(values["target_name"])
        self.core.set_target(target)  # a bad name fails the start with its reason
        self._status_sealer = None
        if values["network_key_path"]:  # a missing or unsafe key file fails the start
            key = load_network_key(str(values["network_key_path"]))
            self._status_sealer = Sealer(key, self.get_fully_qualified_name(), STATUS_PURPOSE)
        self.values = values
        self.log(f"goto: target {shown(self.core.target, 64) if self.core.target else '(none)'}, goals in frame "
                 f"{self.map_frame!r} (world->map x={transform.x_m:g} y={transform.y_m:g} "
                 f"yaw={math.degrees(transform.yaw_rad):g} deg), standoff {self.core.config.standoff_distance_m:g} m",
                 private=True)  # the target's name

    def activate(self) -> None:
        values = self.values
        reliable = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.goal_pub = self.create_publisher(PoseStamped, str(values["goal_topic"]), reliable)
        secured = self._status_sealer is not None
        # sealed: only the current line is kept for a late reader (older seals would not open: too old)
        current = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.status_pub = (self.create_publisher(SealedMsg, "~/status_sealed", current) if secured else
                           self.create_publisher(String, "~/status", latched))
        self._tracks_sub = TracksSubscription(self, self._on_tracks, str(values["tracks_topic"]),
                                              str(values["network_key_path"]), reliable,
                                              on_refused=lambda reason, message: self._reject(f"tracks_{reason}",
                                                                                              message))
        if secured:  # a String cannot carry a seal: the target only through the sealed ~/go_to
            self._subs = []
            self._service = self.create_service(GoToPerson, "~/go_to", self._on_go_to_sealed)
            self._own_timers.append(self.create_steady_timer(_STATUS_RESEAL_S, self._reseal_status))
            self._say_secured()
        else:
            self._subs = [self.create_subscription(String, "~/target", self._on_target, reliable)]
            self._service = self.create_service(GoToPerson, "~/go_to", self._on_go_to)
        if values["robot_pose_topic"]:
            self._subs.append(self.create_subscription(PoseStamped, str(values["robot_pose_topic"]),
                                                       self._on_robot_pose, reliable))
        if values["names_service"]:
            self._names_client = self.create_client(ListFaces, str(values["names_service"]))
            self._seal_names(str(values["names_service"]), str(values["network_key_path"]))
            self._own_timers.append(self.create_steady_timer(1.0, self._ask_names))
        self._started_s = self.now_s()
        self._decide(self.now_s(), announce=True)

    def deactivate(self) -> None:
        if self._tracks_sub is not None:
            self._tracks_sub.destroy()
            self._tracks_sub = None
        for sub in self._subs:
            self.destroy_subscription(sub)
        for timer in self._own_timers:
            self.destroy_timer(timer)
        if self._service is not None:
            self.destroy_service(self._service)
        self._subs, self._own_timers, self._service = [], [], None
        if self._names_client is not None:
            self.destroy_client(self._names_client)
            self._names_client = None
        for pub in (self.goal_pub, self.status_pub):
            if pub is not None:
                self.destroy_publisher(pub)
        self.goal_pub = self.status_pub = None

    def cleanup(self) -> None:
        self.core = None

    # ------------------------------------------------------------------ inputs
    def _on_tracks(self, msg: Any) -> None:
        self.counts["tracks_msgs"] += 1
        self._last_tracks_s = self.now_s()
        frame = str(msg.header.frame_id)
        if self.world_frame and frame != self.world_frame:
            self._reject("frame_id", f"/tracks_named in frame {shown(frame, 64)}, the transform file is from "
                                     f"{self.world_frame!r}: ignored")
            return
        tracks, bad = tracks_from_msg(msg)
        if bad:
            self._reject("malformed_track", f"{bad} malformed track(s) in /tracks_named skipped", bad)
        self._tracks = tracks
        self._decide(self.now_s())

    def _on_robot_pose(self, msg: Any) -> None:
        x, y = float(msg.pose.position.x), float(msg.pose.position.y)
        if msg.header.frame_id != self.map_frame or not (math.isfinite(x) and math.isfinite(y)):
            self._reject("robot_pose", f"robot pose in frame {shown(msg.header.frame_id, 64)} at ({x}, {y}): "
                                       f"expected finite numbers in {self.map_frame!r}; ignored")
            return
        self._robot_xy = (x, y)

    def _on_target(self, msg: Any) -> None:
        self._request(str(msg.data))

    def _on_go_to(self, request: Any, response: Any) -> Any:
        decision = self._request(str(request.name))
        response.accepted = decision is not None and decision.kind in (DecisionKind.GOAL, DecisionKind.IDLE)
        response.status = self._last_status if self.core is not None else "not active"
        return response

    def _on_go_to_sealed(self, request: Any, response: Any) -> Any:
        """A secured goto's ~/go_to: only a request sealed with the network key for this node is done, and its
        reply is sealed for it; any other is refused with the reason (plain: nothing else) and counted."""
        from face_reid_camera.common.ros.sealed import open_request, reply_is_sealed, seal_response

        fqn, error = self.get_fully_qualified_name(), None
        try:
            inner = open_request(self._control_opener, request, fqn, time.time())
        except SealError as exc:
            error = exc
            self.counts["requests"] += 1
            self.counts["go_to_refused"] += 1
            response.accepted, response.status = False, f"refused: {exc}"
            self.log_throttled("go_to_refused", f"go_to: {response.status}", self.counts["go_to_refused"], warn=True)
        else:
            self._on_go_to(inner, response)
        if not reply_is_sealed(error):  # not a key holder's fresh request to this node: why, and nothing else
            return response
        return seal_response(self._control_sealer, response, fqn, request)

    def _say_secured(self) -> None:
        """Once per process: what a secured goto takes and publishes, and what stays plain."""
        if self._said_secured:
            return
        self._said_secured = True
        self.get_logger().info(
            f"secured: no {self.resolve_topic_name('~/target')} topic (a std_msgs/String cannot carry a seal): the "
            f"target is set only through {self.resolve_service_name('~/go_to')} with a request sealed with the "
            "network key for this node (face-reid-goto --send NAME --key KEY), replies sealed; the status is "
            f"published sealed on {self.resolve_topic_name('~/status_sealed')}; the goals on "
            f"{self.values['goal_topic']} stay plain (the navigation stack's PoseStamped: a position, no name)")

    def _request(self, name: str) -> Decision | None:
        """A new target from the service or the topic: the decision for it at once (None: the name is refused)."""
        self.counts["requests"] += 1
        if self.core is None:
            return None
        try:
            self.core.set_target(name)
        except ValueError as exc:
            self.counts["refusals"] += 1
            self._status(f"refused: invalid name: {exc}", force=True)
            self.log_throttled("invalid_name", f"target refused: {exc}", self.counts["refusals"], warn=True,
                               private=True)  # the reason quotes the name
            return None
        return self._decide(self.now_s(), announce=True)

    # ------------------------------------------------------------------ the decision
    def _decide(self, now_s: float, announce: bool = False) -> Decision | None:
        if self.core is None or self.goal_pub is None:
            return None
        decision = self.core.update(self._tracks, self._robot_xy, now_s)
        if decision.kind == DecisionKind.REFUSED and not self.counts["tracks_msgs"] and not self._names_loaded:
            # nothing heard from the master yet: no name can be known, so this is no refusal
            self._status(f"waiting for {self.values['tracks_topic']}: nothing received yet (target "
                         f"{shown(self.core.target, 64)})", force=announce)
            return decision
        if decision.kind == DecisionKind.GOAL and decision.goal is not None:
            self.goal_pub.publish(self._pose(decision))
            self.counts["goals"] += 1
        elif decision.kind == DecisionKind.REFUSED and (announce or decision.status_line() != self._last_status):
            self.counts["refusals"] += 1
        if decision.kind == DecisionKind.IDLE:
            self._status(self._waiting_line(), force=announce)
        elif decision.kind != DecisionKind.UNCHANGED:
            self._status(decision.status_line(), force=announce)
        return decision

    def _waiting_line(self) -> str:
        """The status without a target: no goals, and where a name is taken from (logged once when it starts so)."""
        go_to, topic = self.resolve_service_name("~/go_to"), self.resolve_topic_name("~/target")
        if self._status_sealer is not None:
            return (f"no target: no goals; waiting for a name on the {go_to} service (face_reid_msgs/srv/GoToPerson, "
                    "sealed with the network key: face-reid-goto --send NAME --key KEY), or start with "
                    "face-reid-goto NAME")
        return (f"no target: no goals; waiting for a name on the {go_to} service (face_reid_msgs/srv/GoToPerson) or "
                f"the {topic} topic (std_msgs/msg/String), or start with face-reid-goto NAME")

    def _pose(self, decision: Decision) -> PoseStamped:
        goal = decision.goal
        assert goal is not None
        msg = PoseStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.map_frame
        msg.pose.position.x, msg.pose.position.y = goal.x_m, goal.y_m
        msg.pose.orientation.z, msg.pose.orientation.w = math.sin(goal.yaw_rad / 2), math.cos(goal.yaw_rad / 2)
        return msg

    def _status(self, line: str, force: bool = False) -> None:
        """One status line, published when it differs from the last one (or always, for a request)."""
        line = line[:_MAX_STATUS_CHARS]
        if (line == self._last_status and not force) or self.status_pub is None:
            return
        self._last_status = line
        self._publish_status(line)
        self.log_throttled("status", line, level="info", every_s=1.0, private=True)  # names the target

    def _publish_status(self, line: str) -> None:
        if self._status_sealer is None:
            self.status_pub.publish(String(data=line))
            return
        from face_reid_camera.common.ros.sealed import seal_message

        self.status_pub.publish(seal_message(self._status_sealer, String(data=line)))
        self._status_sealed_s = time.monotonic()

    def _reseal_status(self) -> None:
        """The latched sealed status sealed again when it is getting old: a reader opens only recent seals."""
        if self.status_pub is not None and self._last_status and (
                time.monotonic() - self._status_sealed_s >= _STATUS_RESEAL_S / 2):
            self._publish_status(self._last_status)

    # ------------------------------------------------------------------ known names
    def _seal_names(self, service: str, key_path: str) -> None:
        """With a network key, names requests are sealed for the master that offers ``service`` (a secured master
        answers nothing else) and only its reply sealed for the request is taken."""
        from face_reid_camera.common.sealing import Opener, Sealer

        self._names_master = self.resolve_service_name(service).rsplit("/", 1)[0] or "/"
        self._names_sealer = self._names_opener = None
        if key_path:
            key = load_network_key(key_path)
            self._names_sealer = Sealer(key, self.get_fully_qualified_name(), "requests")
            self._names_opener = Opener(key, "replies", _NAMES_REPLY_AGE_S)

    def _ask_names(self) -> None:
        """Ask the master for its learned names (every names_refresh_period_s; every second until it answers)."""
        client, now = self._names_client, self.now_s()
        if client is None or self._names_future is not None or not client.service_is_ready():
            return
        period = float(self.values["names_refresh_period_s"]) if self._names_loaded else 1.0
        if now - self._names_asked_s < period:
            return
        self._names_asked_s = now
        request = ListFaces.Request()
        if self._names_sealer is not None:
            from face_reid_camera.common.ros.sealed import seal_request

            request = seal_request(self._names_sealer, request, self._names_master)
        self._names_request = request
        self._names_future = client.call_async(request)
        self._names_future.add_done_callback(self._on_names)

    def _on_names(self, future: Any) -> None:
        self._names_future = None
        try:
            reply = future.result()
        except Exception as exc:  # the master went away mid-call: asked again later
            self.log_throttled("names", f"{self.values['names_service']}: {type(exc).__name__}: {exc}", warn=True)
            return
        if self._names_opener is not None:
            from face_reid_camera.common.ros.sealed import open_response
            from face_reid_camera.common.sealing import SealError

            try:
                reply = open_response(self._names_opener, reply, self._names_master, self._names_request)
            except SealError as exc:  # e.g. a server without the key answered first: asked again later
                self._reject(f"names_{exc.code}", f"{self.values['names_service']}: unauthenticated reply from a "
                                                  f"server without the key ({exc}): ignored")
                return
        names = list(reply.names)
        if self.core is not None:
            self.core.add_known_names(names)
            self._names_loaded = True

    # ------------------------------------------------------------------ health
    def _reject(self, reason: str, message: str, count: int = 1) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + count
        self.log_throttled(reason, message, self.rejected[reason], warn=True)

    def diagnostics(self, now_s: float) -> DiagnosticReport:
        warnings = []
        since = self._last_tracks_s if self._last_tracks_s is not None else self._started_s
        if now_s - since > float(self.values["no_tracks_warning_s"]):
            warnings.append(f"no /tracks_named for {now_s - since:.1f} s")
        network = self._tracks_sub.network if self._tracks_sub is not None else None
        if network is not None and network.problem:
            warnings.append(network.problem)
        core = self.core
        values: dict[str, str] = {k: str(v) for k, v in self.counts.items()}
        values.update({f"rejected_{k}": str(v) for k, v in sorted(self.rejected.items())})
        if self._status_sealer is None:  # secured: the target's name and goals only sealed (~/status_sealed)
            values["target"] = shown(core.target, 64) if core is not None else ""
            values["status"] = self._last_status
        values["tracks_skipped_not_finite"] = str(core.tracks_skipped_not_finite if core is not None else 0)
        values.update({k: str(v) for k, v in self.control_values().items()})  # ~/change_state_sealed
        return DiagnosticReport(self.get_name(), self.get_fully_qualified_name(),
                                DiagnosticLevel.WARN if warnings else DiagnosticLevel.OK,
                                "; ".join(warnings) or "ok", values)


def target_from_args(argv: list[str]) -> str | None:
    """NAME from ``face-reid-goto NAME [--ros-args ...]`` (words before --ros-args joined), None when absent."""
    end = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    words = [a for a in argv[1:end] if not a.startswith("-")]
    return " ".join(words) if words else None


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point."""
    args = list(sys.argv if argv is None else argv)
    if {"--send", "--status"} & set(args[1:]):  # a client of a running goto, not the node
        from face_reid_master.ros.goto_client import main as client_main

        return client_main(args[1:])
    target = target_from_args(args)
    return run_node("face-reid-goto", USAGE, TABLE, lambda: GotoNode(target), args)


if __name__ == "__main__":
    sys.exit(main())
