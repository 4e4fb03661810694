"""Our extension of Algorithm 1: a track that shows no face is identified by its body.

Body observations are queued in each track's record until the identity step; then those of identified tracks join their
face's body gallery (not those of a track a face decided below ``learn_confidence``: one uncertain decision must not
teach one person's clothes to another's face) and those of faceless tracks are weighed against every learned face's
recent bodies (:class:`~face_reid_master.identity.body_evidence.BodyEvidence`), which decides the faceless tracks
whose evidence is strong enough. A track's own face, once seen, overrules its body.

Measured on the development scenarios (real evidence, fused): an uncertain known-face decision teaching its face's
body gallery nothing took the seven 20-person scenarios from 2521 / 329 right / wrong to 2550 / 316 (recover 0.596
-> 0.603); oracle runs were unchanged, six people nearly so (nine seeds 275 / 62 -> 274 / 62). Withholding the
bodies of uncertain new-person decisions as well (a new face learns its person's clothes only from a decision of at
least ``learn_confidence``) did not win: six people, nine seeds 274 / 62 -> 289 / 65; seed 215 362 / 53 -> 350 / 59
(wrong identity per detection 1.07 -> 1.31 %).

Measured on the development scenarios and not adopted: letting the body confirm or doubt a face's choice (an
undecided track that shows a face keeps comparing its bodies, and before the face decides, the body's log odds for
the learned face the track's face most likely is multiply that face's posterior; never another face). Unbounded, it
made oracle runs worse (6 people, five seeds: 3 -> 13 wrong: bodies gathered over a long faceless stretch outweighed
a clear face). Bounded at 2.3 nats (a factor of 10), the 6-person oracle runs were unchanged and 6 people with real
evidence gained on every measure (nine seeds: 275 / 62 -> 293 / 52 right / wrong, recover 0.59 -> 0.62, wrong
identity per detection 1.08 -> 0.87 %), but at 20 people it did not: seeds 215 355 / 53 -> 334 / 54, 217 352 / 60 ->
346 / 53, 218 327 / 45 -> 298 / 48, 1920x1080 410 / 23 -> 411 / 20; wrong identity per detection 1.00 -> 2.34, 2.92
-> 2.47, 1.46 -> 1.70, 0.65 -> 0.59 %. In a crowd of twenty several people's recent bodies look alike, so the body
doubted right choices about as often as wrong ones. Variants measured on the same seeds did no better: the evidence
without the feature funnel's bound on abandoned faces (218: 300 / 54), the body's Bayes factor against every other
face rather than against "someone else" (215: 305 / 44, recover 0.51 -> 0.47; 218: 288 / 52), the body's evidence,
unbounded, on every face rather than on the face's choice (215: 325 / 75), confirming only, never doubting (218: 326
/ 52; 6 people real 291 / 59, 1.12 %).

Measured and not adopted either: the body keeping a face from declaring a new person. Most new-person decisions
that are wrong are a returning person whose own learned face was free but missed by the embedder; an undecided
track that shows a face compared its bodies too (never decided by them), and while they made one learned face's
person likelier than 0.9 its face could not call it new. Six people with real evidence gained (nine seeds: 275 / 62
-> 265 / 47, wrong identity per detection 1.08 -> 0.61 %, recover 0.59 -> 0.60), but the oracle runs lost (five
seeds: 155 / 3 -> 140 / 8): a newcomer dressed like someone seen lately waits unlearned, and meanwhile their faceless
tracks are given that someone by their body. At 20 people with real evidence it lost too (213: 358 / 60 -> 326 / 85:
one person never learned, first appearances taken for a known person 5 -> 28; 215 355 / 53 -> 341 / 55; 217 352 /
60 -> 350 / 58; 218 327 / 45 -> 317 / 48). Vetoing only where the face, too, gives the body's choice some
weight (its posterior at least 0.01) never vetoes: the missed face sits at the table's clamp (0.001-0.007), the
face's evidence against it is strong.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.body_evidence import BodyEvidence
from face_reid_master.identity.evidence import CueChunk, Evidence, TrackView

__all__ = ["BodyIdentification"]

F32Array = npt.NDArray[np.float32]
FloatArray = npt.NDArray[np.float64]


class BodyIdentification:
    """The body cue as an :class:`~face_reid_master.identity.evidence.EvidenceSource`: the body evidence fed at
    each identity step with the bodies the tracks' records queued (see the module doc)."""

    kind = Evidence.BODY

    def __init__(self, evidence: BodyEvidence) -> None:
        if not isinstance(evidence, BodyEvidence):
            raise ValueError(f"body_evidence must be a BodyEvidence or None, got {type(evidence).__name__}")
        self.evidence = evidence

    def read(self, person: object, detection: int, detections: Any) -> F32Array | None:
        """The detection's body embedding (1, r) in the metric's space (None: the body was not described)."""
        appearance = detections.appearance
        if appearance is None:
            return None
        row = appearance[detection]
        return row[None, :] if np.isfinite(row[0]) else None  # NaN rows: not described

    def forget_track(self, track_id: int) -> None:
        """The track was deleted (its queued bodies went with its record) or identified without teaching: its
        evidence goes."""
        self.evidence.forget_track(track_id)

    def forget_face(self, face_id: int) -> None:
        """The face was forgotten: its bodies go."""
        self.evidence.forget_face(face_id)

    def observe(self, queued: Sequence[tuple[TrackView, list[CueChunk]]], face_ids: list[int]) -> None:
        """The queued bodies: an identified track's join its face's gallery; a faceless track's (one not
        buffering face observations) are compared with the recent bodies of every face in ``face_ids``."""
        for track, parts in queued:
            for emb, t, source, heights in parts:
                if track.face_id is not None:
                    self.evidence.add_face_bodies(track.face_id, emb, t, heights)
                else:  # faceless tracks are compared; the others only keep their bodies for their face
                    self.evidence.observe(track.track_id, emb, t, face_ids if track.slot is None else [], source,
                                          heights)

    def decide(self, available: list[int], stamp: float,
               alike: Callable[[int, list[int]], list[bool]]) -> list[tuple[int, int, float]]:
        """(track id, face id, posterior) of the faceless tracks their bodies decide now (faces of face_list)."""
        return self.evidence.decide(available, stamp, alike)

    def track_identified(self, track_id: int, face_id: int) -> None:
        """The bodies a track gathered before its decision join its face's gallery."""
        emb, newest, heights = self.evidence.track_bodies(track_id)
        if emb.shape[0]:
            self.evidence.add_face_bodies(face_id, emb, newest, heights=heights)
        self.evidence.forget_track(track_id)
