"""face-reid-demo's summary on constructed /tracks_named messages (no DDS): which evidence re-identified each
returning person (face, body, both) and the one-line explanation of each failure, word for word."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from conftest import FACES_DIR

from face_reid_master.demo import report
from face_reid_master.demo import scenario as demo_scenario
from face_reid_master.evaluation.published_tracks import TrackMessage
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, NamedTrackRecord

# (track id, face id, name, identity evidence, face observations, state)
Row = tuple[int, int, str, str, int, int]
# what the master publishes about person p in their visit (0, 1; -1 while outside) at scene time t, age s into it
Plan = Callable[[int, int, float, float], list[Row]]


@pytest.fixture(scope="module")
def scenario() -> demo_scenario.DemoScenario:
    return demo_scenario.build_scenario(FACES_DIR, demo_scenario.DEFAULT_SEED)


def _messages(scenario: demo_scenario.DemoScenario, plan: Plan) -> list[TrackMessage]:
    """A master publishing every 0.2 s what ``plan`` says, each track at its person's true position (+5 cm), first
    seen when it was first published."""
    messages = []
    first_seen: dict[int, float] = {}
    for t in np.arange(0.0, scenario.duration_s, 0.2):
        xy, inside = scenario.true_xy(np.array([t]))
        tracks = []
        for p, person in enumerate(scenario.people):
            visit = (0 if t < person.visits[0][1] + 0.5 else 1) if inside[0, p] else -1
            since = max(0.0, person.visits[visit][0]) if visit >= 0 else t
            for tid, face, name, evidence, observations, state in plan(p, visit, float(t), float(t - since)):
                born = first_seen.setdefault(tid, float(t))
                tracks.append(NamedTrackRecord(
                    tid, face, name, 0.99 if face else 0.3, observations, xy[0, p] + 0.05, np.zeros(2), np.eye(4),
                    1.75, state, born, float(t), ("camera1",), evidence))
        messages.append(TrackMessage(float(t), tuple(tracks)))
    return messages


def _row(tid: int, face: int, age: float, name: str = "", evidence: str = "face", observations: int = 8,
         state: int = STATE_CONFIRMED) -> Row:
    """A track decided one second after it began (undecided before: no face id, name nor evidence)."""
    decided = age > 1.0
    return (tid, face if decided else 0, name if decided else "", evidence if decided else "", observations, state)


def test_published_evidence_follows_each_face_id_of_a_track() -> None:
    def msg(t: float, *tracks: tuple[int, int, str]) -> TrackMessage:
        return TrackMessage(t, tuple(NamedTrackRecord(tid, fid, "", 0.9, 0, np.zeros(2), np.zeros(2), np.eye(4), 1.7,
                                                      STATE_CONFIRMED, 0.0, t, (), ev) for tid, fid, ev in tracks))

    messages = [msg(0.0, (1, 0, ""), (2, 5, "face")), msg(0.2, (1, 3, "body"), (2, 5, "face")),
                msg(0.4, (1, 3, "both"), (2, 6, "")), msg(0.6, (1, 3, "both"))]
    # track 1: decided by body, then its face agreed; track 2: face 5, then face 6 published without evidence
    assert report.published_evidence(messages[::-1]) == {1: [(3, "body", "both")],
                                                         2: [(5, "face", "face"), (6, "face", "face")]}


def test_summary_says_which_evidence_reidentified_each_person(scenario: demo_scenario.DemoScenario) -> None:
    putin_cut_s = 5.0  # Putin's first visit is cut in two tracks (30, then 32) by the tracker

    def plan(p: int, visit: int, t: float, age: float) -> list[Row]:
        gallery = scenario.people[p].name if scenario.people[p].in_gallery else ""
        if visit < 0:
            return []
        if visit == 0:
            if p == 2:
                return [_row(30, 3, age)] if age < putin_cut_s else [_row(32, 23, age - putin_cut_s)]
            return [_row(10 * (p + 1), p + 1, age, gallery)]
        if p == 0:  # Colin Powell: his own face again, but no name
            return [_row(11, 1, age)]
        if p == 1:  # Ariel Sharon: no face seen, identified by body
            return [_row(21, 2, age, gallery, "body", observations=0)]
        if p == 2:  # Vladimir Putin: by body, then his face agreed
            return [_row(31, 3, age, evidence="body" if age < 3.0 else "both")]
        return [_row(41, 4, age)]

    summary = report.summarize(scenario, _messages(scenario, plan))
    by = {p["name"]: p["reidentified_by"] for p in summary["people"]}
    assert by == {"Colin Powell": ["face"], "Ariel Sharon": ["body"], "Vladimir Putin": ["both"],
                  "Jacques Chirac": ["face"]}
    # the run log carries what decided each assignment, so the evaluation's totals split by evidence too
    assert summary["reidentification"]["by_evidence"] == {"face": {"success": 2, "failure": 1},
                                                          "body": {"success": 2, "failure": 0}}
    assert summary["failures"] == [
        "Vladimir Putin, lost by the tracker in view and picked up again (track 32), was given a new id (face 23) "
        "although their own face (face 3) was free: their face was not matched to it",
        "Colin Powell (track 11) was never named: their face (face 1) was not matched to their gallery photos",
    ]
    text = report.format_summary(summary)
    rows = {line.split("  ")[0].strip(): line for line in text.splitlines()}
    assert rows["Colin Powell (gallery)"].endswith("  face")
    assert rows["Ariel Sharon (gallery)"].endswith("  body")
    assert rows["Vladimir Putin"].endswith("  both")
    assert text.splitlines()[-3:] == [
        "what went wrong:",
        "  - " + summary["failures"][0],
        "  - " + summary["failures"][1],
    ]


def test_each_failure_is_explained_in_one_line(scenario: demo_scenario.DemoScenario) -> None:
    putin_left_s = scenario.people[2].visits[0][1]

    def plan(p: int, visit: int, t: float, age: float) -> list[Row]:
        # Vladimir Putin's first track is never let go: still published (lost), holding his face, until the end
        held = [_row(30, 3, 9.0, state=STATE_LOST)] if p == 2 and t >= putin_left_s and visit != 0 else []
        if visit < 0:
            return held
        if visit == 0:
            name = {0: "Colin Powell", 1: "Ariel Sharon", 3: "Colin Powell"}.get(p, "")  # Chirac named Powell
            return [_row(10 * (p + 1), p + 1, age, name)]
        if p == 0:  # Colin Powell comes back faceless and is given Jacques Chirac's face by his clothes
            return [_row(11, 4, age, evidence="body", observations=0)]
        if p == 1:  # Ariel Sharon comes back and shows no face: nobody decides
            return [(21, 0, "", "", 0, STATE_CONFIRMED)]
        if p == 2:  # Vladimir Putin: a new face while his own is held
            return [_row(31, 13, age), *held]
        return [_row(41, 14, age)]  # Jacques Chirac: a new face while Colin Powell's track holds his

    messages = _messages(scenario, plan)
    summary = report.summarize(scenario, messages)
    assert summary["failures"] == [
        "Jacques Chirac (track 40) was named Colin Powell: their own face (face 4) matched Colin Powell's gallery "
        "photos",
        "Colin Powell was taken for Jacques Chirac by body evidence (track 11 got Jacques Chirac's face 4)",
        "Ariel Sharon came back (track 21) and was never re-identified nor named: no face seen and their clothes "
        "matched nobody confidently",
        "Vladimir Putin came back (track 31) and was given a new id (face 13) while their own face (face 3) was held "
        "by track 30 (their own earlier track)",
        "Jacques Chirac came back (track 41) and was given a new id (face 14) while their own face (face 4) was held "
        "by track 11 (Colin Powell's track)",
    ]
    r = summary["reidentification"]
    assert (r["success"], r["failure_wrong_person"], r["failure_new_id"], r["failure_new_id_face_busy"],
            r["none"]) == (0, 1, 2, 2, 1)
    assert all(p["reidentified_by"] == [] for p in summary["people"])
    assert "Ariel Sharon (gallery)" in report.format_summary(summary)
    # a master that does not decide by body (the threshold method): only the missing face is said
    threshold = report.summarize(scenario, messages, "threshold")
    assert threshold["failures"][2] == ("Ariel Sharon came back (track 21) and was never re-identified nor named: "
                                        "no face seen")


def test_a_perfect_run_has_nothing_to_explain(scenario: demo_scenario.DemoScenario) -> None:
    def plan(p: int, visit: int, t: float, age: float) -> list[Row]:
        person = scenario.people[p]
        return [] if visit < 0 else [_row(10 * (p + 1) + visit, p + 1, age, person.name if person.in_gallery else "")]

    summary = report.summarize(scenario, _messages(scenario, plan))
    assert summary["failures"] == []
    assert all(p["reidentified_by"] == ["face"] for p in summary["people"])
    assert report.format_summary(summary).splitlines()[-1] == "what went wrong: nothing"
