"""Evidence of correlated frames: one glance of a camera at a face counts as a few observations, not as many.

The frames of one glance (one camera seeing one track's face, no gap longer than ``gap_s``) show the same
pose, light and blur, so their embeddings' errors are strongly correlated: counted as independent (the
paper), a glance that happens to look like someone else outvotes everything else within a second. With
a pairwise correlation rho between a glance's n observations, their evidence is worth
``n_eff(n) = n / (1 + (n - 1) rho)`` independent ones (the design effect of a cluster sample), so a glance
contributes ``n_eff(n)`` times the mean log-likelihood ratio of its frames. rho = 0 is the paper's
independent evidence; rho = 1 counts a glance once, however long.

The Bayes table accumulates evidence multiplicatively, so a glance's contribution is applied as the change
since its last update; per-column counts keep faces that joined face_list mid-glance consistent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.checks import check_real

__all__ = ["GlanceEvidence"]

FloatArray = npt.NDArray[np.float64]


@dataclass
class _Glance:
    """One open glance: its last stamp and, per table column, observations, summed and applied evidence."""

    last_s: float
    count: FloatArray
    total: FloatArray
    applied: FloatArray


class GlanceEvidence:
    """Turns per-observation log-likelihood ratios into per-glance contributions (see the module doc).

    ``gap_s``: a camera's observations of a track further apart than this (s) start a new glance (0 = every
    observation is its own glance, i.e. independent evidence).  ``correlation``: rho in [0, 1], the
    correlation assumed between the observations of one glance (0 = independent, the paper).
    """

    def __init__(self, gap_s: float = 1.0, correlation: float = 0.0) -> None:
        self.gap_s = check_real("gap_s", gap_s, 0.0, 3600.0)
        self.correlation = check_real("correlation", correlation, 0.0, 1.0)
        self._glances: dict[int, dict[str, _Glance]] = {}
        self._columns = 1

    @property
    def independent(self) -> bool:
        """True when every observation counts fully (rho = 0 or no glances): the paper's evidence."""
        return self.correlation == 0.0 or self.gap_s == 0.0

    def effective_count(self, n: FloatArray) -> FloatArray:
        """n_eff(n) = n / (1 + (n - 1) rho): what n correlated observations are worth."""
        n = np.asarray(n, dtype=np.float64)
        return n / (1.0 + np.maximum(n - 1.0, 0.0) * self.correlation)

    def open_glances(self, track_id: int) -> int:
        """Glances of a track currently held (one per camera at most)."""
        return len(self._glances.get(track_id, {}))

    def update(self, track_id: int, source: str, stamp_s: float, log_ratio: FloatArray) -> FloatArray:
        """Change of the track's log-evidence (one value per table column) from ``log_ratio`` (k, columns):
        the per-observation evidence of k observations of ``track_id`` seen by ``source`` at ``stamp_s``."""
        if log_ratio.shape[1] != self._columns:
            raise ValueError(f"log_ratio has {log_ratio.shape[1]} columns, the table {self._columns}")
        if self.independent:
            return log_ratio.sum(axis=0)
        by_source = self._glances.setdefault(track_id, {})
        g = by_source.get(source)
        if g is None or abs(stamp_s - g.last_s) > self.gap_s:
            zeros = np.zeros(self._columns)
            g = by_source[source] = _Glance(stamp_s, zeros.copy(), zeros.copy(), zeros)
        g.last_s = max(g.last_s, stamp_s)
        g.count += log_ratio.shape[0]
        g.total += log_ratio.sum(axis=0)
        contribution = self.effective_count(g.count) * g.total / np.maximum(g.count, 1.0)
        delta = contribution - g.applied
        g.applied = contribution
        return delta

    def add_column(self) -> None:
        """A face joined face_list (a new last column): no evidence for it in any open glance yet."""
        self._columns += 1
        for by_source in self._glances.values():
            for g in by_source.values():
                g.count, g.total, g.applied = (np.append(a, 0.0) for a in (g.count, g.total, g.applied))

    def remove_columns(self, columns: list[int]) -> None:
        """Table columns (1-based: column 0 is "new person") left the table."""
        self._columns -= len(columns)
        for by_source in self._glances.values():
            for g in by_source.values():
                g.count, g.total, g.applied = (np.delete(a, columns) for a in (g.count, g.total, g.applied))

    def forget_track(self, track_id: int) -> None:
        """The track left the table (identified or dead): its glances go."""
        self._glances.pop(track_id, None)
