"""``face-reid-state NODE TRANSITION --key PATH``: ask a face-reid node for a lifecycle transition.

A node with a network key offers only ``NODE/change_state_sealed``: the request is sealed with the key for that
node (a participant without it cannot stop or reconfigure the node, nor replay it to another), and the outcome is
taken only from the node's reply sealed for this request (a reply from a server without the key is reported as
unauthenticated and passed over). Without ``--key`` the node's standard
``NODE/change_state`` / ``NODE/get_state`` services are used (an unsecured node). TRANSITION is configure,
activate, deactivate, cleanup, shutdown (the node's process ends) or get (print the state).

Exit codes: 0 done, 1 refused (not allowed from the node's state, not sealed with its key, failed), 2 usage
error (or an unusable key file), 5 no such node answered within ``--timeout-s``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from face_reid_camera.common.ros.service_call import SealedCaller, call_service
from face_reid_camera.common.transitions import QUERY, TRANSITIONS, TransitionError, plan

__all__ = ["EXIT_OK", "EXIT_REFUSED", "EXIT_UNREACHABLE", "EXIT_USAGE", "main", "outcome_line", "unreachable_line"]

PROG = "face-reid-state"
EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_UNREACHABLE = 0, 1, 2, 5


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[1].replace("``", ""))
    parser.add_argument("node", help="the node's full name, e.g. /face_reid_master or /cam_a/face_reid_camera")
    parser.add_argument("transition", choices=[*TRANSITIONS, QUERY],
                        help="the lifecycle transition to ask for, or get (print the node's state)")
    parser.add_argument("--key", default="", help="the network key file (a secured node takes nothing else)")
    parser.add_argument("--timeout-s", type=float, default=20.0, help="how long to wait for the node (s; default 20)")
    return parser


_HINT = "is the node running on this ROS_DOMAIN_ID, and secured exactly when --key is given?"


def _call(node: Any, srv_type: Any, name: str, request: Any, timeout_s: float) -> Any:
    return call_service(node, srv_type, name, request, timeout_s, _HINT)


def _sealed(node: Any, target: str, transition: str, key_path: str, timeout_s: float) -> tuple[bool, str, str]:
    """The transition asked for with a request sealed for ``target``; the outcome from the node's sealed reply
    only (:class:`SealedCaller`)."""
    from face_reid_camera.common.sealing import load_network_key
    from face_reid_msgs.srv import ChangeState

    caller = SealedCaller(node, load_network_key(key_path), PROG, _HINT)
    reply = caller.call(ChangeState, target, "change_state_sealed", ChangeState.Request(transition=transition),
                        timeout_s)
    return bool(reply.success), str(reply.message), str(reply.state)


def _standard(node: Any, target: str, transition: str, timeout_s: float) -> tuple[bool, str, str]:
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    state = _call(node, GetState, f"{target}/get_state", GetState.Request(), timeout_s).current_state.label
    if transition == QUERY:
        return True, f"state {state}", state
    try:
        after = plan(transition, state)
    except TransitionError as exc:
        return False, f"refused: {exc}", state
    request = ChangeState.Request(transition=Transition(label=transition))  # rcl finds it by label from the state
    ok = _call(node, ChangeState, f"{target}/change_state", request, timeout_s).success
    return bool(ok), f"{transition}: {'done' if ok else 'failed (see the node log)'}", after if ok else ""


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits 2 on usage errors, 0 on --help
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    target = "/" + args.node.strip("/")
    import rclpy

    rclpy.init(args=[PROG])
    node = rclpy.create_node("face_reid_state_client", start_parameter_services=False)
    try:
        if args.key:
            ok, message, state = _sealed(node, target, args.transition, args.key, args.timeout_s)
        else:
            ok, message, state = _standard(node, target, args.transition, args.timeout_s)
    except ValueError as exc:  # an unusable key file
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except TimeoutError as exc:
        services = [name for name, _ in node.get_service_names_and_types()]
        print(unreachable_line(str(exc), target, services, bool(args.key)), file=sys.stderr)
        return EXIT_UNREACHABLE
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if ok:
        print(outcome_line(target, message, state))
        return EXIT_OK
    print(f"{PROG}: {outcome_line(target, message, state)}", file=sys.stderr)
    return EXIT_REFUSED


def unreachable_line(message: str, target: str, services: Sequence[str], keyed: bool) -> str:
    """The line for a node that did not answer: without --key, a node offering only its sealed control (seen among
    ``services``, the graph's service names) is secured: say to give --key instead of what else to check."""
    if not keyed and f"{target}/change_state_sealed" in services:
        return (f"{PROG}: {target} is secured (it offers only change_state_sealed): give --key with the network's "
                "key file")
    return f"{PROG}: {message}"


def outcome_line(target: str, message: str, state: str) -> str:
    """'/n: configure: done (state inactive)'; the state only once ('/n: state active' for get)."""
    where = f" (state {state})" if state and message != f"state {state}" else ""
    return f"{target}: {message}{where}"


if __name__ == "__main__":
    sys.exit(main())
