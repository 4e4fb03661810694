"""What the master published during a demo run, judged against the scripted scene: the live table and the
end-of-run summary (metrics of :mod:`face_reid_master.evaluation.metrics`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from face_reid_master.demo.scenario import DemoScenario
from face_reid_master.evaluation.metrics import evaluate_run, evaluated_tracks, track_outcomes
from face_reid_master.evaluation.published_tracks import TrackMessage, nearest_person, run_log_from_messages
from face_reid_master.evaluation.runner import RunLog
from face_reid_master.records import STATE_CONFIRMED, STATE_LOST, NamedTrackRecord
from face_reid_master.sim.visibility import count_losses

__all__ = ["build_run_log", "format_summary", "format_table", "summarize"]


def build_run_log(scenario: DemoScenario, messages: Sequence[TrackMessage], method: str = "bayes") -> RunLog:
    """A :class:`~face_reid_master.evaluation.runner.RunLog` from the published tracks (each confirmed track
    attributed to the nearest true person: see
    :func:`~face_reid_master.evaluation.published_tracks.run_log_from_messages`)."""
    return run_log_from_messages(messages, scenario.true_xy, len(scenario.people),
                                 ((1, 0.0, scenario.duration_s, tuple(p.gt_id for p in scenario.people)),), method)


def summarize(scenario: DemoScenario, messages: Sequence[TrackMessage], method: str = "bayes") -> dict[str, Any]:
    """Per-person and total metrics of a run (JSON-ready): tracks, re-identifications correct / wrong /
    pending, names right / wrong / none, mean re-identification time, and the evaluation's totals."""
    log = build_run_log(scenario, messages, method)
    t = scenario.truth_times()
    detectable, _ = scenario.visibility(t)
    losses = count_losses(t, detectable.T, min_gap_s=1.5)
    gallery = {p.name: p.gt_id for p in scenario.people if p.in_gallery}
    totals = evaluate_run(log, gallery_people=gallery, with_mot=False,
                          scenario_summary={"losses": losses.total_losses, "visible_segments": losses.total_segments})
    outcomes = track_outcomes(log)
    evaluated = {tr.track_id: tr for tr in evaluated_tracks(log)}
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
        people.append({
            "name": person.name, "gt_id": person.gt_id, "in_gallery": person.in_gallery,
            "returns": len(person.visits) - 1, "tracks": len(mine), "face_ids": face_ids,
            "reid_correct": sum(o.outcome == "success" for o in reid),
            "reid_wrong": sum(o.outcome == "failure" for o in reid),
            "reid_pending": sum(o.outcome == "none" for o in reid),
            "names_right": right, "names_wrong": wrong, "names_none": none,
            "mean_reid_time_s": round(float(np.mean(times)), 2) if times else None,
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
    }


def _who(tr: NamedTrackRecord) -> str:
    who = tr.name or (f"face {tr.face_id}" if tr.face_id else "?")
    return f"{who} (by body)" if tr.identity_evidence == "body" else who


_STATES = {0: "tentative", STATE_CONFIRMED: "confirmed", STATE_LOST: "lost"}


def format_table(scenario: DemoScenario, msg: TrackMessage | None, elapsed_s: float, compact: bool = False) -> str:
    """The live table: one row per published track (who, confidence, where, cameras, state, truth)."""
    head = f"t = {elapsed_s:5.1f} s / {scenario.duration_s:.0f} s"
    if msg is None:
        return f"{head}: no /tracks_named message yet"
    xy, inside = scenario.true_xy(np.array([msg.stamp_s]))
    rows = []
    for tr in sorted(msg.tracks, key=lambda r: r.track_id):
        gt = nearest_person(np.asarray(tr.position_xy, dtype=np.float64), xy[0], inside[0])
        truth = scenario.people[gt].name if gt >= 0 else "-"
        rows.append((tr, truth))
    if compact:
        parts = [f"#{tr.track_id} {_who(tr)} ({tr.identity_confidence:.2f}) at ({tr.position_xy[0]:+.1f}, "
                 f"{tr.position_xy[1]:+.1f}) [{_STATES.get(tr.state, tr.state)}; truth: {truth}]" for tr, truth in rows]
        return f"{head}: {len(rows)} tracks" + ("; " + "; ".join(parts) if parts else "")
    lines = [f"{head}   {len(rows)} tracks on /tracks_named",
             f"{'track':>5}  {'who':<18} {'conf':>5}  {'x m':>6} {'y m':>6}  {'cameras':<18} {'state':<9}  truth"]
    for tr, truth in rows:
        cams = ",".join(tr.cameras) or "-"
        lines.append(f"{tr.track_id:>5}  {_who(tr):<18.18} {tr.identity_confidence:>5.2f}  {tr.position_xy[0]:>6.2f} "
                     f"{tr.position_xy[1]:>6.2f}  {cams:<18.18} {_STATES.get(tr.state, str(tr.state)):<9}  {truth}")
    return "\n".join(lines)


def format_summary(summary: dict[str, Any]) -> str:
    """The end-of-run summary as plain text."""
    lines = [
        f"Summary: {summary['duration_s']:.0f} s, {summary['cameras']} cameras, {len(summary['people'])} people "
        f"(seed {summary['seed']}), master method {summary['method']}, {summary['messages']} /tracks_named messages",
        f"{'person':<24} {'tracks':>6}  {'re-id ok/wrong/pending':>22}  {'names right/wrong/none':>22}  "
        f"{'mean re-id s':>12}",
    ]
    for p in summary["people"]:
        who = p["name"] + (" (gallery)" if p["in_gallery"] else "")
        reid = f"{p['reid_correct']}/{p['reid_wrong']}/{p['reid_pending']}"
        names = f"{p['names_right']}/{p['names_wrong']}/{p['names_none']}"
        mean = f"{p['mean_reid_time_s']:.1f}" if p["mean_reid_time_s"] is not None else "-"
        lines.append(f"{who:<24} {p['tracks']:>6}  {reid:>22}  {names:>22}  {mean:>12}")
    r = summary["reidentification"]
    rate = f"{r['recover_rate']:.2f}" if r["recover_rate"] is not None else "-"
    lines.append(f"re-identifications: {r['success']} correct, {r['failure']} wrong, {r['none']} pending "
                 f"(recover rate {rate}); false tracks: {summary['false_tracks']}; median position error: "
                 f"{summary['median_position_error_m']} m")
    lines.append("(per track; people not in the gallery should get no name: 'none' is right for them)")
    return "\n".join(lines)
