"""What the master published during a demo run, judged against the scripted scene: the live table and the
end-of-run summary (metrics of :mod:`face_reid_master.evaluation.metrics`): per person what re-identified them
(``NamedTrack.identity_evidence``: face, body or both) and one plain line per failure, saying what happened."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from face_reid_master.demo.scenario import DemoPerson, DemoScenario
from face_reid_master.evaluation.metrics import (
    TrackOutcome,
    evaluate_run,
    evaluated_tracks,
    face_persons,
    holding_intervals,
    track_outcomes,
)
from face_reid_master.evaluation.published_tracks import TrackMessage, nearest_person, run_log_from_messages
from face_reid_master.evaluation.runner import RunLog
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, NamedTrackRecord
from face_reid_master.sim.visibility import count_losses

__all__ = ["build_run_log", "explain_failures", "format_summary", "format_table", "published_evidence", "summarize"]

# what identified a track, as the summary says it ("by ...")
EVIDENCE_WORDS = {"face": "their face", "body": "body evidence", "both": "body evidence, then their face"}


def published_evidence(messages: Sequence[TrackMessage]) -> dict[int, list[tuple[int, str, str]]]:
    """Per track, each face id it was published with, in order (as
    :func:`~face_reid_master.evaluation.published_tracks.run_log_from_messages` lists its assignments): (face id,
    what decided it: "face" | "body", what it was last published with while holding that face: "face" | "body" |
    "both", i.e. a body decision its own face then confirmed). Evidence a master did not publish counts as face."""
    out: dict[int, list[tuple[int, str, str]]] = {}
    current: dict[int, int] = {}
    for msg in sorted(messages, key=lambda m: m.stamp_s):
        present = set()
        for tr in msg.tracks:
            tid, fid = int(tr.track_id), int(tr.face_id)
            present.add(tid)
            evidence = tr.identity_evidence if tr.identity_evidence in EVIDENCE_WORDS else "face"
            if fid and current.get(tid) != fid:
                out.setdefault(tid, []).append((fid, "body" if evidence == "both" else evidence, evidence))
            elif fid:
                face, decided, _ = out[tid][-1]
                out[tid][-1] = (face, decided, evidence)
            current[tid] = fid
        for tid in [t for t in current if t not in present]:
            del current[tid]
    return out


def build_run_log(scenario: DemoScenario, messages: Sequence[TrackMessage], method: str = "bayes") -> RunLog:
    """A :class:`~face_reid_master.evaluation.runner.RunLog` from the published tracks (each confirmed track
    attributed to the nearest true person: see
    :func:`~face_reid_master.evaluation.published_tracks.run_log_from_messages`), each assignment with the evidence
    that decided it (face or body, :func:`published_evidence`)."""
    log = run_log_from_messages(messages, scenario.true_xy, len(scenario.people),
                                ((1, 0.0, scenario.duration_s, tuple(p.gt_id for p in scenario.people)),), method)
    for tid, given in published_evidence(messages).items():
        log.tracks[tid].evidence = [decided for _, decided, _ in given]
    return log


def _visit_of(person: DemoPerson, t_s: float) -> int:
    """Which of the person's visits (0, 1, ...) scene time ``t_s`` falls in (the tracks start after the door)."""
    return max(0, sum(enter <= t_s + 0.5 for enter, _ in person.visits) - 1)


def _faces(ids: Sequence[int]) -> str:
    return f"face {ids[0]}" if len(ids) == 1 else "faces " + ", ".join(str(f) for f in ids)


def explain_failures(scenario: DemoScenario, log: RunLog, outcomes: Sequence[TrackOutcome],
                     evidence: dict[int, list[tuple[int, str, str]]], body_identity: bool = True) -> list[str]:
    """One plain line per failure, in the order the tracks began, from what the demo saw: a returning person
    given another person's face or a new id (and whether their own face was then held by another track, and
    by whose), never re-identified (no face seen, or seen without a decision), a predefined person never named
    or anybody named wrongly. ``body_identity``: the master decides faceless tracks by their bodies (the
    bayes method's default), so an unidentified faceless track also means that its clothes matched nobody."""
    people = scenario.people
    face_person = face_persons(log)
    held = holding_intervals(log)  # face id -> (from, until, track) holding intervals

    def own_faces(p: int, before: float) -> list[int]:
        return sorted(f for f, (s, _) in log.faces.items() if face_person[f] == p and s < before)

    def holders(faces: Sequence[int], at: float, track_id: int) -> list[int]:
        """The other tracks holding each of ``faces`` at ``at`` ([] unless every one of them is held)."""
        out = []
        for f in faces:
            tid = next((tid for a, b, tid in held.get(f, ()) if a <= at < b and tid != track_id), None)
            if tid is None:
                return []
            out.append(tid)
        return out

    def whose(tids: Sequence[int], p: int) -> str:
        parts = []
        for tid in tids:
            q = log.tracks[tid].true_person
            parts.append("their own earlier track" if q == p else f"{people[q].name}'s track" if q >= 0
                         else "a false track")
        return "; ".join(dict.fromkeys(parts))

    def held_by(faces: Sequence[int], tids: Sequence[int], p: int) -> str:
        own = f"their own face ({_faces(faces)})" if len(faces) == 1 else f"all their own faces ({_faces(faces)})"
        verb = "was" if len(faces) == 1 else "were"
        track_word = "track" if len(set(tids)) == 1 else "tracks"
        return f"{own} {verb} held by {track_word} {', '.join(str(t) for t in dict.fromkeys(tids))} ({whose(tids, p)})"

    lines = []
    for o in sorted(outcomes, key=lambda o: (o.birth_s, o.track_id)):
        tr = log.tracks[o.track_id]
        person = people[o.person]
        name, tid = person.name, o.track_id
        lead = f"{name} (track {tid})"  # "<lead> was given a new id ..."
        if o.reid_case:
            learned_s = min(log.faces[f][0] for f in own_faces(o.person, o.birth_s))
            lead = (f"{name} came back (track {tid}) and" if _visit_of(person, o.birth_s) > _visit_of(person, learned_s)
                    else f"{name}, lost by the tracker in view and picked up again (track {tid}),")
        given = evidence.get(tid, [])
        how = EVIDENCE_WORDS[given[0][2] if given else "face"]
        wrong_names = [n for n in tr.names if n != name]
        if o.failure_kind == "wrong_person":
            q = face_person.get(o.face_id, -1)
            if q < 0:
                lines.append(f"{name} (track {tid}) was given face {o.face_id}, learned from nobody in the scene, "
                             f"by {how}")
            elif wrong_names:
                lines.append(f"{name} was named {', '.join(wrong_names)} by {how} (track {tid} got "
                             f"{people[q].name}'s face {o.face_id})")
            else:
                lines.append(f"{name} was taken for {people[q].name} by {how} (track {tid} got "
                             f"{people[q].name}'s face {o.face_id})")
        elif o.failure_kind == "new_id":
            assert o.decided_s is not None
            own = own_faces(o.person, o.decided_s)
            busy = holders(own, o.decided_s, tid)
            if busy:
                lines.append(f"{lead} was given a new id (face {o.face_id}) while {held_by(own, busy, o.person)}")
            else:
                free = "their own face ({}) was free: their face was not matched to it" if len(own) == 1 else \
                    "their own faces ({}) were free: their face was not matched to them"
                lines.append(f"{lead} was given a new id (face {o.face_id}) although "
                             + free.format(_faces(own)))
        elif o.outcome == "none" and o.reid_case:
            own = own_faces(o.person, tr.last_seen_s)
            busy = holders(own, tr.last_seen_s, tid)
            if tr.face_detections == 0:
                why = "no face seen"
                if busy:
                    why += f", and {held_by(own, busy, o.person)}"
                elif body_identity:
                    why += " and their clothes matched nobody confidently"
            else:
                why = f"their face was seen ({tr.face_detections} observations) without a decision"
                if busy:
                    why += f" while {held_by(own, busy, o.person)}"
            lines.append(f"{lead} was never re-identified{' nor named' if person.in_gallery else ''}: {why}")
        elif wrong_names:  # its own face (or a first appearance's new one) was named after somebody else
            photos = f"{wrong_names[0]}'s gallery photos" if len(wrong_names) == 1 else "their gallery photos"
            lines.append(f"{name} (track {tid}) was named {', '.join(wrong_names)}: their own face (face "
                         f"{o.face_id}) matched {photos}")
        elif person.in_gallery and name not in tr.names:
            if o.face_id:
                lines.append(f"{name} (track {tid}) was never named: their face (face {o.face_id}) was not matched "
                             "to their gallery photos")
            else:
                why = ("no face seen" if tr.face_detections == 0 else
                       f"their face was seen ({tr.face_detections} observations) without a decision")
                lines.append(f"{name} (track {tid}) was never named: never identified, {why}")
    return lines


def summarize(scenario: DemoScenario, messages: Sequence[TrackMessage], method: str = "bayes",
              body_identity: bool | None = None) -> dict[str, Any]:
    """Per-person and total metrics of a run (JSON-ready): tracks, re-identifications correct / wrong /
    pending and by what (face, body, both), names right / wrong / none, mean re-identification time, the
    evaluation's totals and one line per failure (:func:`explain_failures`; ``body_identity``: the master
    decides faceless tracks by body, by default with the bayes method)."""
    log = build_run_log(scenario, messages, method)
    t = scenario.truth_times()
    detectable, _ = scenario.visibility(t)
    losses = count_losses(t, detectable.T, min_gap_s=1.5)
    gallery = {p.name: p.gt_id for p in scenario.people if p.in_gallery}
    totals = evaluate_run(log, gallery_people=gallery, with_mot=False,
                          scenario_summary={"losses": losses.total_losses, "visible_segments": losses.total_segments})
    outcomes = track_outcomes(log)
    evaluated = {tr.track_id: tr for tr in evaluated_tracks(log)}
    evidence = published_evidence(messages)
    people = []
    for person in scenario.people:
        mine = [o for o in outcomes if o.person == person.gt_id]
        reid = [o for o in mine if o.reid_case]
        times = [o.decided_s - o.birth_s for o in reid if o.outcome == "success" and o.decided_s is not None]
        right = wrong = none = 0
        for o in mine:
            names = evaluated[o.track_id].names
            if any(n != person.name for n in names) or (names and not person.in_gallery):
                wrong += 1
            elif person.name in names:
                right += 1
            else:
                none += 1
        face_ids = sorted({o.face_id for o in mine if o.face_id})
        # what re-identified them: per correct re-identification, the evidence its face id was last shown with
        by = [evidence[o.track_id][0][2] if o.track_id in evidence else "face"
              for o in reid if o.outcome == "success"]
        people.append({
            "name": person.name, "gt_id": person.gt_id, "in_gallery": person.in_gallery,
            "returns": len(person.visits) - 1, "tracks": len(mine), "face_ids": face_ids,
            "reid_correct": sum(o.outcome == "success" for o in reid),
            "reid_wrong": sum(o.outcome == "failure" for o in reid),
            "reid_pending": sum(o.outcome == "none" for o in reid),
            "names_right": right, "names_wrong": wrong, "names_none": none,
            "mean_reid_time_s": round(float(np.mean(times)), 2) if times else None,
            "reidentified_by": by,
        })
    errors = []
    if messages:
        for tr in evaluated.values():
            if tr.path:
                ts = np.array([s for s, _, _ in tr.path])
                est = np.array([[x, y] for _, x, y in tr.path])
                xy, _ = scenario.true_xy(ts)
                errors.extend(np.linalg.norm(est - xy[:, tr.true_person], axis=1).tolist())
    return {
        "seed": scenario.seed, "duration_s": scenario.duration_s, "cameras": len(scenario.cameras),
        "method": method, "messages": len(messages), "people": people,
        "false_tracks": totals["tracker"]["false_positive_tracks"],
        "median_position_error_m": round(float(np.median(errors)), 3) if errors else None,
        "reidentification": totals["reidentification"], "predefined_people": totals["predefined_people"],
        "first_appearance": totals["first_appearance"], "faces": totals["faces"],
        "failures": explain_failures(scenario, log, outcomes, evidence,
                                     method == "bayes" if body_identity is None else body_identity),
    }


def label(tr: NamedTrackRecord, undecided: str = "?") -> str:
    """Who the master said a track is: its name, its face, or ``undecided``."""
    return tr.name or (f"face {tr.face_id}" if tr.face_id else undecided)


def _who(tr: NamedTrackRecord) -> str:
    who = label(tr)
    return f"{who} (by body)" if tr.identity_evidence == "body" else who


def _confidence(tr: NamedTrackRecord, undecided: str = "-") -> str:
    """A decided track's identity_confidence; ``undecided`` for a track with face id 0 (it claims nobody: no
    number is shown, whatever a master sent with it)."""
    return f"{tr.identity_confidence:.2f}" if tr.face_id else undecided


_STATES = {0: "tentative", STATE_CONFIRMED: "confirmed", STATE_LOST: "lost"}


def format_table(scenario: DemoScenario, msg: TrackMessage | None, elapsed_s: float, compact: bool = False) -> str:
    """The live table: one row per published track (who, confidence, where, cameras, state, truth)."""
    head = f"t = {elapsed_s:5.1f} s / {scenario.duration_s:.0f} s"
    if msg is None:
        return f"{head}: no /tracks_named message yet"
    xy, inside = scenario.true_xy(np.array([msg.stamp_s]))
    rows = []
    half = scenario.world.room.half_extents
    for tr in sorted(msg.tracks, key=lambda r: r.track_id):
        if tr.state == STATE_LOST:  # a lost track is a prediction that drifts on: shown where it was, in the room
            tr = dataclasses.replace(tr, position_xy=np.clip(np.asarray(tr.position_xy, dtype=np.float64), -half, half))
        gt = nearest_person(np.asarray(tr.position_xy, dtype=np.float64), xy[0], inside[0])
        truth = scenario.people[gt].name if gt >= 0 else "-"
        rows.append((tr, truth))
    if compact:
        parts = [f"#{tr.track_id} {_who(tr)} ({_confidence(tr, 'undecided')}) at ({tr.position_xy[0]:+.1f}, "
                 f"{tr.position_xy[1]:+.1f}) [{_STATES.get(tr.state, tr.state)}; truth: {truth}]" for tr, truth in rows]
        return f"{head}: {len(rows)} tracks" + ("; " + "; ".join(parts) if parts else "")
    lines = [f"{head}   {len(rows)} tracks on /tracks_named",
             f"{'track':>5}  {'who':<18} {'conf':>5}  {'x m':>6} {'y m':>6}  {'cameras':<18} {'state':<9}  truth"]
    for tr, truth in rows:
        cams = ",".join(tr.cameras) or "-"
        lines.append(f"{tr.track_id:>5}  {_who(tr):<18.18} {_confidence(tr):>5}  {tr.position_xy[0]:>6.2f} "
                     f"{tr.position_xy[1]:>6.2f}  {cams:<18.18} {_STATES.get(tr.state, str(tr.state)):<9}  {truth}")
    return "\n".join(lines)


def format_summary(summary: dict[str, Any]) -> str:
    """The end-of-run summary as plain text."""
    lines = [
        f"Summary: {summary['duration_s']:.0f} s, {summary['cameras']} cameras, {len(summary['people'])} people "
        f"(seed {summary['seed']}), {summary['messages']} /tracks_named messages",
        f"{'person':<24} {'tracks':>6}  {'re-id ok/wrong/pending':>22}  {'names right/wrong/none':>22}  "
        f"{'mean re-id s':>12}  re-identified by",
    ]
    for p in summary["people"]:
        who = p["name"] + (" (gallery)" if p["in_gallery"] else "")
        reid = f"{p['reid_correct']}/{p['reid_wrong']}/{p['reid_pending']}"
        names = f"{p['names_right']}/{p['names_wrong']}/{p['names_none']}"
        mean = f"{p['mean_reid_time_s']:.1f}" if p["mean_reid_time_s"] is not None else "-"
        by = ", ".join(p["reidentified_by"]) or "-"
        lines.append(f"{who:<24} {p['tracks']:>6}  {reid:>22}  {names:>22}  {mean:>12}  {by}")
    r = summary["reidentification"]
    rate = f"{r['recover_rate']:.2f}" if r["recover_rate"] is not None else "-"
    lines.append(f"re-identifications: {r['success']} correct, {r['failure']} wrong, {r['none']} pending "
                 f"(recover rate {rate}); false tracks: {summary['false_tracks']}; median position error: "
                 f"{summary['median_position_error_m']} m")
    lines.append("(per track; people not in the gallery should get no name: 'none' is right for them; "
                 "re-identified by: their face, their body, or both: body first, then the face agreed)")
    failures = summary["failures"]
    lines.append("what went wrong:" + ("" if failures else " nothing"))
    lines.extend(f"  - {line}" for line in failures)
    return "\n".join(lines)
