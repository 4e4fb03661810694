"""Calibration of the identity posterior: is a decision taken at posterior p right p of the time?

Every face-id decision of a run (a track's first face id, and the next one after a swap released it) with the
posterior it was taken at (``identity_confidence``), what decided it (face / body) and whether it was right by the
evaluation's own rule (:func:`~face_reid_master.evaluation.metrics.track_outcomes`: the Table II verdict of the
track's first face id). From them: a reliability table (bins of the posterior: count, mean confidence, accuracy),
the expected calibration error, the error rate of the decisions each threshold in use let through, and the
frontier of right / wrong decisions kept when deciding only at posterior >= t. Pure numpy; no rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_master.evaluation.metrics import decision_verdict, face_persons, learned_at, track_outcomes
from face_reid_master.evaluation.runner import RunLog
from face_reid_master.identity.confidence_map import DECISIONS, decision_key

__all__ = [
    "DEFAULT_BIN_EDGES",
    "DEFAULT_FRONTIER_THRESHOLDS",
    "EVIDENCE_KINDS",
    "Decision",
    "calibration_report",
    "expected_calibration_error",
    "frontier",
    "reliability_bins",
    "run_decisions",
    "save_reliability_plot",
]

# the posteriors crowd near 1 (face decisions exceed 0.95, body ones 0.999; the face table is clamped at 0.999):
# bins fine there, so that the thresholds in use are edges
DEFAULT_BIN_EDGES: tuple[float, ...] = (0.0, 0.5, 0.9, 0.95, 0.97, 0.99, 0.995, 0.999, 0.9999, 1.0)
DEFAULT_FRONTIER_THRESHOLDS: tuple[float, ...] = (0.0, 0.5, 0.9, 0.95, 0.96, 0.97, 0.98, 0.99, 0.995, 0.998,
                                                  0.999, 0.9995, 0.9999)
EVIDENCE_KINDS = ("face", "body", "both")


@dataclass(frozen=True)
class Decision:
    """One face-id decision of an evaluated track (``confidence``: NaN when the run did not record it)."""

    track_id: int
    stamp_s: float
    face_id: int
    kind: str  # "new" | "known"
    confidence: float
    evidence: str  # "face" | "body" | "both": what decided it
    right: bool
    failure_kind: str  # "" | "wrong_person" | "new_id"
    first: bool  # the track's first face id (judged exactly as Table II); False: after a swap released one
    reid_case: bool  # the person had a learned face before the track's birth (or, after a swap, before it)


def run_decisions(log: RunLog) -> list[Decision]:
    """Every face-id assignment of the evaluated tracks, in time order, judged as the metrics judge them.

    A track's first face id takes its :func:`track_outcomes` verdict. A later one (its lent face was taken while
    it was lost, and it was identified afresh) is judged by the same rule with the track's person until then
    (:meth:`TrackLog.face_person_until`).
    """
    face_person = face_persons(log)
    learned = learned_at(log, face_person)
    out: list[Decision] = []
    for o in track_outcomes(log):
        t = log.tracks[o.track_id]
        for k, (stamp, fid, kind) in enumerate(t.assignments):
            conf = float(t.confidence[k]) if k < len(t.confidence) else math.nan
            evidence = t.evidence[k] if k < len(t.evidence) else "face"
            if k == 0:
                right, why, reid = o.outcome == "success", o.failure_kind, o.reid_case
            else:
                person = t.face_person_until(stamp)
                reid = learned.get(person, math.inf) < t.birth_s
                verdict, why = decision_verdict(face_person.get(fid, -1), kind, person, reid)
                right = verdict == "success"
            out.append(Decision(t.track_id, float(stamp), int(fid), kind, conf, evidence, right, why, k == 0, reid))
    out.sort(key=lambda d: (d.stamp_s, d.track_id))
    return out


def _arrays(confidence: Sequence[float] | NDArray[np.floating], right: Sequence[bool] | NDArray[np.bool_]
            ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    conf = np.asarray(confidence, dtype=np.float64).reshape(-1)
    ok = np.asarray(right, dtype=bool).reshape(-1)
    if conf.shape != ok.shape:
        raise ValueError(f"confidence ({conf.size}) and right ({ok.size}) differ in length")
    if conf.size and not (np.all(np.isfinite(conf)) and conf.min() >= 0.0 and conf.max() <= 1.0):
        raise ValueError("confidences must be finite and in [0, 1]")
    return conf, ok


def _edges(edges: Sequence[float]) -> NDArray[np.float64]:
    e = np.asarray(edges, dtype=np.float64)
    if e.ndim != 1 or e.size < 2 or e[0] != 0.0 or e[-1] != 1.0 or np.any(np.diff(e) <= 0):
        raise ValueError(f"bin edges must increase strictly from 0 to 1, got {list(edges)}")
    return e


def _bin_index(conf: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.intp]:
    """Bin of each confidence: [lo, hi), the last bin closed at 1."""
    return np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, edges.size - 2)


def reliability_bins(confidence: Sequence[float] | NDArray[np.floating], right: Sequence[bool] | NDArray[np.bool_],
                     edges: Sequence[float] = DEFAULT_BIN_EDGES) -> list[dict[str, Any]]:
    """Per bin [lo, hi) of the posterior (the last one closed): count, mean confidence, accuracy (None if empty)."""
    conf, ok = _arrays(confidence, right)
    e = _edges(edges)
    idx = _bin_index(conf, e)
    out = []
    for b in range(e.size - 1):
        sel = idx == b
        n = int(np.count_nonzero(sel))
        out.append({"lo": float(e[b]), "hi": float(e[b + 1]), "count": n,
                    "mean_confidence": round(float(conf[sel].mean()), 6) if n else None,
                    "accuracy": round(float(ok[sel].mean()), 6) if n else None,
                    "wrong": int(n - np.count_nonzero(ok[sel]))})
    return out


def expected_calibration_error(confidence: Sequence[float] | NDArray[np.floating],
                               right: Sequence[bool] | NDArray[np.bool_],
                               edges: Sequence[float] = DEFAULT_BIN_EDGES) -> float | None:
    """Count-weighted mean over the bins of |accuracy - mean confidence| (None without decisions)."""
    conf, ok = _arrays(confidence, right)
    if not conf.size:
        return None
    e = _edges(edges)
    idx = _bin_index(conf, e)
    conf_sum = np.bincount(idx, weights=conf, minlength=e.size - 1)
    right_sum = np.bincount(idx, weights=ok.astype(np.float64), minlength=e.size - 1)
    return float(np.sum(np.abs(right_sum - conf_sum)) / conf.size)  # sum_b n_b |acc_b - conf_b| / N


def frontier(confidence: Sequence[float] | NDArray[np.floating], right: Sequence[bool] | NDArray[np.bool_],
             thresholds: Sequence[float] = DEFAULT_FRONTIER_THRESHOLDS, *,
             recovers: Sequence[bool] | NDArray[np.bool_] | None = None, reid_tracks: int = 0
             ) -> list[dict[str, Any]]:
    """Per threshold t: the decisions taken at posterior >= t (right, wrong, error rate) and, given ``recovers``
    (per decision: a right first decision of a re-identification case) and ``reid_tracks``, the recover rate
    they would keep. An offline filter of the decisions taken: a stricter master would wait for more evidence
    and decide some of the dropped ones later, so the kept counts are a lower bound."""
    conf, ok = _arrays(confidence, right)
    rec = np.zeros(conf.size, dtype=bool) if recovers is None else np.asarray(recovers, dtype=bool).reshape(-1)
    if rec.shape != conf.shape:
        raise ValueError("recovers must have one flag per decision")
    out = []
    for t in thresholds:
        keep = conf >= float(t)
        n, n_right = int(np.count_nonzero(keep)), int(np.count_nonzero(keep & ok))
        row: dict[str, Any] = {"threshold": float(t), "decisions": n, "right": n_right, "wrong": n - n_right,
                               "error_rate": round((n - n_right) / n, 6) if n else None}
        if reid_tracks:
            row["recover_rate"] = round(int(np.count_nonzero(keep & rec)) / reid_tracks, 6)
        out.append(row)
    return out


def _summary(conf: NDArray[np.float64], ok: NDArray[np.bool_], edges: Sequence[float]) -> dict[str, Any]:
    n = int(conf.size)
    ece = expected_calibration_error(conf, ok, edges)
    return {
        "decisions": n,
        "right": int(np.count_nonzero(ok)),
        "wrong": int(n - np.count_nonzero(ok)),
        "error_rate": round(float(1.0 - ok.mean()), 6) if n else None,
        "mean_confidence": round(float(conf.mean()), 6) if n else None,
        "expected_error": round(float(1.0 - conf.mean()), 6) if n else None,  # what the posteriors promise
        "ece": round(ece, 6) if ece is not None else None,
        "brier": round(float(np.mean((conf - ok) ** 2)), 6) if n else None,
        "bins": reliability_bins(conf, ok, edges),
    }


def calibration_report(decisions: Sequence[Decision], *, thresholds: Mapping[str, float] | None = None,
                       reid_tracks: int = 0, edges: Sequence[float] = DEFAULT_BIN_EDGES,
                       frontier_thresholds: Sequence[float] = DEFAULT_FRONTIER_THRESHOLDS) -> dict[str, Any]:
    """The JSON block ``calibration`` of the evaluation: all decisions with a recorded posterior, then split by
    evidence and by kind (new / known face), the decisions each threshold in use let through
    (``thresholds``: evidence -> posterior it must exceed), and the frontier (``reid_tracks``: the
    re-identification-case tracks, the recover rate's denominator)."""
    recorded = [d for d in decisions if math.isfinite(d.confidence)]
    conf, ok = _arrays([d.confidence for d in recorded], [d.right for d in recorded])
    evidence = np.array([d.evidence for d in recorded], dtype=object)
    key = np.array([decision_key(d.evidence, d.kind == "new") for d in recorded], dtype=object)
    at_thresholds = {}
    for ev, thr in sorted((thresholds or {}).items()):
        sel = evidence == ev
        above = sel & (conf >= thr)
        n, n_ok = int(np.count_nonzero(above)), int(np.count_nonzero(above & ok))
        at_thresholds[ev] = {"threshold": float(thr), "promised_max_error": round(1.0 - float(thr), 6),
                             "decisions": n, "wrong": n - n_ok, "error_rate": round((n - n_ok) / n, 6) if n else None,
                             "decisions_below_threshold": int(np.count_nonzero(sel & (conf < thr)))}
    recovers = [d.first and d.reid_case and d.right for d in recorded]
    return {
        "bin_edges": [float(e) for e in _edges(edges)],
        **_summary(conf, ok, edges),
        "first_decisions": sum(d.first for d in recorded),
        "decisions_after_release": sum(not d.first for d in recorded),
        "decisions_without_confidence": len(decisions) - len(recorded),
        "by_evidence": {ev: _summary(conf[evidence == ev], ok[evidence == ev], edges) for ev in EVIDENCE_KINDS},
        "by_decision": {k: _summary(conf[key == k], ok[key == k], edges) for k in DECISIONS},  # the map's kinds
        "at_thresholds": at_thresholds,
        "frontier": frontier(conf, ok, frontier_thresholds, recovers=recovers, reid_tracks=reid_tracks),
    }


def save_reliability_plot(decisions: Sequence[Decision], path: str, *, thresholds: Mapping[str, float] | None = None,
                          edges: Sequence[float] = DEFAULT_BIN_EDGES, title: str = "") -> None:
    """A reliability diagram per evidence kind: observed error rate against the error the posterior promises
    (1 - mean confidence) per bin, log-log (the posteriors crowd near 1), marker area ~ decisions; on the
    diagonal a posterior of p is right p of the time. Bins without an error are drawn at half an error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    recorded = [d for d in decisions if math.isfinite(d.confidence)]
    fig, ax = plt.subplots(figsize=(6.5, 6))
    lo = 1e-5
    ax.plot([lo, 1.0], [lo, 1.0], color="0.5", lw=1, ls="--", label="perfectly calibrated")
    colours = {"face": "tab:blue", "body": "tab:orange", "both": "tab:purple"}
    for ev in EVIDENCE_KINDS:
        sel = [d for d in recorded if d.evidence == ev]
        if not sel:
            continue
        for b in reliability_bins([d.confidence for d in sel], [d.right for d in sel], edges):
            if not b["count"]:
                continue
            promised = max(1.0 - b["mean_confidence"], lo)
            observed = b["wrong"] / b["count"]
            shown = observed if b["wrong"] else 0.5 / b["count"]
            ax.scatter([promised], [shown], s=20 + 4 * b["count"], color=colours[ev], alpha=0.6,
                       marker="o" if b["wrong"] else "v", edgecolors="k", linewidths=0.5)
            ax.annotate(str(b["count"]), (promised, shown), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.scatter([], [], color=colours[ev], label=f"{ev} ({len(sel)} decisions)")
    for ev, thr in sorted((thresholds or {}).items()):
        ax.axvline(max(1.0 - thr, lo), color=colours.get(ev, "k"), lw=0.8, ls=":",
                   label=f"{ev} threshold {thr:g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(lo, 1.0)
    ax.set_ylim(lo, 1.5)  # an all-wrong bin (error 1) stays inside the frame
    ax.set_xlabel("promised error: 1 - mean posterior of the bin")
    ax.set_ylabel("observed error rate (triangle: no error, drawn at 0.5 / count)")
    ax.set_title(f"{title}  reliability of identity decisions", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
