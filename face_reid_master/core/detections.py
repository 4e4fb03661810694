"""A camera frame's people as the tracker and the identity layer take them: the one place they are validated.

Positions and their spread go to the tracker; a face embedding is used only when it is of the master's
embedder space, of the right length, finite, of a plausible norm, not degenerate and of sufficient quality;
a body descriptor only when well formed and of the body metric's projection (embedded with it for the
tracker and the body evidence). Everything refused is counted; a camera of another space is said once.
One vectorised pass: it runs for every person of every camera frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.checks import is_finite_number, shown
from face_reid_camera.common.embedding_spaces import extract_space, plausible_norms, space_dim
from face_reid_master.body.metric_file import BodyMetricModel
from face_reid_master.core.config import MasterConfig
from face_reid_master.core.records import MasterStats
from face_reid_master.identity.size_likelihood import FaceLikelihood
from face_reid_master.records import CameraFrameRecord

__all__ = ["DetectionReader", "Detections", "degenerate_rows"]

_MAX_NOTICED_CAMERAS = 1024  # cameras whose unusable spaces are remembered (hostile ids cannot grow it)



def _constant_rows(rows: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Finite rows (k, dim) whose values are all equal (all zero included): no embedder produces them."""
    return np.ptp(rows, axis=1) <= 1e-6 * np.abs(rows).max(axis=1)


def degenerate_rows(rows: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Rows (k, dim) no embedder produces: a NaN / Inf, or all values equal (zero norm, a constant vector): such a
    vector is as near to every face as to any other, so it would match, or teach, anyone."""
    rows = np.asarray(rows)
    if not rows.shape[1]:
        return np.ones(len(rows), dtype=bool)
    finite = np.isfinite(rows).all(axis=1)
    return ~finite | _constant_rows(np.where(finite[:, None], rows, 0.0))


def _first_notice(seen: dict[str, str], camera_id: str, space: str) -> bool:
    """True the first time ``camera_id`` sends ``space`` (cut to 64 characters); remembers at most
    _MAX_NOTICED_CAMERAS cameras, the least recently noticed forgotten first."""
    camera_id, space = camera_id[:256], space[:64]
    if seen.get(camera_id) == space:
        return False
    seen.pop(camera_id, None)
    seen[camera_id] = space
    while len(seen) > _MAX_NOTICED_CAMERAS:
        del seen[next(iter(seen))]
    return True


@dataclass
class Detections:
    """A frame's valid detections as tracker input, with their usable faces and bodies."""

    positions: NDArray[np.float64]  # (N, 2) world x, y (m)
    stds: NDArray[np.float64]  # (N,) position spread (m)
    heights: NDArray[np.float64]  # (N,) head height (m)
    appearance: NDArray[np.float32] | None  # (N, r) body embeddings, NaN rows for undescribed bodies; None: none
    faces: dict[int, tuple[NDArray[np.float32], NDArray[np.float64]]] = field(default_factory=dict)  # detection ->
    # (face embedding in the likelihood's scaled space, [eye distance px; 0 = unknown])
    person_index: list[int] = field(default_factory=list)  # detection -> index in frame.people


class DetectionReader:
    """Validates a frame's people (see the module doc); counts into ``stats``, appends notices to ``notices``."""

    def __init__(self, config: MasterConfig, stats: MasterStats, likelihood: FaceLikelihood,
                 body_metric: BodyMetricModel | None, notices: list[str]) -> None:
        self.config = config
        self.stats = stats
        self.likelihood = likelihood
        self.body_metric = body_metric
        self.body_fused = None if body_metric is None else body_metric.features["fused"]  # bodies embedded with it
        self.notices = notices
        self._dim = space_dim(config.embedding_space)
        self._space_noticed: dict[str, str] = {}  # camera id -> the unusable face space it was last logged for
        self._body_space_noticed: dict[str, str] = {}  # camera id -> the unusable body space it was logged for

    def read(self, frame: CameraFrameRecord) -> Detections:
        """The frame's valid detections, their usable faces and bodies (see :class:`Detections`)."""
        cfg, st = self.config, self.stats
        people = frame.people
        n = len(people)
        st.detections_received += n
        if n == 0:
            return Detections(np.zeros((0, 2)), np.zeros(0), np.zeros(0), None)
        xy = np.full((n, 2), np.nan)
        std = np.full(n, np.nan)
        for i, person in enumerate(people):
            pos = np.asarray(person.position_world, dtype=np.float64).reshape(-1)
            if pos.size >= 2:
                xy[i] = pos[:2]
            std[i] = person.position_std_m
        valid = np.isfinite(xy).all(axis=1) & np.isfinite(std) & (std > 0)
        st.detections_rejected_position += int(n - np.count_nonzero(valid))
        person_index = np.flatnonzero(valid).tolist()
        out = Detections(
            xy[valid],
            std[valid],
            np.array([float(people[i].height_m) for i in person_index], dtype=np.float64),
            self._appearance([people[i].body for i in person_index], frame.camera_id),
            person_index=person_index,
        )
        with_face = [
            (k, i) for k, i in enumerate(person_index)
            if people[i].embedding is not None and np.size(people[i].embedding) > 0
        ]
        if not with_face:
            return out
        vectors = [(k, i, self._in_space(people[i], frame.camera_id)) for k, i in with_face]
        in_space = [(k, i, v) for k, i, v in vectors if v is not None]
        st.embeddings_rejected_space += len(vectors) - len(in_space)
        good_len = [(k, i, v) for k, i, v in in_space if v.size == self._dim]
        st.embeddings_rejected_length += len(in_space) - len(good_len)
        if not good_len:
            return out
        stacked = np.array([v for _, _, v in good_len])  # same-length rows (checked above)
        finite = np.isfinite(stacked).all(axis=1)
        plausible = finite & plausible_norms(stacked, cfg.embedding_space)  # NaN / Inf lengths fail the range
        st.embeddings_rejected_norm += int(np.count_nonzero(finite & ~plausible))
        with np.errstate(invalid="ignore"):  # NaN rows are not plausible already
            constant = plausible & _constant_rows(stacked)
        st.embeddings_rejected_degenerate += int(np.count_nonzero(constant))
        plausible &= ~constant
        stacked = self.likelihood.scale(stacked)
        quality = np.array([people[i].face_quality for _, i, _ in good_len], dtype=np.float64)
        good_quality = quality >= cfg.min_face_quality
        st.embeddings_rejected_nonfinite += int(np.count_nonzero(~finite))
        st.embeddings_skipped_quality += int(np.count_nonzero(plausible & ~good_quality))
        for row in np.flatnonzero(plausible & good_quality):
            eye = float(people[good_len[row][1]].face_eye_distance_px)
            out.faces[good_len[row][0]] = (stacked[row], np.array([eye if math.isfinite(eye) and eye > 0 else 0.0]))
        return out

    def _appearance(self, bodies: list[Any], camera_id: str) -> NDArray[np.float32] | None:
        """Count the detections' body fields (cameras without bodies send none) and embed the well-formed
        descriptors of the body metric's space for the tracker: (N, r), NaN rows for the others; None when
        none is usable (or appearance tracking is off). One pass over the frame's bodies, one GEMM."""
        st, metric = self.stats, self.body_metric
        present = [(k, b) for k, b in enumerate(bodies) if b is not None]
        if not present:
            return None
        usable: list[int] = []  # of the metric's space: checked for NaN / Inf together below
        rows: list[NDArray[np.float32]] = []
        for k, body in present:
            descriptor = np.asarray(body.descriptor, dtype=np.float32)
            visible = body.visible_fraction
            if descriptor.ndim != 1 or not is_finite_number(visible) or not 0.0 <= float(visible) <= 1.0:
                st.bodies_rejected_malformed += 1
            elif metric is not None and descriptor.size and body.space == metric.space \
                    and descriptor.size == metric.length:
                usable.append(k)
                rows.append(descriptor)
            elif not np.isfinite(descriptor).all():
                st.bodies_rejected_malformed += 1
            else:
                st.bodies_received += 1
                if metric is not None and descriptor.size:
                    self._other_body_space(camera_id, str(body.space))
        if not rows:
            return None
        stacked = np.stack(rows)
        finite = np.isfinite(stacked).all(axis=1)
        st.bodies_received += int(np.count_nonzero(finite))
        st.bodies_rejected_malformed += int(np.count_nonzero(~finite))
        if not finite.any():
            return None
        assert metric is not None
        assert self.body_fused is not None
        embedded = self.body_fused.embed(stacked[finite])
        out = np.full((len(bodies), embedded.shape[1]), np.nan, dtype=np.float32)
        out[np.asarray(usable)[finite]] = embedded
        return out

    def _other_body_space(self, camera_id: str, space: str) -> None:
        """Count a descriptor of another projection than the body metric's; say it once per camera and space."""
        assert self.body_metric is not None
        self.stats.bodies_rejected_space += 1
        space = space[:64]
        if _first_notice(self._body_space_noticed, camera_id, space):
            self.notices.append(f"camera {shown(camera_id, 64)} sends body descriptors of space {space!r}, the body "
                                 "metric "
                                 f"compares {self.body_metric.space!r}: its bodies are not used for tracking (see the "
                                 "cameras' body_projection_path and face-reid-fit-body)")

    def _in_space(self, person: Any, camera_id: str) -> NDArray[np.float32] | None:
        """The person's embedding in the master's space (part of a joint one is fine; not yet weighted by the
        likelihood's component scale); None: another space.

        An empty array for a length that does not match its space. The first embedding of a space the master
        cannot use, per camera, becomes a notice for the node to log."""
        space = person.embedding_space if isinstance(person.embedding_space, str) else ""
        values = np.asarray(person.embedding, dtype=np.float32).reshape(-1)
        want = self.config.embedding_space
        try:
            if space != want and values.size != space_dim(space):
                return np.zeros(0, dtype=np.float32)
            part = extract_space(values, space, want)  # scaled by the likelihood's weights once checked
            why = f"its face embeddings are of space {space[:64]!r}, this master compares {want!r}"
        except ValueError as exc:
            part, why = None, f"its face embeddings are unusable ({exc})"
        if part is None and _first_notice(self._space_noticed, camera_id, space):
            self.notices.append(f"camera {camera_id[:64]!r}: {why}: they are not used for identity (its "
                                 "positions still are); see the embedder / embedding_space parameters")
        return part
