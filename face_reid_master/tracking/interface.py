"""What the master asks of a multi-camera tracker: the interface :class:`~face_reid_master.core.master.MasterCore`
is given, and the two kinds of track id.

The master core drives a tracker as a component (the shape of Stone Soup's injected trackers and norfair's
``Tracker.update``): one :meth:`MultiCameraTracker.update_frame` per camera frame with that frame's detections and
stamp, returning what happened (associations, created, lost, recovered and deleted tracks); :meth:`advance`
when no frame arrives; :meth:`snapshots` to publish. Swapping the tracker is writing a class of this shape and
handing it to ``MasterCore(tracker=...)`` (the default is :class:`~face_reid_master.tracking.tracker.Tracker`);
its configuration is read in one place, its own ``config``, which the core then holds as ``config.tracker``.

Two ids name a track and must not be mixed: the tracker's :data:`TrackerId` (stable while the tracker follows
the track; what the identity layer keys its evidence by) and the master's published ``PublicId``
(:mod:`face_reid_master.core.records`), which changes when a swap splits the track.
"""

from __future__ import annotations

from typing import NewType, Protocol

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.stamp_admission import ClockVerdict, StampClock
from face_reid_master.tracking.config import TrackerConfig
from face_reid_master.tracking.records import TrackerStats, TrackSnapshot, UpdateResult

__all__ = ["FrameDetections", "MultiCameraTracker", "TrackerId"]

TrackerId = NewType("TrackerId", int)  # a track as the tracker names it (never reused)


class FrameDetections(Protocol):
    """One camera frame's valid detections on the ground plane (validated by the caller), row i = detection i."""

    positions: NDArray[np.float64]  # (N, 2) world x, y (m)
    stds: NDArray[np.float64]  # (N,) isotropic position spread (m), > 0
    heights: NDArray[np.float64]  # (N,) head height (m), NaN = unknown
    appearance: NDArray[np.float32] | None  # (N, r) body embeddings (NaN rows: not described); None: none


class MultiCameraTracker(Protocol):
    """A multi-camera people tracker as the master core uses it (see the module doc)."""

    @property
    def config(self) -> TrackerConfig:
        """Its configuration: the one place the timeouts and the late-frame window are read from."""

    @property
    def stats(self) -> TrackerStats:
        """Its counters (a copy)."""

    @property
    def clock(self) -> StampClock:
        """Its clock (the newest applied stamp), which the core's stamp gate judges each frame against before
        :meth:`update_frame` (the verdict is handed over as ``admitted``)."""

    def update_frame(self, detections: FrameDetections, stamp_s: float, camera_id: str, *,
                     resync_backward: bool = True, admitted: ClockVerdict | None = None) -> UpdateResult:
        """Fuse one camera frame; associations are (TrackerId, detection row); lost / recovered / deleted ids.
        ``admitted``: the stamp's verdict already given by the core's stamp gate (not judged again)."""

    def advance(self, stamp_s: float) -> UpdateResult:
        """Move time to ``stamp_s`` without detections (timeouts: lost / deleted tracks)."""

    def reset(self) -> tuple[int, ...]:
        """Delete every track and forget the clock; the deleted ids."""

    def reserve_id(self) -> int:
        """An id no track will ever be given (a split track's new published id)."""

    def snapshots(self, at_s: float | None = None, include_tentative: bool = True) -> list[TrackSnapshot]:
        """The live tracks, sorted by id, predicted to ``at_s`` (default: the clock)."""

