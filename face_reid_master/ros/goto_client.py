"""Drive a running face-reid-goto from a robot application or a shell: set its target, read its status.

On a secured network (a network key) the goto takes its target only from a ``~/go_to`` request sealed with the key
for it, and publishes its status only sealed (``~/status_sealed``): :func:`send_go_to` seals the request and takes
the outcome only from the goto's reply sealed for it (a reply from a server without the key on the same name is
passed over and counted, the call waits on for the genuine one); :class:`StatusReader` opens the sealed status.
Without a key both talk to an unsecured goto's plain ``~/go_to`` and ``~/status``.

``face-reid-goto --send NAME [--key KEY] [--node /face_reid_goto]`` and ``face-reid-goto --status ...`` use them.
Exit codes: 0 accepted (a goal is out, or the target cleared) / a status read, 1 not accepted (the reason on
stderr), 2 usage error (or an unusable key file), 5 no goto answered within ``--timeout-s``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from face_reid_camera.common.ros.service_call import SealedCaller, call_service

__all__ = ["EXIT_OK", "EXIT_REFUSED", "EXIT_UNREACHABLE", "EXIT_USAGE", "STATUS_PURPOSE", "GoToReply", "StatusReader",
           "main", "send_go_to"]

PROG = "face-reid-goto"
DEFAULT_GOTO = "/face_reid_goto"
EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_UNREACHABLE = 0, 1, 2, 5
_HINT = "is face-reid-goto running on this ROS_DOMAIN_ID, and secured exactly when --key is given?"
_SEAL_AGE_S = 30.0  # a sealed reply or status stamped further than this from this host's clock is not taken
_DRAIN_S = 0.5  # --status: the newest of the lines that arrive this long after the first
STATUS_PURPOSE = "status"  # a secured goto's sealed status: not tracks, not a request or a reply


@dataclass(frozen=True)
class GoToReply:
    """What the goto answered: ``accepted`` (a goal went out, or the target was cleared) and its status line;
    ``passed_over``: unauthenticated replies ignored on the way (a server without the key on the same name)."""

    accepted: bool
    status: str
    passed_over: int = 0


def send_go_to(node: Any, name: str, key_path: str = "", goto: str = DEFAULT_GOTO,
               timeout_s: float = 20.0) -> GoToReply:
    """Ask the goto ``goto`` (its fully qualified node name) to go to ``name`` ('' stops following), with a request
    sealed with the key in ``key_path`` ('' = a plain request, for an unsecured goto). TimeoutError when no
    (genuine) reply came within ``timeout_s``; ValueError for an unusable key file."""
    from face_reid_msgs.srv import GoToPerson

    goto = "/" + goto.strip("/")
    request = GoToPerson.Request(name=name)
    if not key_path:
        reply = call_service(node, GoToPerson, f"{goto}/go_to", request, timeout_s, _HINT)
        return GoToReply(bool(reply.accepted), str(reply.status))
    from face_reid_camera.common.sealing import load_network_key

    caller = SealedCaller(node, load_network_key(key_path), PROG, _HINT)
    reply = caller.call(GoToPerson, goto, "go_to", request, timeout_s)
    return GoToReply(bool(reply.accepted), str(reply.status), caller.passed_over)


class StatusReader:
    """The goto's status lines for ``callback`` (one str each): with the key in ``key_path``, those on
    ``<goto>/status_sealed`` that open with it (sealed by the goto itself, purpose "status"; others are counted
    in :attr:`refused` by reason); without, the plain ``<goto>/status``. Latched: the current line arrives on
    subscribing (a secured goto keeps only it and re-seals it every 10 s, so it is fresh enough to open; an
    unsecured one keeps its last 10 lines)."""

    def __init__(self, node: Any, callback: Callable[[str], None], key_path: str = "",
                 goto: str = DEFAULT_GOTO) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        self.goto = "/" + goto.strip("/")
        self.refused: dict[str, int] = {}
        self._callback = callback
        self._opener: Any = None
        latched = QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        if key_path:
            from face_reid_camera.common.sealing import Opener, load_network_key
            from face_reid_msgs.msg import Sealed

            self._opener = Opener(load_network_key(key_path), STATUS_PURPOSE, _SEAL_AGE_S)
            self._sub = node.create_subscription(Sealed, f"{self.goto}/status_sealed", self._on_sealed, latched)
        else:
            from std_msgs.msg import String

            self._sub = node.create_subscription(String, f"{self.goto}/status", lambda m: callback(str(m.data)),
                                                 latched)

    def _on_sealed(self, msg: Any) -> None:
        from std_msgs.msg import String

        from face_reid_camera.common.ros.sealed import open_message
        from face_reid_camera.common.sealing import SealError

        try:
            if str(msg.sender_id) != self.goto:
                raise SealError("other_sender", "sealed by another sender than the goto")
            line = open_message(self._opener, msg, String)
        except SealError as exc:  # forged, replayed, stale (an old latched copy), another sender
            self.refused[exc.code] = self.refused.get(exc.code, 0) + 1
            return
        self._callback(str(line.data))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description="Set a running face-reid-goto's target, or read its "
                                     "status (sealed with the network key on a secured network).")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--send", metavar="NAME", help="the person to go to ('' stops following)")
    what.add_argument("--status", action="store_true", help="print the goto's current status line")
    parser.add_argument("--key", default="", help="the network key file (a secured goto takes nothing else)")
    parser.add_argument("--node", default=DEFAULT_GOTO, help="the goto's full node name (default %(default)s)")
    parser.add_argument("--timeout-s", type=float, default=20.0, help="how long to wait for the goto (s)")
    return parser


def _read_status(node: Any, key_path: str, goto: str, timeout_s: float) -> str:
    import rclpy

    lines: list[str] = []
    StatusReader(node, lines.append, key_path, goto)
    deadline = time.monotonic() + timeout_s
    while not lines:
        if time.monotonic() > deadline:
            raise TimeoutError(f"no status from {goto} within {timeout_s:g} s ({_HINT})")
        rclpy.spin_once(node, timeout_sec=0.1)
    drained = time.monotonic() + _DRAIN_S  # an unsecured goto's latched history comes oldest first
    while time.monotonic() < drained:
        rclpy.spin_once(node, timeout_sec=0.05)
    return lines[-1]


def main(argv: Sequence[str] | None = None) -> int:
    """``face-reid-goto --send NAME ...`` / ``--status ...`` (argv without the program name)."""
    import sys

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits 2 on usage errors, 0 on --help
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    import rclpy

    rclpy.init(args=[PROG])
    node = rclpy.create_node("face_reid_goto_client", start_parameter_services=False)
    goto = "/" + args.node.strip("/")
    try:
        if args.status:
            print(f"{goto}: {_read_status(node, args.key, goto, args.timeout_s)}")
            return EXIT_OK
        reply = send_go_to(node, args.send, args.key, goto, args.timeout_s)
    except ValueError as exc:  # an unusable key file
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except TimeoutError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_UNREACHABLE
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if reply.accepted:
        print(f"{goto}: {reply.status}")
        return EXIT_OK
    print(f"{PROG}: {goto}: not accepted: {reply.status}", file=sys.stderr)
    return EXIT_REFUSED
