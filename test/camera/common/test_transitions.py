"""The lifecycle transitions an operator may ask for (face-reid-state, ~/change_state_sealed)."""

from __future__ import annotations

import pytest

from face_reid_camera.common.transitions import STATES, TRANSITIONS, TransitionError, allowed, plan


def test_each_transition_leads_where_the_ros_lifecycle_goes() -> None:
    assert plan("configure", "unconfigured") == "inactive"
    assert plan("activate", "inactive") == "active"
    assert plan("deactivate", "active") == "inactive"
    assert plan("cleanup", "inactive") == "unconfigured"
    assert [plan("shutdown", s) for s in ("unconfigured", "inactive", "active")] == ["finalized"] * 3
    assert plan(" Deactivate ", "active") == "inactive"  # as typed on a command line
    assert plan("get", "inactive") == "inactive"  # a query changes nothing


def test_what_each_state_allows() -> None:
    assert allowed("unconfigured") == ["configure", "shutdown"]
    assert allowed("inactive") == ["activate", "cleanup", "shutdown"]
    assert allowed("active") == ["deactivate", "shutdown"]
    assert allowed("finalized") == []
    assert {s for moves in TRANSITIONS.values() for s in (*moves, *moves.values())} <= set(STATES)


@pytest.mark.parametrize("transition,state,message", [
    ("activate", "active", "cannot activate from active: allowed from active: deactivate, shutdown"),
    ("cleanup", "active", "cannot cleanup from active: allowed from active: deactivate, shutdown"),
    ("configure", "finalized", "cannot configure from finalized: nothing is allowed from finalized"),
    ("shutdown", "finalized", "cannot shutdown from finalized"),
    ("reboot", "active", "unknown transition 'reboot': one of configure, activate, deactivate, cleanup, shutdown, get"),
    ("", "active", "unknown transition ''"),
])
def test_a_transition_the_state_does_not_allow_is_refused_with_what_it_allows(transition: str, state: str,
                                                                              message: str) -> None:
    with pytest.raises(TransitionError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        plan(transition, state)
