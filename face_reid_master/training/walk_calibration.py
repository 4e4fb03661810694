"""Camera x, y, yaw in one world frame from one person walking through overlapping views.

Each camera reports the walker's floor positions in the world frame *as it is configured* (height, roll and
pitch right, from its floor; x, y, yaw possibly wrong). What camera ``i`` reports is then off from the truth
by a rigid 2-D motion ``C_i`` (rotation about the vertical and a shift). This module finds every ``C_i`` with
the anchor camera's fixed to identity:

1. per pair of cameras, time-matched positions of the walker (the other camera's track interpolated at this
   camera's stamps, only across short gaps);
2. per pair, a rigid transform by RANSAC (two-point hypotheses) and least squares on the inliers;
3. a spanning tree from the anchor over the best pairs gives every reachable camera a first guess (cameras
   that do not overlap the anchor are reached through others: a pose graph);
4. one joint least-squares refinement over all pairs' inliers; each camera's RMS residual says how well it fits.

Pure numpy / scipy; no rclpy.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from face_reid_master.robot.frames import PlanarTransform

__all__ = ["CalibrationResult", "CameraTrack", "calibrate_cameras", "rigid_2d", "time_matched"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CameraTrack:
    """One camera's detections of the walker: stamps (N,) in s and floor positions (N, 2) in m."""

    camera_id: str
    stamps_s: FloatArray
    xy: FloatArray

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps_s, dtype=np.float64).reshape(-1)
        xy = np.asarray(self.xy, dtype=np.float64).reshape(-1, 2)
        if stamps.shape[0] != xy.shape[0]:
            raise ValueError(f"camera {self.camera_id!r}: {stamps.shape[0]} stamps but {xy.shape[0]} positions")
        keep = np.isfinite(stamps) & np.isfinite(xy).all(axis=1)
        order = np.argsort(stamps[keep], kind="stable")
        object.__setattr__(self, "stamps_s", stamps[keep][order])
        object.__setattr__(self, "xy", xy[keep][order])


@dataclass(frozen=True)
class CalibrationResult:
    """Per camera: its correction (world_true <- as configured) and RMS residual (m) over its matched pairs.

    ``pairs``: (camera a, camera b) -> inlier correspondences used; ``unreached``: cameras no chain of
    overlapping views connects to the anchor (no correction for them).
    """

    anchor: str
    corrections: dict[str, PlanarTransform]
    residual_m: dict[str, float]
    pairs: dict[tuple[str, str], int] = field(default_factory=dict)
    unreached: tuple[str, ...] = ()


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def time_matched(a: CameraTrack, b: CameraTrack, max_gap_s: float = 0.2) -> tuple[FloatArray, FloatArray]:
    """Positions of a and b at a's stamps where b can be interpolated (b's samples around it at most
    ``max_gap_s`` apart): (M, 2) and (M, 2)."""
    if a.stamps_s.size == 0 or b.stamps_s.size < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    idx = np.searchsorted(b.stamps_s, a.stamps_s)
    ok = (idx > 0) & (idx < b.stamps_s.size)
    lo, hi = np.clip(idx - 1, 0, b.stamps_s.size - 1), np.clip(idx, 0, b.stamps_s.size - 1)
    gap = b.stamps_s[hi] - b.stamps_s[lo]
    ok &= gap <= max_gap_s
    w = np.where(gap > 0, (a.stamps_s - b.stamps_s[lo]) / np.where(gap > 0, gap, 1.0), 0.0)
    interp = b.xy[lo] + w[:, None] * (b.xy[hi] - b.xy[lo])
    return a.xy[ok], interp[ok]


def rigid_2d(src: FloatArray, dst: FloatArray) -> PlanarTransform:
    """The least-squares rigid motion taking ``src`` (N, 2) onto ``dst`` (N, 2) (N >= 2; 2-D Kabsch)."""
    if src.shape[0] < 2:
        raise ValueError(f"a rigid 2-D transform needs at least 2 point pairs, got {src.shape[0]}")
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    s, d = src - cs, dst - cd
    yaw = math.atan2(float(np.sum(s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0])), float(np.sum(s * d)))
    rot = PlanarTransform(0.0, 0.0, yaw)
    shift = cd - rot.apply(cs[None, :])[0]
    return PlanarTransform(float(shift[0]), float(shift[1]), yaw)


def _ransac_rigid_2d(src: FloatArray, dst: FloatArray, threshold_m: float, iterations: int,
                     rng: np.random.Generator) -> tuple[PlanarTransform, NDArray[np.bool_]]:
    """Robust :func:`rigid_2d`: the two-point hypothesis with most inliers, refitted on them (twice)."""
    n = src.shape[0]
    best = np.zeros(n, dtype=bool)
    for _ in range(iterations):
        i, j = rng.choice(n, 2, replace=False)
        if np.linalg.norm(src[i] - src[j]) < 0.3:  # too close together to fix a rotation
            continue
        guess = rigid_2d(src[[i, j]], dst[[i, j]])
        inliers = np.linalg.norm(guess.apply(src) - dst, axis=1) < threshold_m
        if inliers.sum() > best.sum():
            best = inliers
    if best.sum() < 2:
        return rigid_2d(src, dst), np.ones(n, dtype=bool)
    for _ in range(2):
        fit = rigid_2d(src[best], dst[best])
        refreshed = np.linalg.norm(fit.apply(src) - dst, axis=1) < threshold_m
        if refreshed.sum() < 2:
            break
        best = refreshed
    return rigid_2d(src[best], dst[best]), best


def calibrate_cameras(tracks: list[CameraTrack], anchor: str, *, max_gap_s: float = 0.2,
                      min_pairs: int = 20, inlier_threshold_m: float = 0.25, iterations: int = 300,
                      seed: int = 0) -> CalibrationResult:
    """Corrections (world_true <- as configured) of every camera reachable from ``anchor`` through overlapping
    views; see the module docstring.

    ``max_gap_s``: longest gap (s) across which a track is interpolated; ``min_pairs``: time-matched positions
    two cameras need to be linked (>= 3); ``inlier_threshold_m``: a matched pair further apart than this after the
    pair's transform is an outlier (m, > 0); ``iterations``: RANSAC hypotheses per pair (>= 1).
    """
    by_id = {t.camera_id: t for t in tracks}
    if len(by_id) != len(tracks):
        raise ValueError("tracks: one track per camera id")
    if anchor not in by_id:
        raise ValueError(f"anchor {anchor!r} is not one of the cameras {sorted(by_id)}")
    if min_pairs < 3:
        raise ValueError(f"min_pairs must be >= 3, got {min_pairs}")
    if not (inlier_threshold_m > 0):
        raise ValueError(f"inlier_threshold_m must be > 0, got {inlier_threshold_m}")
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    if not (max_gap_s > 0):
        raise ValueError(f"max_gap_s must be > 0, got {max_gap_s}")
    rng = np.random.default_rng(seed)
    ids = sorted(by_id)
    links: dict[tuple[str, str], tuple[PlanarTransform, FloatArray, FloatArray]] = {}  # b's frame -> a's frame
    for ia, a in enumerate(ids):
        for b in ids[ia + 1:]:
            pa, pb = time_matched(by_id[a], by_id[b], max_gap_s)
            if pa.shape[0] < min_pairs:
                continue
            fit, inl = _ransac_rigid_2d(pb, pa, inlier_threshold_m, iterations, rng)
            if inl.sum() >= min_pairs:
                links[(a, b)] = (fit, pa[inl], pb[inl])
    guess = _spanning_tree(anchor, links)
    corrections = _refine(anchor, guess, links)
    residual = _residuals(corrections, links)
    return CalibrationResult(anchor, corrections, residual,
                             {k: int(v[1].shape[0]) for k, v in links.items()},
                             tuple(c for c in ids if c not in corrections))


def _spanning_tree(anchor: str, links: dict[tuple[str, str], tuple[PlanarTransform, FloatArray, FloatArray]]
                   ) -> dict[str, PlanarTransform]:
    """First corrections: breadth first from the anchor, always through the link with most inliers."""
    edges: dict[str, list[tuple[int, str, PlanarTransform]]] = {}
    for (a, b), (fit, pa, _) in links.items():  # fit maps b's reports onto a's
        edges.setdefault(a, []).append((pa.shape[0], b, fit))
        edges.setdefault(b, []).append((pa.shape[0], a, fit.inverse()))
    out = {anchor: PlanarTransform()}
    queue = deque([anchor])
    while queue:
        here = queue.popleft()
        for _, there, to_here in sorted(edges.get(here, []), key=lambda e: -e[0]):
            if there not in out:
                out[there] = out[here].compose(to_here)  # there's reports -> here's -> truth
                queue.append(there)
    return out


def _refine(anchor: str, guess: dict[str, PlanarTransform],
            links: dict[tuple[str, str], tuple[PlanarTransform, FloatArray, FloatArray]]) -> dict[str, PlanarTransform]:
    """Joint least squares over every link between reached cameras (the anchor fixed)."""
    from scipy.optimize import least_squares

    free = [c for c in sorted(guess) if c != anchor]
    used = [(a, b, pa, pb) for (a, b), (_, pa, pb) in links.items() if a in guess and b in guess]
    if not free or not used:
        return dict(guess)
    index = {c: k for k, c in enumerate(free)}

    def unpack(params: FloatArray) -> dict[str, PlanarTransform]:
        out = {anchor: PlanarTransform()}
        for c, k in index.items():
            out[c] = PlanarTransform(float(params[3 * k]), float(params[3 * k + 1]), float(params[3 * k + 2]))
        return out

    def residuals(params: FloatArray) -> FloatArray:
        corr = unpack(params)
        return np.concatenate([(corr[a].apply(pa) - corr[b].apply(pb)).reshape(-1) for a, b, pa, pb in used])

    x0 = np.array([v for c in free for v in (guess[c].x_m, guess[c].y_m, guess[c].yaw_rad)])
    fit = least_squares(residuals, x0, loss="soft_l1", f_scale=0.05)
    return {c: PlanarTransform(v.x_m, v.y_m, _wrap(v.yaw_rad)) for c, v in unpack(fit.x).items()}


def _residuals(corrections: dict[str, PlanarTransform],
               links: dict[tuple[str, str], tuple[PlanarTransform, FloatArray, FloatArray]]) -> dict[str, float]:
    """RMS distance (m) between where a camera and each linked camera put the walker at the same moment."""
    sq: dict[str, list[FloatArray]] = {c: [] for c in corrections}
    for (a, b), (_, pa, pb) in links.items():
        if a in corrections and b in corrections:
            d2 = np.sum((corrections[a].apply(pa) - corrections[b].apply(pb)) ** 2, axis=1)
            sq[a].append(d2)
            sq[b].append(d2)
    return {c: float(np.sqrt(np.mean(np.concatenate(v)))) if v else math.nan for c, v in sq.items()}
