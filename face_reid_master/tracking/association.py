"""Data association of one camera frame: which detection belongs to which predicted track (pure numpy).

Tracks are served in a cascade (as DeepSORT's matching cascade): CONFIRMED tracks detected within
``coast_after_s``, then the other CONFIRMED ones, then LOST, then TENTATIVE, so that neither a
coasting track whose person is gone nor a tentative duplicate takes the detection of a person whose
track is healthy.  Within a group, pass 1 is GNN inside the chi-square gate (and the metric gate) on
``d2 + log det S`` (the negative log-likelihood: with ``d2`` alone a vague track looks closer than a
precise one).  Pass 2 (not for LOST tracks) gives a leftover track a leftover detection within
``min_person_separation_m`` of its prediction (nobody else can be so close), inside the wider gate of
probability ``1 - (1 - gate_probability)**2`` (= twice the d2 gate for 2 dof), or within reach of its
last measured position (``min_person_separation_m + max_speed_mps * elapsed``, at most
``max_gate_distance_m``): the constant-velocity gate alone loses people who turn or stop, and noise
outliers.

Body appearance (where a track and a detection both have an embedding, see
:mod:`~face_reid_master.tracking.appearance`): a pair beyond ``appearance_gate`` is infeasible in every
pass, ``appearance_weight`` x the distance is added to the pass-1 cost, and LOST tracks left over get a
third pass: a detection within walking reach of their last one (no position gate) that looks like them and
like no other track.

Crossings: for two tracks the association could have given each other's detection (both pairs within the wide
gate), the probability that it swapped them is the likelihood of the exchanged pairs over both assignments'
(``Matches.swaps``); likewise for a track that took a detection another, undetected, track could have had.

Strays: a track may also take the detection of a person it was not following, one whose own track is new or gone
(its person left the view as another walked in). For every detection a CONFIRMED or LOST track took, the
probability that it is such a person (``Matches.strays``) is a logistic of the pair's position log-likelihood and
its body-appearance distance (:class:`StrayModel`, fitted on development scenarios), raised when the track had
missed the camera's previous frame but saw it within ``stray_occlusion_max_s`` (``hidden``): a switch happens most
often as a person comes out from behind another. On the strays of development seeds 202 and 213 (20 people), those
reported on the frame after one that saw the track were real switches less often than the model's odds said, by
2.1 log odds with real evidence and 0.4 with oracle evidence; those after one missed frame to 3 s were within 0.8 of
them with real evidence and 1.1-3 log odds commoner with oracle evidence. Beyond 3 s (a person walking into the
camera's view) they were, with real evidence, as rare as on the next frame again.

Measured on the development scenarios and not adopted: keeping a suspected stray's look (p >= 0.05) out of its
track's gallery, so that the track's next detections are judged against its look from before (the gallery takes a
new person's look at once: only the first detection after a switch is judged). With oracle evidence wrong identity
per detection fell everywhere (20 people, four seeds: 0.38 -> 0.35, 0.81 -> 0.39, 0.92 -> 0.59, 0.37 -> 0.26 %; 6
people, five seeds: 0.61 -> 0.29 %), but with real evidence at 20 people wrong decisions rose on all three seeds
(65 -> 72, 60 -> 67, 53 -> 66; 23 -> 25 at 1920x1080) and wrong identity per detection on two (2.0 -> 3.4, 1.0 ->
2.2 %): a real person's look changes as they turn (6 people, real evidence: 1 % of a track's own detections lie
beyond 0.52-0.58 of its gallery, and for 40 % of the strays reported at p >= 0.05 on the same person another recent
track's look is nearer), so the held look kept reporting strays on right identities: more tracks were released and
decided afresh (6 people: 555 -> 603 tracks), some wrongly.

Measured and not adopted: a CUSUM of each track's head heights against the median of its recent ones (same
person N(0, 0.045 m), another N(0, 0.12 m), alarm at 4.6 nats, one height at most half of it), its alarm reported
as a stray. With oracle evidence it removed every wrong decision on 6 people (five seeds: 3 -> 0) and wrong
identity per detection fell on every 20-person seed (0.38 -> 0.02, 0.81 -> 0.37, 0.92 -> 0.60, 0.37 -> 0.09 %);
with real evidence it was even or better on 6 people (nine seeds: 62 -> 61 wrong, 1.08 -> 0.87 %), but over seven
20-person scenarios it made more wrong decisions (329 -> 352) and more wrong identity per detection (mean of the
seven 1.68 -> 1.86 %): better on seeds 202, 216, 217 and 1920x1080 (65 -> 62, 23 -> 22, 60 -> 59, 23 -> 21),
even on 213 (60 -> 61), worse on 215 (53 -> 73, 1.0 -> 2.8 %) and 218 (45 -> 54, 1.5 -> 1.8 %). Its alarms were
mostly right (seed 215: 146 of 169 on a real switch); the losses came after them. On 215 one person's first face
decision went to a look-alike's face (posterior 0.964) instead of a new face, and every later track of theirs was
decided as one of three look-alikes' faces, whose body galleries took their bodies (wrong body rows learned 2059 ->
5099); on 218 re-identifications taken for another person rose (27 -> 35): a released track is decided again, and
with real evidence a decision just over the posterior threshold is often wrong. The simulator's head-height noise is
independent per detection (3 cm); with noisier heights replayed (per-camera bias, slow drift, outliers) it still
helped the oracle runs but left more detections undecided. Measured again once uncertain face decisions no longer
taught their face's body gallery: still worse on 215 (362 / 53 -> 348 / 68 right / wrong) and 218 (334 / 46 ->
332 / 50).

Measured and not adopted: checking a stray on the detections after it. For 2 s after a stray of p >= 0.05 the
track's look from before it was kept, and each later described detection moved the stray's log odds by the stray
model's appearance term of its mean distance to that look (counted for at most three detections), up or down; the
identity manager replaced the stray's probability by the revised one. With oracle evidence it removed almost every
carried identity (20 people, seeds 202, 213, 215, 228: 374 / 4 -> 380 / 3, 372 / 6 -> 376 / 3, 421 / 12 -> 431 / 9,
399 / 5 -> 401 / 3 right / wrong; wrong identity per detection 0.38 -> 0.02, 0.81 -> 0.25, 0.92 -> 0.12, 0.37 ->
0.01 %; 6 people, five seeds: 155 / 3 -> 159 / 0), and 6 people with real evidence gained on every measure (nine
seeds: 274 / 62 -> 331 / 59, recover 0.59 -> 0.61, wrong identity per detection 1.08 -> 0.35 %). At 20 people with
real evidence it was split: more right decisions and less wrong identity per detection on 202, 213, 216, 217 and
1920x1080 (316 / 64 -> 337 / 68 with 3.1 -> 2.2 %, 371 / 50 -> 416 / 52 with 1.9 -> 1.2 %, 410 / 24 -> 441 / 25 with
0.7 -> 0.4 %, 347 / 58 -> 388 / 69 with 2.9 -> 2.5 %, 410 / 21 -> 469 / 24 with 0.4 -> 0.3 %), worse on 215 (362 /
53 -> 371 / 67, 1.1 -> 2.1 %) and 218 (334 / 46 -> 320 / 56, 1.5 -> 2.2 %); over the seven, wrong of decided 11.0 ->
11.6 %, recover 0.60 -> 0.59 and undecided detections up on every seed. In a crowd of twenty the real looks do not
bear the check's confidence: on seed 218 half of the strays it revised above 0.95 were the same person (147 of 294),
and so were two thirds of the strays the model itself put at 0.5-0.8 (51 of 74). Raising a stray only past 0.9, or
counting one detection at most, kept the oracle gain on seed 215 (431 / 9) but did not mend 215 and 218 with real
evidence (374 / 59 and 331 / 50; 363 / 64 and 320 / 54); only lowering strays did not either (351 / 57, 322 / 49).

Calibrated, the check has little to say. Its log odds were fitted (logistic) on the checks of development seeds 202
and 213 with real evidence (2317 checks, 599 real switches): the first stray probability, the summed distances to
the look before (at most three detections) and their counts, the stray's camera apart from the others. After a
stray the same person's detections in that camera lie 0.55-0.57 from the look before (sd 0.23), another person's
0.72-0.73 (sd 0.16); other cameras' detections barely differ (0.27-0.29 against 0.33-0.41). Log loss: the stray
probability alone, recalibrated, 0.473; with the distances 0.435; the check above 2.15. The fitted check lost on 215
and 218 (362 / 53 -> 356 / 55, 334 / 46 -> 324 / 50; wrong identity per detection 1.07 -> 1.25 %, 1.46 -> 1.77 %)
and is far too timid with oracle evidence (of its revisions at 0.2-0.5, 98 % were real switches). Nor can the
tracker calibrate the check itself from the distances it sees every frame (each detection to its own track's look
and to the other tracks'): with 6 people and real evidence those give 0.25 (sd 0.05) against 0.72 (sd 0.13), a slope
of 46 per unit (the stray model's: 9.6), and the check was as wrong as uncalibrated (215: 375 / 67, 2.08 %). A stray
is reported just when a detection looks unlike its track, and the same person keeps looking unlike it for a while.

Measured on the development scenarios and not adopted: the association acting on its own probabilities. With
oracle evidence nearly every remaining wrong decision at 20 people is an undecided track the tracker moved to another
person and then decided right for that person (seed 215: 7 of 8; 213: 3 of 4), and at each switch the tracker had
reported a stray of 0.65-1.0 (oracle bodies of two people lie only 0.5-0.74 apart in the metric, inside
``appearance_gate``). Refusing a detection whose stray probability is above 0.5 (the track coasts, the detection
starts a track) took the wrong decisions of four oracle seeds from 18 to 10 (215: 438 / 8 -> 407 / 2 right / wrong),
but wrong identity per detection rose on all four (0.26 -> 0.47, 0.42 -> 0.62, 0.00 -> 0.11, 0.14 -> 0.43 %), and
with real evidence it rose too (215, 213, 218: 1.38 -> 1.73, 1.52 -> 3.71, 1.31 -> 2.19 %), recover fell (0.52 ->
0.47, 0.63 -> 0.56, 0.51 -> 0.45) and seed 213 made more wrong decisions (46 -> 59); above 0.9 seed 215 real was
worse on every count (334 / 68, 4.15 %). Exchanging two tracks' detections (or handing one to an unmatched track)
where the likelihood of the exchange is above one half, against the cascade's choice (seed 215): oracle 438 / 8 ->
402 / 9 and 0.26 -> 0.51 %; real 373 / 49, wrong identity per detection even.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.kalman import mahalanobis_sq
from face_reid_master.tracking.records import TrackState

__all__ = ["Associator", "Matches", "StrayModel", "gnn", "stray_probabilities", "swap_probabilities"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]

_TENTATIVE = int(TrackState.TENTATIVE)
_CONFIRMED = int(TrackState.CONFIRMED)
_LOST = int(TrackState.LOST)
_EMPTY = np.zeros(0, dtype=np.intp)


def gnn(cost: FloatArray, feasible: NDArray[np.bool_]) -> tuple[IndexArray, IndexArray]:
    """Global-nearest-neighbour assignment restricted to ``feasible`` pairs; (rows, cols) matched.

    Infeasible pairs cost more than any set of feasible ones, so the result has the maximum number
    of feasible matches and, among those, the minimum total cost (OpenPTrack-style GNN).
    """
    per_row = feasible.sum(axis=1)
    rows_ok = np.flatnonzero(per_row)
    if rows_ok.shape[0] == 0:
        return _EMPTY, _EMPTY
    per_col = feasible.sum(axis=0)
    if per_row.max() == 1 and per_col.max() == 1:  # no two pairs compete: the feasible pairs are the assignment
        return rows_ok, feasible[rows_ok].argmax(axis=1)
    cols_ok = np.flatnonzero(per_col)
    sub = cost[np.ix_(rows_ok, cols_ok)]
    sub_feasible = feasible[np.ix_(rows_ok, cols_ok)]
    lo, hi = sub[sub_feasible].min(), sub[sub_feasible].max()
    big = (hi - lo) * (min(sub.shape) + 1.0) + 1.0
    r, c = linear_sum_assignment(np.where(sub_feasible, sub - lo, big))
    keep = sub_feasible[r, c]
    return rows_ok[r[keep]], cols_ok[c[keep]]


@dataclass(frozen=True, slots=True)
class Matches:
    """``rows`` (tracks) matched to ``cols`` (detections); ``near``: (M,) detections within
    ``min_person_separation_m`` of some track's predicted position; ``swaps``: (track, track, probability that
    this association swapped their people) for the pairs it could have swapped; ``strays``: (track, probability
    that the detection it took is a person it was not following) (tracks as in ``rows``)."""

    rows: IndexArray
    cols: IndexArray
    near: NDArray[np.bool_]
    swaps: tuple[tuple[int, int, float], ...] = ()
    strays: tuple[tuple[int, float], ...] = ()


@dataclass(frozen=True, slots=True)
class _Costs:
    """Per (track, detection): squared Mahalanobis and Euclidean distances, closer than the people's separation,
    inside the metric gate, feasible for pass 1, its cost (negative log-likelihood plus appearance), the position
    part of it, clearly another person and alike by appearance (None: no appearance known)."""

    d2: FloatArray
    dist2: FloatArray
    close: NDArray[np.bool_]
    in_metric_gate: NDArray[np.bool_]
    feasible: NDArray[np.bool_]
    nll: FloatArray
    position_nll: FloatArray
    other_person: NDArray[np.bool_] | None
    looks_alike: NDArray[np.bool_] | None


_MIN_SWAP_PROBABILITY = 1e-3  # pairs less likely swapped than this are not reported
_MIN_STRAY_PROBABILITY = 1e-2  # nor tracks less likely strayed (they would only add rounding to the doubt)


@dataclass(frozen=True, slots=True)
class StrayModel:
    """The log odds that a track's detection is a person it was not following: ``log_odds`` + 0.5 x the pair's
    negative log-likelihood (``d2 + log det S``, S in m^2) + ``appearance_slope`` x (its body-appearance distance
    - ``appearance_distance``); the appearance term is 0 where either has no appearance; + ``occlusion_log_odds``
    for a track hidden from the camera until this frame."""

    log_odds: float
    appearance_slope: float
    appearance_distance: float
    occlusion_log_odds: float = 0.0


def swap_probabilities(nll: FloatArray, possible: NDArray[np.bool_], rows: IndexArray, cols: IndexArray,
                       carries: NDArray[np.bool_]) -> tuple[tuple[int, int, float], ...]:
    """(track, track, p) for every two tracks that could have taken each other's detection: p, the probability
    that the assignment swapped them, is the likelihood of the exchanged pairs over both (``nll``: -2 log
    likelihood per pair, up to a constant; ``possible``: pairs the association could have made). An unmatched
    track that could carry a person (``carries``: not tentative) counts too, against the track that took the
    detection it could have had. Pairs below 1e-3 are left out."""
    out: list[tuple[int, int, float]] = []
    if rows.shape[0]:
        own = nll[rows, cols]
        alt = nll[rows][:, cols]  # alt[k, l]: track rows[k] with detection cols[l]
        ok = possible[rows][:, cols]
        ok &= ok.T.copy()
        np.fill_diagonal(ok, False)
        k, l_ = np.nonzero(np.triu(ok))
        if k.shape[0]:
            delta = alt[k, l_] + alt[l_, k] - own[k] - own[l_]
            p = 1.0 / (1.0 + np.exp(np.minimum(0.5 * delta, 700.0)))
            out.extend((int(rows[a]), int(rows[b]), float(q)) for a, b, q in zip(k, l_, p, strict=True)
                       if q >= _MIN_SWAP_PROBABILITY)
    unmatched = np.ones(nll.shape[0], dtype=bool)
    unmatched[rows] = False
    idle = np.flatnonzero(unmatched & carries)
    if idle.shape[0] and rows.shape[0]:
        j, m = np.nonzero(possible[idle][:, cols])
        if j.shape[0]:
            delta = nll[idle[j], cols[m]] - nll[rows[m], cols[m]]
            p = 1.0 / (1.0 + np.exp(np.minimum(0.5 * delta, 700.0)))
            out.extend((int(rows[b]), int(idle[a]), float(q)) for a, b, q in zip(j, m, p, strict=True)
                       if q >= _MIN_SWAP_PROBABILITY)
    return tuple(out)


def stray_probabilities(model: StrayModel, position_nll: FloatArray, appearance: FloatArray | None, rows: IndexArray,
                        cols: IndexArray, follows: NDArray[np.bool_], hidden: NDArray[np.bool_] | None = None
                        ) -> tuple[tuple[int, float], ...]:
    """(track, p) for the matched tracks that ``follow`` a person (not tentative): p, the probability that the
    detection it took is a person it was not following, by ``model`` (``position_nll``: d2 + log det S per pair;
    ``appearance``: body-appearance distances, NaN = unknown; ``hidden``: tracks hidden from the camera until
    this frame, None = none). Tracks below 1e-2 are left out."""
    keep = follows[rows]
    r, c = rows[keep], cols[keep]
    if r.shape[0] == 0:
        return ()
    log_odds = model.log_odds + 0.5 * position_nll[r, c]
    if hidden is not None:
        log_odds += np.where(hidden[r], model.occlusion_log_odds, 0.0)
    if appearance is not None:
        a = appearance[r, c]
        log_odds += np.where(np.isfinite(a), model.appearance_slope * (a - model.appearance_distance), 0.0)
    p = 1.0 / (1.0 + np.exp(-np.clip(log_odds, -700.0, 700.0)))
    return tuple((int(t), float(q)) for t, q in zip(r, p, strict=True) if q >= _MIN_STRAY_PROBABILITY)


class Associator:
    """The association cascade of one :class:`TrackerConfig` (see the module doc)."""

    def __init__(self, config: TrackerConfig) -> None:
        self._gate = config.gate_mahalanobis_sq
        self._wide_gate = 2.0 * self._gate
        self._gate_m2 = config.max_gate_distance_m**2
        self._sep = config.min_person_separation_m
        self._sep2 = config.min_person_separation_m**2
        self._max_reach = max(config.max_gate_distance_m, config.min_person_separation_m)
        self._max_speed = config.max_speed_mps
        self._coast_after_s = config.coast_after_s
        self._app_gate = config.appearance_gate
        self._app_weight = config.appearance_weight
        self._app_match = config.appearance_match_distance
        self._stray = StrayModel(config.stray_log_odds, config.stray_appearance_slope, config.stray_appearance_distance,
                                 config.stray_occlusion_log_odds)

    def __call__(
        self,
        x_pred: FloatArray,
        P_pred: FloatArray,
        state: NDArray[np.int8],
        t_last: FloatArray,
        z_last: FloatArray,
        z: FloatArray,
        r2: FloatArray,
        stamp: float,
        appearance: FloatArray | None = None,
        alike: NDArray[np.intp] | None = None,
        hidden: NDArray[np.bool_] | None = None,
    ) -> Matches:
        """Associate detections ``z`` (M, 2) with variances ``r2`` (M,) at ``stamp`` to N tracks.

        ``x_pred`` (N, 4) / ``P_pred`` (N, 4, 4): the tracks predicted to ``stamp``; ``state`` (N,)
        their :class:`TrackState`; ``t_last`` (N,) / ``z_last`` (N, 2): stamp and position of each
        track's newest measurement at or before ``stamp`` (its first one if it was born later).
        ``appearance`` (N, M): body-appearance distances (NaN = unknown; None = none known); ``alike`` (M,): how many
        tracks look like each detection (below ``appearance_match_distance``), when these N are not all of them.
        ``hidden`` (N,): tracks hidden from this frame's camera until now (their strays are likelier; None = none).
        """
        c = self._costs(x_pred, P_pred, z, r2, appearance)
        d2, dist2, close, in_metric_gate, feasible, nll = c.d2, c.dist2, c.close, c.in_metric_gate, c.feasible, c.nll
        free_c = np.ones(d2.shape[1], dtype=bool)
        rows_l: list[IndexArray] = []
        cols_l: list[IndexArray] = []
        confirmed = state == _CONFIRMED
        fresh = stamp - t_last < self._coast_after_s
        groups = (
            (confirmed & fresh, True),
            (confirmed & ~fresh, True),
            (state == _LOST, False),
            (state == _TENTATIVE, True),
        )
        for group, second_pass in groups:
            if not group.any() or not free_c.any():
                continue
            r_, c_ = gnn(nll, feasible & group[:, None] & free_c[None, :])
            rows_l.append(r_)
            cols_l.append(c_)
            free_c[c_] = False
            if not second_pass or not free_c.any():
                continue
            group[r_] = False
            left_r = np.flatnonzero(group)
            if left_r.shape[0]:
                near_pred = (close[left_r] | (d2[left_r] <= self._wide_gate)) & in_metric_gate[left_r]
                self._second_pass(left_r, near_pred, None if c.other_person is None else ~c.other_person[left_r],
                                  dist2[left_r], t_last, z_last, z, stamp, free_c, rows_l, cols_l)
        if c.looks_alike is not None and free_c.any():
            assert appearance is not None
            unique = (c.looks_alike.sum(axis=0) if alike is None else alike) == 1  # no other track looks like it
            self._reattach(c.looks_alike, unique, appearance, state, t_last, z_last, z, stamp, free_c, rows_l, cols_l)
        rows = np.concatenate(rows_l) if rows_l else _EMPTY
        cols = np.concatenate(cols_l) if cols_l else _EMPTY
        possible = (close | (d2 <= self._wide_gate)) & in_metric_gate
        if c.other_person is not None:
            possible &= ~c.other_person
        follows = state != _TENTATIVE
        swaps = swap_probabilities(nll, possible, rows, cols, follows)
        strays = stray_probabilities(self._stray, c.position_nll, appearance, rows, cols, follows, hidden)
        return Matches(rows, cols, close.any(axis=0), swaps, strays)

    def _costs(self, x_pred: FloatArray, P_pred: FloatArray, z: FloatArray, r2: FloatArray,
               appearance: FloatArray | None) -> _Costs:
        """The gates and costs of every (track, detection) pair (see :class:`_Costs`)."""
        d2, log_det = mahalanobis_sq(x_pred[:, :2], P_pred[:, :2, :2], z, r2)
        dist2 = ((z[None, :, :] - x_pred[:, None, :2]) ** 2).sum(axis=2)
        in_metric_gate = dist2 <= self._gate_m2
        feasible = (d2 <= self._gate) & in_metric_gate
        nll = position_nll = d2 + log_det
        other_person = looks_alike = None
        if appearance is not None:
            known = np.isfinite(appearance)
            other_person = known & (appearance > self._app_gate)  # NaN compares False: unknown stays possible
            feasible &= ~other_person
            nll = nll + self._app_weight * np.where(known, appearance, self._app_match)
            looks_alike = known & (appearance < self._app_match)
        return _Costs(d2, dist2, dist2 < self._sep2, in_metric_gate, feasible, nll, position_nll, other_person,
                      looks_alike)

    def _second_pass(
        self, left_r: IndexArray, near_pred: NDArray[np.bool_], same_looks: NDArray[np.bool_] | None,
        dist2: FloatArray, t_last: FloatArray, z_last: FloatArray, z: FloatArray, stamp: float,
        free_c: NDArray[np.bool_], rows_l: list[IndexArray], cols_l: list[IndexArray],
    ) -> None:
        """Pass 2 for a group's tracks ``left_r`` left unmatched: a free detection near the prediction
        (``near_pred``) or within walking reach of the track's last detection, and not clearly someone else by
        its looks (``same_looks``; None = unknown), nearest first."""
        reach = np.minimum(self._sep + self._max_speed * np.maximum(stamp - t_last[left_r], 0.0), self._max_reach)
        dist2_last = ((z[None, :, :] - z_last[left_r][:, None, :]) ** 2).sum(axis=2)
        ok2 = (near_pred | (dist2_last < reach[:, None] ** 2)) & free_c[None, :]
        if same_looks is not None:
            ok2 &= same_looks
        if ok2.any():
            r_, c_ = gnn(np.minimum(dist2, dist2_last), ok2)
            rows_l.append(left_r[r_])
            cols_l.append(c_)
            free_c[c_] = False

    def _reattach(
        self, looks_alike: NDArray[np.bool_], unique: NDArray[np.bool_], appearance: FloatArray,
        state: NDArray[np.int8], t_last: FloatArray, z_last: FloatArray, z: FloatArray, stamp: float,
        free_c: NDArray[np.bool_], rows_l: list[IndexArray], cols_l: list[IndexArray],
    ) -> None:
        """Pass 3: LOST tracks still unmatched take a free detection that looks like them and like no other
        track (``unique``), within walking reach of their last detection (no position gate: a hidden person reappears
        where the prediction is not)."""
        taken = np.zeros(state.shape[0], dtype=bool)
        for r_ in rows_l:
            taken[r_] = True
        lost = np.flatnonzero((state == _LOST) & ~taken)
        if lost.shape[0] == 0:
            return
        reach = self._sep + self._max_speed * np.maximum(stamp - t_last[lost], 0.0)
        dist2_last = ((z[None, :, :] - z_last[lost][:, None, :]) ** 2).sum(axis=2)
        ok = looks_alike[lost] & unique[None, :] & (dist2_last < reach[:, None] ** 2) & free_c[None, :]
        if ok.any():
            r_, c_ = gnn(appearance[lost], ok)
            rows_l.append(lost[r_])
            cols_l.append(c_)
            free_c[c_] = False
