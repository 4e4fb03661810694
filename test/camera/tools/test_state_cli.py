"""face-reid-state's outcome line (pure): the state said once."""

from __future__ import annotations

from face_reid_camera.tools.state import outcome_line


def test_get_says_the_state_once_and_a_transition_says_where_it_ended() -> None:
    # before: '/face_reid_master: state active (state active)'
    assert outcome_line("/face_reid_master", "state active", "active") == "/face_reid_master: state active"
    assert outcome_line("/n", "configure: done", "inactive") == "/n: configure: done (state inactive)"
    assert outcome_line("/n", "refused: not sealed", "") == "/n: refused: not sealed"
