"""Synthetic multi-camera people trajectories for tracker tests (motpy-style generator).

People walk at constant speed through waypoints (turns at the waypoints, optionally rounded) and
vanish after the last one.  Cameras see a wedge of the ground plane (position, yaw, horizontal field
of view, range) and emit frames at their own rate and phase, each detection with Gaussian noise, a
per-camera calibration bias, a miss probability, optional clutter and a ground-truth person id
(-1 = clutter).  Frames are delivered in *arrival* order (stamp + latency + jitter) so that
out-of-order delivery can be simulated.  Everything is deterministic given ``seed``.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from face_reid_master.tracking.records import Detection, UpdateResult

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CameraFov:
    """A camera's field of view on the ground plane: a wedge with apex at ``position_xy``."""

    camera_id: str
    position_xy: tuple[float, float]
    yaw_rad: float
    hfov_rad: float = math.radians(70.0)
    max_range_m: float = 6.0
    min_range_m: float = 0.5
    rate_hz: float = 30.0
    phase_s: float = 0.0
    bias_xy: tuple[float, float] = (0.0, 0.0)  # extrinsic calibration error added to its detections

    def sees(self, xy: FloatArray) -> NDArray[np.bool_]:
        """(N,) mask of the (N, 2) ground points inside the wedge."""
        d = np.atleast_2d(xy) - np.asarray(self.position_xy)
        rng = np.hypot(d[:, 0], d[:, 1])
        bearing = np.arctan2(d[:, 1], d[:, 0]) - self.yaw_rad
        bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
        return (rng >= self.min_range_m) & (rng <= self.max_range_m) & (np.abs(bearing) <= self.hfov_rad / 2)


@dataclass(frozen=True)
class Walker:
    """A person walking through ``waypoints`` at ``speed_mps`` from ``start_s``; gone after the end.

    With ``corner_radius_m`` > 0 each turn is rounded (quadratic Bezier fillet starting that far
    before the waypoint, capped at half of each leg): people do not reverse direction instantly.
    """

    person_id: int
    waypoints: tuple[tuple[float, float], ...]
    speed_mps: float = 1.2
    start_s: float = 0.0
    corner_radius_m: float = 0.0

    def __post_init__(self) -> None:
        if len(self.waypoints) < 2 or self.speed_mps <= 0 or self.corner_radius_m < 0:
            raise ValueError("a Walker needs >= 2 waypoints, a positive speed and corner_radius_m >= 0")

    @cached_property
    def _path(self) -> tuple[FloatArray, FloatArray]:
        """Dense polyline of the (rounded) path and the cumulative arc length at its vertices."""
        pts = np.asarray(self.waypoints, dtype=float)
        if self.corner_radius_m > 0 and len(pts) > 2:
            dense = [pts[0]]
            u = np.linspace(0.0, 1.0, 9)[:, None]
            for k in range(1, len(pts) - 1):
                a, p, b = pts[k - 1], pts[k], pts[k + 1]
                la, lb = np.linalg.norm(p - a), np.linalg.norm(b - p)
                c = min(self.corner_radius_m, la / 2, lb / 2)
                start = p + (a - p) * (c / la) if la > 0 else p
                end = p + (b - p) * (c / lb) if lb > 0 else p
                dense.extend((1 - u) ** 2 * start + 2 * u * (1 - u) * p + u**2 * end)
            dense.append(pts[-1])
            pts = np.asarray(dense)
        lengths = np.hypot(*np.diff(pts, axis=0).T)
        return pts, np.concatenate([[0.0], np.cumsum(lengths)])

    @property
    def end_s(self) -> float:
        return self.start_s + float(self._path[1][-1]) / self.speed_mps

    def positions(self, ts: FloatArray) -> FloatArray:
        """(T, 2) positions at times ``ts``, NaN where the person is not in the world."""
        pts, cum = self._path
        s = (np.asarray(ts, dtype=float) - self.start_s) * self.speed_mps
        out = np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)
        out[(s < 0) | (s > cum[-1])] = np.nan
        return out

    def position(self, t: float) -> FloatArray | None:
        """Ground position at time ``t`` or None when the person is not in the world."""
        if t < self.start_s or t > self.end_s:
            return None
        pts, cum = self._path
        s = (t - self.start_s) * self.speed_mps
        return np.array([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])])


@dataclass(frozen=True)
class SyntheticFrame:
    """One camera frame as delivered to the master."""

    stamp_s: float
    arrival_s: float
    camera_id: str
    detections: tuple[Detection, ...]
    gt_ids: tuple[int, ...]


@dataclass(frozen=True)
class Scenario:
    """Walkers + cameras + sensor imperfections; :meth:`frames` renders the camera frames."""

    walkers: tuple[Walker, ...]
    cameras: tuple[CameraFov, ...]
    duration_s: float
    noise_std_m: float = 0.05
    miss_probability: float = 0.0
    false_positives_per_frame: float = 0.0
    latency_s: float = 0.0
    latency_jitter_s: float = 0.0
    reported_std_m: float | None = None  # std given to the tracker; default max(noise, 0.02)
    seed: int = 0

    def frames(self) -> list[SyntheticFrame]:
        """All frames of all cameras, sorted by arrival time (ties by stamp)."""
        rng = np.random.default_rng(self.seed)
        std = self.reported_std_m if self.reported_std_m is not None else max(self.noise_std_m, 0.02)
        out: list[SyntheticFrame] = []
        for cam in self.cameras:
            n_frames = math.floor((self.duration_s - cam.phase_s) * cam.rate_hz + 1e-9) + 1
            for k in range(n_frames):
                t = cam.phase_s + k / cam.rate_hz
                dets: list[Detection] = []
                gts: list[int] = []
                for w in self.walkers:
                    p = w.position(t)
                    if p is None or not cam.sees(p)[0] or rng.random() < self.miss_probability:
                        continue
                    z = p + np.asarray(cam.bias_xy) + rng.normal(scale=self.noise_std_m, size=2)
                    dets.append(Detection(z, std, height_m=1.7))
                    gts.append(w.person_id)
                for _ in range(rng.poisson(self.false_positives_per_frame)):
                    ang = cam.yaw_rad + rng.uniform(-cam.hfov_rad / 2, cam.hfov_rad / 2)
                    r = rng.uniform(cam.min_range_m, cam.max_range_m)
                    z = np.asarray(cam.position_xy) + r * np.array([math.cos(ang), math.sin(ang)])
                    dets.append(Detection(z, std))
                    gts.append(-1)
                order = rng.permutation(len(dets))  # detector output order carries no information
                arrival = t + self.latency_s + rng.uniform(0.0, self.latency_jitter_s)
                out.append(
                    SyntheticFrame(
                        t, arrival, cam.camera_id, tuple(dets[i] for i in order), tuple(gts[i] for i in order)
                    )
                )
        out.sort(key=lambda f: (f.arrival_s, f.stamp_s))
        return out


def crossing_pair(
    angle_deg: float,
    speed_mps: float = 1.2,
    half_length_m: float = 3.0,
    min_separation_m: float = 0.0,
) -> tuple[Walker, Walker]:
    """Two people whose straight paths cross at the origin, headings ``angle_deg`` apart.

    With ``min_separation_m`` = 0 they are at the crossing point at the same instant (maximally
    ambiguous); otherwise person 2 is delayed (or, head-on, offset sideways) so that their closest
    approach is ``min_separation_m``, as real people who do not walk through each other.
    """
    theta = math.radians(angle_deg)
    e1 = np.array([1.0, 0.0])
    e2 = np.array([math.cos(theta), math.sin(theta)])
    closing = math.cos(theta / 2)  # closest approach = speed * delay * cos(theta / 2)
    delay_s, lateral = 0.0, np.zeros(2)
    if min_separation_m > 0 and closing > 0.2:
        delay_s = min_separation_m / (speed_mps * closing)
    elif min_separation_m > 0:
        lateral = min_separation_m * np.array([-e2[1], e2[0]])
    w1 = Walker(1, (tuple(-half_length_m * e1), tuple(half_length_m * e1)), speed_mps)
    w2 = Walker(
        2, (tuple(lateral - half_length_m * e2), tuple(lateral + half_length_m * e2)), speed_mps, delay_s
    )
    return w1, w2


def hidden_walker_and_bystander(
    hidden_s: float = 1.2,
    bystander_offset_m: float = 1.2,
    speed_mps: float = 1.2,
    hide_at_s: float = 3.0,
) -> tuple[Walker, Walker, Walker]:
    """Person 1 walks along +x and is hidden (occluded) for ``hidden_s`` from ``hide_at_s``; half-way
    through, person 2 steps out from behind the occluder ``bystander_offset_m`` to the side of where
    person 1 is, and stands there.

    Person 1 is two walkers with the same id (an unseen gap on one straight path), so a tracker
    sees a track coasting through the gap while a new person appears within a metre or two of it,
    as in a crowd, where people are hidden behind each other all the time.
    """
    x0 = -speed_mps * hide_at_s
    x_hide = 0.0
    x_back = speed_mps * hidden_s
    end = x_back + 3.0
    before = Walker(1, ((x0, 0.0), (x_hide, 0.0)), speed_mps)
    after = Walker(1, ((x_back, 0.0), (end, 0.0)), speed_mps, start_s=hide_at_s + hidden_s)
    t_b = hide_at_s + hidden_s / 2
    bx = speed_mps * hidden_s / 2
    bystander = Walker(2, ((bx, bystander_offset_m), (bx, bystander_offset_m + 0.3)), 0.1, start_s=t_b)
    return before, after, bystander


def min_pair_distance(walkers: Sequence[Walker], step_s: float = 0.05) -> float:
    """Smallest distance between any two walkers present at the same time (inf if never)."""
    if len(walkers) < 2:
        return math.inf
    ts = np.arange(0.0, max(w.end_s for w in walkers) + step_s, step_s)
    pos = np.stack([w.positions(ts) for w in walkers])  # (n, T, 2)
    gaps = np.linalg.norm(pos[:, None] - pos[None, :], axis=3)  # (n, n, T), NaN when absent
    gaps[np.arange(len(walkers)), np.arange(len(walkers))] = np.nan
    finite = gaps[np.isfinite(gaps)]
    return float(finite.min()) if finite.size else math.inf


def max_turn_angle_deg(waypoints: FloatArray) -> float:
    """Largest heading change at the interior waypoints of a polyline, in degrees."""
    d = np.diff(np.asarray(waypoints, dtype=float), axis=0)
    if d.shape[0] < 2:
        return 0.0
    h = np.arctan2(d[:, 1], d[:, 0])
    turn = np.abs((np.diff(h) + math.pi) % (2 * math.pi) - math.pi)
    return float(np.degrees(turn.max()))


def random_walkers(
    n: int,
    seed: int,
    area_m: float = 8.0,
    n_turns: int = 3,
    speed_range_mps: tuple[float, float] = (0.8, 1.5),
    corner_radius_m: float = 0.7,
    min_separation_m: float = 0.6,
    max_turn_deg: float = 120.0,
) -> tuple[Walker, ...]:
    """``n`` people on random waypoints in a square of side ``area_m`` centred on the origin.

    Draws are repeated (deterministically) until no turn is sharper than ``max_turn_deg`` (nobody
    reverses at full walking speed) and no two people come closer than ``min_separation_m``.
    """
    rng = np.random.default_rng(seed)
    for _ in range(1000):
        out = []
        for pid in range(1, n + 1):
            pts = rng.uniform(-area_m / 2, area_m / 2, size=(n_turns + 2, 2))
            while max_turn_angle_deg(pts) > max_turn_deg:
                pts = rng.uniform(-area_m / 2, area_m / 2, size=(n_turns + 2, 2))
            speed = float(rng.uniform(*speed_range_mps))
            out.append(Walker(pid, tuple(map(tuple, pts)), speed, corner_radius_m=corner_radius_m))
        if min_pair_distance(out) >= min_separation_m:
            return tuple(out)
    raise RuntimeError("could not draw walkers that keep their separation; lower min_separation_m")


def overview_camera(camera_id: str = "cam_all", rate_hz: float = 30.0, phase_s: float = 0.0) -> CameraFov:
    """A camera that sees a 20 m disc around the origin (for tests that need no hand-over)."""
    return CameraFov(camera_id, (0.0, 0.0), 0.0, 2 * math.pi, 20.0, 0.0, rate_hz, phase_s)


@dataclass(frozen=True)
class PersonTrackReport:
    """How one ground-truth person was tracked."""

    person_id: int
    track_sequence: tuple[tuple[float, int], ...]  # (stamp, track id) of each associated detection
    dominant_track: int
    dominant_fraction: float
    switches: int  # changes of track id lasting at least `min_run` consecutive detections

    @property
    def first_track(self) -> int:
        return self.track_sequence[0][1]

    @property
    def last_track(self) -> int:
        return self.track_sequence[-1][1]


def person_reports(
    frames: Sequence[SyntheticFrame], results: Sequence[UpdateResult], min_run: int = 3
) -> dict[int, PersonTrackReport]:
    """Per-person identity summary over the tracks that were ever CONFIRMED.

    ``frames`` and ``results`` in processing order.  Tentative tracks that died unconfirmed (start-up
    noise) are ignored.  A *switch* is a change of the person's track id that persists for
    ``min_run`` consecutive associated detections: a single ambiguous assignment when two people are
    at the same spot is not a switch, a real swap of identities is.
    """
    confirmed = {tid for res in results for tid in res.confirmed}
    seqs: dict[int, list[tuple[float, int]]] = {}
    for frame, res in zip(frames, results, strict=True):
        if not res.accepted:
            continue
        t_of_d = res.track_of_detection()
        for d, gt in enumerate(frame.gt_ids):
            if gt >= 0 and t_of_d.get(d) in confirmed:
                seqs.setdefault(gt, []).append((frame.stamp_s, t_of_d[d]))
    out: dict[int, PersonTrackReport] = {}
    for pid, seq in seqs.items():
        seq.sort()
        ids = [t for _, t in seq]
        dominant, n_dom = Counter(ids).most_common(1)[0]
        switches = 0
        current = ids[0]
        for k in range(len(ids)):
            if ids[k] != current and ids[k : k + min_run] == [ids[k]] * min_run:
                switches += 1
                current = ids[k]
        out[pid] = PersonTrackReport(pid, tuple(seq), dominant, n_dom / len(ids), switches)
    return out
