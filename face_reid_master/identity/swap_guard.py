"""Our guard against tracker swaps: an identified track's face learns only what looks like its person.

When the tracker swaps two people, an identified track goes on with someone else. An observation farther
than ``gate_distance`` from every stored feature of the track's face is therefore not learned (counted in
``stats.observations_not_learned_inconsistent``), so the face does not absorb the other person; and once the
track's last ``release_after`` observations were all beyond the gate, the track has been swapped: the
identity manager gives its face back to face_list (a SWAPPED event) and classifies the track afresh from the
run's first observation on. ``gate_distance`` None = the paper (everything is learned); ``release_after`` 0 =
never released. Releasing after one inconsistent observation instead of three (development, 6 people) changed
nothing with oracle evidence (the tracker switches that carry an identity there show no face before they end) and
with real evidence made more wrong decisions (62 -> 64 over nine seeds).
"""

from __future__ import annotations

from collections.abc import Callable
from itertools import accumulate

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.entries import Chunk, TrackRecord
from face_reid_master.identity.feature_bank import FeatureBank
from face_reid_master.identity.records import IdentityStats

__all__ = ["SwapGuard"]

F32Array = npt.NDArray[np.float32]


class SwapGuard:
    """The feature gate and the swap release (see the module doc) over the manager's feature ``bank``."""

    def __init__(self, gate_distance: float | None, release_after: int, bank: FeatureBank,
                 stats: IdentityStats) -> None:
        if release_after and gate_distance is None:
            raise ValueError("release_after_inconsistent needs feature_gate_distance (it counts the observations "
                             "beyond it); 0 = never release")
        self.gate_distance = gate_distance
        self.release_after = release_after
        self.bank = bank
        self.stats = stats

    def consistent(self, rows: dict[int, F32Array], face_slot: Callable[[int], int | None]
                   ) -> dict[int, npt.NDArray[np.bool_]]:
        """For each identified track's new observations (``face_slot``: track -> its face's bank slot, None when
        unidentified): which lie within ``gate_distance`` of a stored feature of its face (all tracks in one
        batched product; {} when the gate is off)."""
        gate = self.gate_distance
        if gate is None:
            return {}
        slot_of = {tid: slot for tid in rows if (slot := face_slot(tid)) is not None}
        ident = list(slot_of)
        if not ident:
            return {}
        obs = np.concatenate([rows[tid] for tid in ident])
        counts = [rows[tid].shape[0] for tid in ident]
        slots = np.repeat(np.array([slot_of[tid] for tid in ident], np.intp), counts)
        keep = self.bank.own_min_distances(obs, slots) <= gate
        self.stats.observations_not_learned_inconsistent += int(keep.size - np.count_nonzero(keep))
        ends = list(accumulate(counts))
        return {tid: keep[end - n:end] for tid, n, end in zip(ident, counts, ends, strict=True)}

    def swapped(self, track: TrackRecord, chunks: list[Chunk], keep: npt.NDArray[np.bool_]) -> list[Chunk] | None:
        """Follow the identified track's run of inconsistent observations; once it is
        ``release_after`` long, the chunks from the run's start on (None: no swap)."""
        k = self.release_after
        if not k:
            return None
        if keep.size and keep.all():  # every observation consistent: any run is over
            track.inconsistent.clear()
            return None
        start = 0
        for c in chunks:
            n = c.embeddings.shape[0]
            ok = keep[start:start + n]
            start += n
            if ok.all():
                track.inconsistent.clear()
                continue
            last_ok = int(np.flatnonzero(ok)[-1]) if ok.any() else -1
            if last_ok >= 0:
                track.inconsistent.clear()
            rows = slice(last_ok + 1, None)
            track.inconsistent.append(Chunk(c.embeddings[rows], None if c.eye_px is None else c.eye_px[rows],
                                            c.stamp_s, c.source))
        run = track.inconsistent
        if sum(c.embeddings.shape[0] for c in run) < k:
            return None
        track.inconsistent = []
        return run
