"""Bayesian face classification of Koide et al. 2017 (III-E): posterior table + Sinkhorn + decision.

Posterior table (paper Fig. 5, OpenPTrack ``FaceRecognizerBayes``)::

                 col 0 "new person"   col j = learned face available for assignment (face_list)
    row 0         (unused, 0)          p(x_0j): face j's person is not tracked (slack)
    row i         p(x_i0)              p(x_ij): unassigned track i is face j

Likelihood, per face observation y of track i with eq. 4 distances d_ik to every face k of face_list:
under x_ij (j >= 1) d_ij is a positive pair and every other d_ik a negative one; under x_i0 all are
negative; c (``new_person_scale_c``) scales the "new person" hypothesis::

    p(y | x_ij) = N_p(d_ij) * prod_{k != j} N_n(d_ik)          p(y | x_i0) = c * prod_k N_n(d_ik)

Rows are renormalised, so dividing row i by prod_k N_n(d_ik) changes nothing and leaves the ratio form
implemented: column j *= N_p(d_ij) / N_n(d_ij), column 0 *= c.  That is the paper's eq. 5 multiplied over
all learned faces (OpenPTrack applies c once per learned face, this once per observation: identical for
the paper's c = 1), at O(M) instead of O(M^2) per observation.  Evidence is summed in log space and
rescaled by the row maximum, so nothing under/overflows.  Then Sinkhorn normalisation
(:mod:`~face_reid_master.identity.sinkhorn`), clamping to [clamp, 1 - clamp], and a decision when
p(x_ij) > posterior_threshold and the track has >= min_observations compared with j.  Ours: a person split
over learned faces that are alike is decided on their summed posterior (:mod:`~face_reid_master.identity.alike_group`).

Measured on the development scenarios and not adopted: a stricter decision. At 20 people with real evidence, face
decisions at posteriors 0.95-0.99 are about a quarter wrong, those above 0.99 a few per cent, and new-person
decisions below 0.999 mostly wrong (a returning person whose learned face the embedder missed), so a filter of the
decisions taken promises far fewer wrong ones at 0.99. Run as the master's threshold, it does the opposite:
``posterior_threshold`` 0.99 took seed 215 from 355 / 53 right / wrong to 346 / 60 (wrong identity per detection
1.00 -> 3.50 %) and seed 218 from 327 / 45 to 269 / 95 (1.46 -> 7.77 %). The posterior of a track that shows
a look-alike's face keeps rising with more views of it, so a wrong decision is taken later, not avoided, and at
0.99 it also teaches its face (``learn_confidence``): the pollution cascades. A separate threshold of 0.995 for
new-person decisions alone (6 people, nine seeds: 275 / 62 -> 274 / 64, 1.08 -> 2.02 %) only delayed them: the
returning people whose face was missed reached 0.995 too. Counting one camera's face observations of an undecided
track as evidence at most every 0.5 s (all still buffered) halved the wrong
decisions but moved along the frontier, not beyond it, at 20 people (215: 355 / 53 -> 243 / 26, recover 0.51 ->
0.41; 218: 327 / 45 -> 215 / 22, 0.51 -> 0.42; main's own decisions at posterior >= 0.98-0.99 give the same) and
lost recover on oracle evidence (6 people, five seeds: 155 / 3 -> 130 / 2, recover 0.79 -> 0.68); with 6 people
and real evidence it was beyond it (nine seeds: 275 / 62 -> 239 / 26, recover 0.59 both). Every 0.2 s: 6 people
real 250 / 50, recover 0.57; oracle 148 / 3, 0.76.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_int, check_real
from face_reid_master.identity.algorithm1 import IdentityManagerBase
from face_reid_master.identity.alike_group import alike_group
from face_reid_master.identity.entries import TrackRecord
from face_reid_master.identity.likelihood import LikelihoodModel
from face_reid_master.identity.sinkhorn import sinkhorn_with_slack
from face_reid_master.identity.size_likelihood import FaceLikelihood, default_face_likelihood

__all__ = ["BayesIdentityManager"]

FloatArray = npt.NDArray[np.float64]
F32Array = npt.NDArray[np.float32]


class BayesIdentityManager(IdentityManagerBase):
    """Algorithm 1 with the paper's Bayesian face classification (posterior table + Sinkhorn).

    Parameters (OpenPTrack's values in brackets): ``prior_probability`` of new table cells [0.1],
    ``posterior_threshold`` to decide [0.95], ``min_observations`` compared with the decided column [3],
    ``clamp_probability`` applied after normalisation [1e-3], ``sinkhorn_tolerance`` on row sums [1e-3]
    and ``sinkhorn_max_iterations`` [10]; ``sinkhorn_solver`` "newton" (same fixed point in a few
    iterations) or "sinkhorn" (the paper's alternations). Ours: ``learn_confidence`` [0], the posterior a face
    decision needs to teach its face the track's face and body embeddings (below it the track is identified and
    teaches nothing). The remaining arguments are those of :class:`IdentityManagerBase`.
    """

    def __init__(
        self,
        likelihood: LikelihoodModel | FaceLikelihood | None = None,
        *,
        prior_probability: float = 0.1,
        posterior_threshold: float = 0.95,
        min_observations: int = 3,
        clamp_probability: float = 1e-3,
        sinkhorn_tolerance: float = 1e-6,
        sinkhorn_max_iterations: int = 100,
        sinkhorn_solver: str = "newton",
        learn_confidence: float = 0.0,
        **bank_args: Any,
    ) -> None:
        super().__init__(**bank_args)  # embedding_dim, max_features_per_face, ...: see IdentityManagerBase
        if likelihood is None:
            likelihood = default_face_likelihood()
        if isinstance(likelihood, LikelihoodModel):
            likelihood = FaceLikelihood(likelihood)
        if not isinstance(likelihood, FaceLikelihood):
            raise ValueError(f"likelihood must be a FaceLikelihood or LikelihoodModel, got {type(likelihood).__name__}")
        self.likelihood = likelihood
        self.prior_probability = check_real(
            "prior_probability", prior_probability, 0.0, 1.0, low_open=True, high_open=True
        )
        self.clamp_probability = check_real("clamp_probability", clamp_probability, 0.0, 0.5, high_open=True)
        self.posterior_threshold = check_real(
            "posterior_threshold", posterior_threshold, 0.5, 1.0 - self.clamp_probability,
            low_open=True, high_open=True,
        )
        self.min_observations = check_int("min_observations", min_observations, 1)
        self.learn_confidence = check_real("learn_confidence", learn_confidence, 0.0, 1.0)
        self.sinkhorn_tolerance = check_real(
            "sinkhorn_tolerance", sinkhorn_tolerance, 0.0, 1.0, low_open=True, high_open=True
        )
        self.sinkhorn_max_iterations = check_int("sinkhorn_max_iterations", sinkhorn_max_iterations, 1)
        if sinkhorn_solver not in ("newton", "sinkhorn"):
            raise ValueError(f"sinkhorn_solver must be 'newton' or 'sinkhorn', got {sinkhorn_solver!r}")
        self.sinkhorn_solver = sinkhorn_solver
        self._log_c = math.log(self.likelihood.new_person_scale_c)
        self._table = np.zeros((1, 1))  # row 0 / column 0 slack; P[0, 0] unused (0)
        self._counts = np.zeros((1, 1), dtype=np.int64)
        self._rows: list[TrackRecord] = []  # the tracks of rows 1..N (each record knows its bayes_row)
        self._dirty = False
        self._converged = True

    # ------------------------------------------------------------------------------ queries
    def posterior_table(self) -> tuple[FloatArray, list[int], list[int]]:
        """(copy of the table, track ids of rows 1..N, face ids of columns 1..M)."""
        return self._table.copy(), [t.track_id for t in self._rows], list(self.faces.available)

    @property
    def is_normalised(self) -> bool:
        """True when the stored table is the (clamped) result of a converged Sinkhorn normalisation."""
        return not self._dirty and self._converged

    def observation_counts(self) -> npt.NDArray[np.int64]:
        """Copy of the per-cell observation counts (same layout as the table)."""
        return self._counts.copy()

    def posterior_of(self, track_id: int) -> dict[int, float]:
        track = self.tracks.entries.get(track_id)
        row = 0 if track is None else track.bayes_row
        if not row:
            return {}
        p = self._table[row]
        out = {0: float(p[0])}
        out.update({fid: float(v) for fid, v in zip(self.faces.available, p[1:], strict=True)})
        return out

    def _current_confidence(self, track: TrackRecord) -> float:
        row = track.bayes_row
        return float(self._table[row].max()) if row else 0.0

    # ------------------------------------------------------------------------------ table structure
    def _add_row(self, track: TrackRecord) -> None:
        m1 = self._table.shape[1]
        self._table = np.vstack([self._table, np.full((1, m1), self.prior_probability)])
        self._counts = np.vstack([self._counts, np.zeros((1, m1), dtype=np.int64)])
        self._rows.append(track)
        track.bayes_row = len(self._rows)
        self._dirty = True

    def _remove_row(self, track: TrackRecord) -> None:
        row = track.bayes_row
        if not row:
            return
        self._table = np.delete(self._table, row, axis=0)
        self._counts = np.delete(self._counts, row, axis=0)
        del self._rows[row - 1]
        track.bayes_row = 0
        for i in range(row - 1, len(self._rows)):
            self._rows[i].bayes_row = i + 1
        self._dirty = True

    def _on_face_available(self, face_id: int) -> None:
        n1 = self._table.shape[0]
        self._table = np.hstack([self._table, np.full((n1, 1), self.prior_probability)])
        self._counts = np.hstack([self._counts, np.zeros((n1, 1), dtype=np.int64)])
        self._dirty = True

    def _on_faces_unavailable(self, column_indices: list[int]) -> None:
        cols = [c + 1 for c in column_indices]
        self._table = np.delete(self._table, cols, axis=1)
        self._counts = np.delete(self._counts, cols, axis=1)
        self._dirty = True

    def _on_track_identified(self, track: TrackRecord) -> None:
        self._remove_row(track)

    def _on_track_forgotten(self, track: TrackRecord) -> None:
        self._remove_row(track)

    # ------------------------------------------------------------------------------ inference
    def _ingest_unassigned(self, track_ids: list[int], observations: list[F32Array],
                           eye_px: list[FloatArray]) -> None:
        records = [self.tracks.entries[tid] for tid in track_ids]
        for track in records:
            if not track.bayes_row:
                self._add_row(track)
        obs = np.concatenate(observations) if len(observations) > 1 else observations[0]
        sizes = np.array([o.shape[0] for o in observations])
        rows = np.array([t.bayes_row for t in records])
        m = len(self.faces.available)
        log_ev = np.empty((len(track_ids), m + 1))
        log_ev[:, 0] = sizes * self._log_c  # column 0: c per observation (ratio form, see module doc)
        lr = np.zeros((obs.shape[0], 0))
        if m:
            d = self.faces.distances(obs)
            n_feats = self._bank.count[self.faces.slots].astype(np.float64)[None, :]  # K of eq. 4
            model = self.likelihood
            buckets = model.bucket_of(eye_px[0] if len(eye_px) == 1 else np.concatenate(eye_px)) \
                if model.conditioned else None
            # faces outside the search shortlist (inf) get the weakest evidence: clipped to distance d_hi
            lr = model.log_ratio_rows(d, n_feats, buckets)
        if m and len(sizes) == obs.shape[0]:
            log_ev[:, 1:] = lr
        elif m:
            starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            log_ev[:, 1:] = np.add.reduceat(lr, starts, axis=0)
        log_ev -= log_ev.max(axis=1, keepdims=True)  # per-row rescale: exact after row normalisation
        self._table[rows] *= np.exp(log_ev)
        self._counts[rows] += sizes[:, None]
        self._dirty = True

    def _normalise(self) -> None:
        if len(self._rows) == 0:
            self._dirty = False
            self._converged = True
            return
        res = sinkhorn_with_slack(
            self._table, self.sinkhorn_tolerance, self.sinkhorn_max_iterations, self.sinkhorn_solver
        )
        self.stats.sinkhorn_runs += 1
        self.stats.last_sinkhorn_iterations = res.iterations
        self._converged = res.converged
        if not res.converged:
            self.stats.sinkhorn_not_converged += 1
        table = np.clip(res.table, self.clamp_probability, 1.0 - self.clamp_probability)
        table[0, 0] = 0.0
        self._table = table
        self._dirty = False

    def _decide(self) -> list[tuple[int, int, float]]:
        if self._dirty:
            self._normalise()
        if not self._rows:
            return []
        body = self._table[1:]
        best = np.argmax(body, axis=1)
        idx = np.arange(len(self._rows))
        p = body[idx, best]
        counts = self._counts[1:]
        thr = self.posterior_threshold
        decisions, taken = [], set()
        for r in np.flatnonzero((p > thr) & (counts[idx, best] >= self.min_observations)):
            face = self.faces.available[best[r] - 1] if best[r] else 0
            taken.add(face)
            decisions.append((self._rows[r].track_id, face, float(p[r])))
        split = (p <= thr) & (best > 0) & (body[:, 0] < 1.0 - thr)  # a person split over faces: their sum may decide
        for r in np.flatnonzero(split):
            cols = np.flatnonzero(body[r] > (1.0 - thr) / body.shape[1])  # the others cannot change the verdict
            post = {(self.faces.available[c - 1] if c else 0): float(body[r, c]) for c in cols}
            column = {f: int(c) for f, c in zip(post, cols, strict=True)}
            face, total = alike_group(post, self.faces.available[best[r] - 1], post.keys(), self._faces_alike, thr)
            if total > thr and face not in taken and counts[r, column[face]] >= self.min_observations:
                taken.add(face)
                decisions.append((self._rows[r].track_id, face, min(total, 1.0 - self.clamp_probability)))
        return decisions
