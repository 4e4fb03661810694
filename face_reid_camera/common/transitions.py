"""The ROS lifecycle transitions an operator may ask of a face-reid node, by name, and where each leads.

Used by the nodes' sealed ``~/change_state_sealed`` service and by ``face-reid-state``: a transition that the
node's current state does not allow is refused with a message naming the ones it does. ``get`` changes
nothing (it reports the state). Pure Python, no rclpy.
"""

from __future__ import annotations

__all__ = ["QUERY", "STATES", "TRANSITIONS", "TransitionError", "allowed", "plan"]

STATES = ("unconfigured", "inactive", "active", "finalized")
QUERY = "get"
# transition -> {state it may start from: state it leads to (on success)}
TRANSITIONS: dict[str, dict[str, str]] = {
    "configure": {"unconfigured": "inactive"},
    "activate": {"inactive": "active"},
    "deactivate": {"active": "inactive"},
    "cleanup": {"inactive": "unconfigured"},
    "shutdown": {"unconfigured": "finalized", "inactive": "finalized", "active": "finalized"},
}


class TransitionError(ValueError):
    """A transition that does not exist, or that the current state does not allow."""


def allowed(state: str) -> list[str]:
    """The transitions the node may take from ``state`` (in the order of :data:`TRANSITIONS`)."""
    return [name for name, moves in TRANSITIONS.items() if state in moves]


def plan(transition: str, state: str) -> str:
    """The state ``transition`` leads to from ``state`` (``state`` itself for :data:`QUERY`); TransitionError
    with the allowed transitions when it is unknown or not allowed now."""
    name = transition.strip().lower()
    if name == QUERY:
        return state
    if name not in TRANSITIONS:
        raise TransitionError(f"unknown transition {transition[:40]!r}: one of {', '.join([*TRANSITIONS, QUERY])}")
    moves = TRANSITIONS[name]
    if state not in moves:
        can = allowed(state)
        raise TransitionError(f"cannot {name} from {state}: " + (
            f"allowed from {state}: {', '.join(can)}" if can else f"nothing is allowed from {state}"))
    return moves[state]
