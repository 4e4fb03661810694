"""The identity layer's behaviour as scenario files (``scenarios/*.yaml``): steps of observations in, the
identity events expected out, read as a story. Each file says what it shows in its ``description``.

A step at time ``at`` (s) may show faces (``faces: {track: "alice x3"}``: three noisy face embeddings of
Alice on that track), bodies (``bodies: {track: "red x2"}``), and tell the tracker's ``lost`` / ``found`` /
``deleted`` tracks, the pairs of tracks it may have swapped (``crossed: [[1, 2, 0.4]]``: with probability
0.4), the tracks that may have taken a person they were not following (``strayed: [[1, 0.8]]``), ``forget``
face ids, or ``restart`` (the learned faces saved and loaded into a new
manager, as the face store does). ``expect`` lists the step's identity events in order as
``"<kind> track <T> face <F>"`` (``by body`` when the body decided it); none expected when left out.
``faces_of`` checks which face each track carries then (null: none), ``published`` which face a robot reads for it
(null: none, or withheld while a crossing makes it more likely wrong than right). ``manager`` in the file header
overrides the identity manager's arguments.

People's faces are points of a 128-d space ~0.99 apart (another person) with ~0.3 between two views of one
person; ``alike`` names a look-alike of Alice 0.7 from her, ``twin`` one 0.48 from her. Clothes are colours of a
4-d body space.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.likelihood import LikelihoodModel, SkewNormal

SCENARIOS = sorted((Path(__file__).parent / "scenarios").glob("*.yaml"))
DIM = 128
PEOPLE = ("alice", "bob", "carol", "dave", "erin", "frank")
COLOURS = ("red", "blue", "green", "black")
_NOISE = 0.3 / math.sqrt(2 * DIM)  # two views of one person ~0.3 apart
_BODY_LIKELIHOOD = LikelihoodModel(SkewNormal(0.0, 0.4, 0.15), SkewNormal(0.0, 1.2, 0.25))  # equal near 0.75
_ALIKE = {"alike": 0.7, "twin": 0.48}  # distance from Alice
_OBSERVED = re.compile(r"^(\w+)(?: x(\d+))?$")
_EVENT = re.compile(r"^(\w+) track (\d+) face (\d+)( by body)?$")


def _face_centre(name: str) -> np.ndarray:
    v = np.zeros(DIM, np.float32)
    if name in _ALIKE:  # near Alice: "alike" beyond the likelihood's decision distance (~0.6), "twin" within it
        theta = math.acos(1.0 - _ALIKE[name] ** 2 / (2 * 0.7**2))
        v[0], v[DIM - 1 - list(_ALIKE).index(name)] = 0.7 * math.cos(theta), 0.7 * math.sin(theta)
    else:
        v[PEOPLE.index(name)] = 0.7
    return v


def _observed(text: str) -> tuple[str, int]:
    match = _OBSERVED.match(str(text).strip())
    if match is None:
        raise ValueError(f"an observation is 'name' or 'name xN', got {text!r}")
    return match.group(1), int(match.group(2) or 1)


class ScenarioRun:
    """Plays one scenario file against a Bayesian identity manager with body evidence."""

    def __init__(self, manager_args: dict[str, Any]) -> None:
        self.args = {"feature_gate_distance": 0.75, "release_after_inconsistent": 3, "lend_lost_faces": True,
                     "learn_confidence": 0.99, **manager_args}
        self.rng = np.random.default_rng(7)
        self.manager = self._new_manager()

    def _new_manager(self) -> BayesIdentityManager:
        body = BodyEvidence(_BODY_LIKELIHOOD, window_s=100.0, min_observations=3, max_log_ratio=3.0)
        return BayesIdentityManager(embedding_dim=DIM, body_evidence=body, **self.args)

    def step(self, step: dict[str, Any]) -> list[str]:
        m, t = self.manager, float(step["at"])
        for track, seen in (step.get("faces") or {}).items():
            name, n = _observed(seen)
            m.add_observations(int(track), _face_centre(name) + self.rng.normal(0.0, _NOISE, (n, DIM)), t)
        for track, worn in (step.get("bodies") or {}).items():
            colour, n = _observed(worn)
            rows = np.repeat(np.eye(4, dtype=np.float32)[COLOURS.index(colour)][None, :], n, axis=0)
            m.add_body_observations(int(track), rows + self.rng.normal(0.0, 0.02, rows.shape).astype(np.float32), t)
        for a, b, p in step.get("crossed") or ():
            m.crossings.crossed(int(a), int(b), float(p), t)
        for a, p in step.get("strayed") or ():
            m.crossings.strayed(int(a), float(p))
        for track in step.get("lost") or ():
            m.track_lost(int(track))
        for track in step.get("found") or ():
            m.track_recovered(int(track))
        for track in step.get("deleted") or ():
            m.track_deleted(int(track), t)
        events = [f"{e.kind.value} track {e.track_id} face {e.face_id}" + (" by body" if e.evidence == "body" else "")
                  for e in m.step(t)]
        for face in step.get("forget") or ():
            assert m.forget_face(int(face)), f"face {face} to forget is not learned"
        if step.get("restart"):
            saved = m.faces.export_all()
            self.manager = self._new_manager()
            self.manager.faces.import_faces(saved)
            self.manager.faces.reserve_ids(max((f.face_id for f in saved), default=0))
        return events


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_scenario(path: Path) -> None:
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert doc.get("description"), f"{path.name}: say what the scenario shows"
    run = ScenarioRun(doc.get("manager") or {})
    for k, step in enumerate(doc["steps"]):
        expected = [str(e) for e in step.get("expect") or []]
        assert all(_EVENT.match(e) for e in expected), f"{path.name} step {k}: unreadable expectation {expected}"
        assert run.step(step) == expected, f"{path.name} step {k} (at {step['at']} s)"
        for track, face in (step.get("faces_of") or {}).items():
            assert run.manager.face_id_of(int(track)) == face, f"{path.name} step {k}: track {track}"
        for track, face in (step.get("published") or {}).items():
            withheld = run.manager.crossings.withholds(int(track))
            assert (None if withheld else run.manager.face_id_of(int(track))) == face, f"{path.name} step {k}: {track}"


def test_there_are_scenarios_for_each_behaviour() -> None:
    names = {p.stem for p in SCENARIOS}
    assert {"leave_and_return", "swap", "stranger", "look_alikes", "body_only", "second_day", "forget",
            "restart", "crossing_with_no_face_after", "person_split_over_two_faces",
            "seen_alongside_is_someone_else"} <= names
