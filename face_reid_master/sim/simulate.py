"""Scenario simulator: people walking in a room watched by RGB-D cameras, as recorded camera messages.

:func:`simulate` builds the world (:mod:`~face_reid_master.sim.world`), the people's motion
(:mod:`~face_reid_master.sim.motion`) and their photos (:mod:`~face_reid_master.sim.photos`), then makes
the camera messages at one of two levels sharing all of these: ``feature``
(:mod:`~face_reid_master.sim.feature_level`, fast) or ``pixel`` (:mod:`~face_reid_master.sim.pixel_level`,
rendered frames through the real camera pipeline). Both are camera-true: a face or a body never shows more
pixels than the camera's colour focal length, the range and the face's angle give (``summary.camera_true`` of
scenario.json records the focal length and the eye distances). The result is written by
:func:`~face_reid_master.sim.scenario_files.write_scenario`; the same seed gives byte-identical files. People keep
``motion.passing_distance_m`` from each other (:mod:`~face_reid_master.sim.crowd`; 0: they walk through each
other).

Bodies (``config.bodies`` and a crops folder, :mod:`~face_reid_master.sim.bodies`): every person wears a crop
identity per day (a new one on day 2) and has body measures; detections then carry body descriptors,
visibility and geometry. Bodies draw from their own random streams: without them the files are unchanged.

Oracle evidence (``oracle_noise_std``, :mod:`~face_reid_master.sim.oracle`): once the frame table is assembled,
every face embedding and body descriptor of a person is replaced by one fixed real vector of theirs plus that
noise (the identity logic's floor); scenario.json then has ``"oracle": true`` and ``oracle_evidence``. Only
those arrays change: everything else is the same scenario as without it.

Days: with ``second_day`` the same room and cameras are replayed ``day_gap_s`` (default overnight) after day 1 ends with
``people - new_people`` of the day-1 people (their day-2 photos) and ``new_people`` identities never seen
on day 1.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.body.projection import BodyProjection
from face_reid_camera.common.checks import is_finite_number
from face_reid_camera.common.embedding_spaces import EMBEDDER_CHOICES, embedder_space
from face_reid_master.sim.bodies import (
    BodyBank,
    BodySimConfig,
    BodyWorld,
    assign_clothes,
    camera_light_gains,
    make_measures,
)
from face_reid_master.sim.crowd import CrowdConfig, CrowdStats, keep_apart
from face_reid_master.sim.feature_level import CameraTrueLog, color_focal_px, feature_camera_day
from face_reid_master.sim.frame_table import DetectionColumns, assemble_frames
from face_reid_master.sim.ground_truth import sample_ground_truth
from face_reid_master.sim.motion import MotionConfig, Trajectory, plan_trajectory
from face_reid_master.sim.oracle import S_ORACLE, oracle_table
from face_reid_master.sim.photos import PhotoBank
from face_reid_master.sim.pixel_level import pixel_camera_frames
from face_reid_master.sim.scenario_files import SimResult, scenario_document
from face_reid_master.sim.streams import (
    S_BODIES,
    S_BODY_LIGHT,
    S_BODY_MEASURES,
    S_CAMERA,
    S_IDENTITIES,
    S_MOTION,
    S_PHASE,
    S_WORLD,
    stream_rng,
)
from face_reid_master.sim.visibility import VisibilityConfig
from face_reid_master.sim.world import Room, make_world, room_size_for

__all__ = ["DEFAULT_RATE_HZ", "LEVELS", "Day", "SimConfig", "simulate"]

LEVELS = ("feature", "pixel")
DEFAULT_RATE_HZ = {"feature": 15.0, "pixel": 5.0}


@dataclass(frozen=True)
class SimConfig:
    """Everything that defines a scenario (with the faces folder and the seed)."""

    num_people: int = 6
    num_cameras: int = 3
    duration_s: float = 200.0
    seed: int = 0
    level: str = "feature"
    rate_hz: float | None = None  # None: 15 Hz (feature) / 5 Hz (pixel)
    second_day: bool = False
    new_people: int | None = None  # None: num_people // 3
    day_gap_s: float = 50400.0  # overnight: longer than the body evidence's window (clothes change by day 2)
    room_size_m: tuple[float, float] | None = None  # None: scaled with the number of cameras
    miss_probability: float = 0.05
    false_positives_per_frame: float = 0.01
    position_noise_base_m: float = 0.04
    position_noise_per_m: float = 0.01
    calibration_error_m: float = 0.03
    height_noise_m: float = 0.03
    face_detect_probability: float = 0.95
    embedding_noise_std: float = 0.01
    glance_gap_s: float = 0.5
    min_photos_per_identity: int = 2
    loss_gap_s: float = 1.5
    ground_truth_rate_hz: float = 10.0
    embedder: str = "both"  # the cameras' embedder: dlib | sface | both (one scenario serves all three spaces)
    color_resolution: tuple[int, int] | None = None  # colour image W, H (px); None: the depth camera's
    motion: MotionConfig = field(default_factory=MotionConfig)
    visibility: VisibilityConfig = field(default_factory=VisibilityConfig)
    bodies: BodySimConfig | None = None  # None: no bodies (simulate needs a crops folder otherwise)
    oracle_noise_std: float | None = None  # oracle evidence with this noise per value (None: real evidence)

    def __post_init__(self) -> None:
        for name, low, high in (("num_people", 1, 500), ("num_cameras", 1, 64), ("min_photos_per_identity", 1, 1000)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= high:
                raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.level not in LEVELS:
            raise ValueError(f"level must be one of {LEVELS}, got {self.level!r}")
        if not (is_finite_number(self.duration_s) and 0 < self.duration_s <= 24 * 3600):
            raise ValueError(f"duration_s must be in (0, 86400] s, got {self.duration_s!r}")
        if self.rate_hz is not None and not (is_finite_number(self.rate_hz) and 0 < self.rate_hz <= 120):
            raise ValueError(f"rate_hz must be in (0, 120] Hz, got {self.rate_hz!r}")
        if self.new_people is not None and (
            isinstance(self.new_people, bool) or not isinstance(self.new_people, (int, np.integer))
            or not 0 <= self.new_people <= self.num_people
        ):
            raise ValueError(
                f"new_people must be an integer in [0, num_people={self.num_people}], got {self.new_people!r}"
            )
        if self.room_size_m is not None:
            Room(*self.room_size_m)  # validates
        for name in ("miss_probability", "face_detect_probability"):
            value = getattr(self, name)
            if not (is_finite_number(value) and 0 <= value <= 1):
                raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
        for name in ("false_positives_per_frame", "position_noise_per_m", "calibration_error_m", "height_noise_m",
                     "embedding_noise_std", "glance_gap_s", "loss_gap_s", "day_gap_s"):
            value = getattr(self, name)
            if not (is_finite_number(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not (is_finite_number(self.position_noise_base_m) and self.position_noise_base_m > 0):
            raise ValueError(f"position_noise_base_m must be > 0, got {self.position_noise_base_m!r}")
        if not (is_finite_number(self.ground_truth_rate_hz) and 0 < self.ground_truth_rate_hz <= 100):
            raise ValueError(f"ground_truth_rate_hz must be in (0, 100] Hz, got {self.ground_truth_rate_hz!r}")
        if self.embedder not in EMBEDDER_CHOICES:
            raise ValueError(f"embedder must be one of {sorted(EMBEDDER_CHOICES)}, got {self.embedder!r}")
        if self.color_resolution is not None:
            w, h = self.color_resolution
            if not all(isinstance(v, (int, np.integer)) and 64 <= v <= 8192 for v in (w, h)):
                raise ValueError(f"color_resolution must be two integers in [64, 8192] (W, H px), got "
                                 f"{self.color_resolution!r}")
        if not isinstance(self.motion, MotionConfig) or not isinstance(self.visibility, VisibilityConfig):
            raise ValueError("motion / visibility must be MotionConfig / VisibilityConfig instances")
        if self.oracle_noise_std is not None and not (is_finite_number(self.oracle_noise_std)
                                                      and 0 <= self.oracle_noise_std <= 1):
            raise ValueError(f"oracle_noise_std must be None or in [0, 1], got {self.oracle_noise_std!r}")
        if self.bodies is not None and not isinstance(self.bodies, BodySimConfig):
            raise ValueError(f"bodies must be a BodySimConfig or None, got {type(self.bodies).__name__}")

    @property
    def frame_rate_hz(self) -> float:
        return float(self.rate_hz) if self.rate_hz is not None else DEFAULT_RATE_HZ[self.level]

    @property
    def num_new_people(self) -> int:
        if not self.second_day:
            return 0
        return int(self.new_people) if self.new_people is not None else self.num_people // 3

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["frame_rate_hz"] = self.frame_rate_hz
        out["num_new_people"] = self.num_new_people
        if self.bodies is None:
            del out["bodies"]  # scenarios without bodies keep their files of before
        if self.oracle_noise_std is None:
            del out["oracle_noise_std"]  # real evidence: the files of before
        return out


@dataclass
class Day:
    """One simulated day: its people (gt ids), their trajectories (and how they gave way to each other)."""

    day: int
    start_s: float
    gt_ids: list[int]
    trajectories: list[Trajectory]
    crowd: CrowdStats | None = None  # how people gave way (None: nobody had to)


def camera_stamps(start_s: float, duration_s: float, rate_hz: float, phase_s: float) -> NDArray[np.float64]:
    """Frame stamps of one camera over one day: every 1 / rate_hz from start_s + phase_s."""
    n = math.floor((duration_s - phase_s) * rate_hz - 1e-9) + 1
    return start_s + phase_s + np.arange(max(n, 0), dtype=np.float64) / rate_hz


def simulate(faces_dir: str | Path, config: SimConfig, cache_path: str | Path | None = None,
             log: TextIO | None = None, bank: PhotoBank | None = None, bodies_dir: str | Path | None = None,
             body_projection: BodyProjection | None = None) -> SimResult:
    """Run a scenario. Raises InsufficientFacesError for an empty / too small faces folder.

    With ``config.bodies``: the crops folder ``bodies_dir`` and the cameras' ``body_projection`` are needed;
    InsufficientBodiesError for an unusable crops folder.
    """
    cfg = config
    if (cfg.bodies is None) != (bodies_dir is None):
        raise ValueError("bodies_dir and config.bodies go together (a crops folder for a config with bodies)")
    body_bank = None
    if cfg.bodies is not None:
        if body_projection is None:
            raise ValueError("config.bodies needs the cameras' body_projection")
        body_bank = BodyBank(bodies_dir, body_projection, log)  # type: ignore[arg-type]

    def say(message: str) -> None:
        if log is not None:
            log.write(message + "\n")
            log.flush()

    t0 = time.perf_counter()
    bank = bank if bank is not None else PhotoBank(faces_dir, cache_path, cfg.min_photos_per_identity, log,
                                                   embedder=cfg.embedder, variants=False)
    if bank.space != embedder_space(cfg.embedder):
        raise ValueError(f"the photo bank embeds with {bank.embedder_choice!r}, the config asks for {cfg.embedder!r}")
    n_day1, n_new = cfg.num_people, cfg.num_new_people
    say(f"choosing {n_day1 + n_new} identities in {bank.faces_dir} ({len(bank.identity_files)} folders)")
    identities = bank.choose(n_day1 + n_new, stream_rng(cfg.seed, S_IDENTITIES))
    bank.save_cache()
    say(f"photos ready in {time.perf_counter() - t0:.1f} s ({bank.embedded_now} embedded now, the rest cached; "
        f"skipped {len(bank.skipped_unreadable)} unreadable, {len(bank.skipped_no_face)} without a face)")
    photo_offsets = list(np.cumsum([0] + [len(i.photos) for i in identities[:-1]]).astype(int))
    room = Room(*cfg.room_size_m) if cfg.room_size_m is not None else room_size_for(cfg.num_cameras)
    world = make_world(cfg.num_cameras, stream_rng(cfg.seed, S_WORLD), room=room)
    rate = cfg.frame_rate_hz
    phases = stream_rng(cfg.seed, S_PHASE).uniform(0.0, 1.0 / rate, size=cfg.num_cameras)
    bias_rng = stream_rng(cfg.seed, S_CAMERA, 0)
    camera_bias = [bias_rng.normal(size=2) * cfg.calibration_error_m / math.sqrt(2.0) for _ in world.cameras]
    heights_all = stream_rng(cfg.seed, S_MOTION, 0).uniform(*cfg.motion.height_range_m, size=len(identities))

    days = [Day(1, 0.0, list(range(n_day1)), [])]
    if cfg.second_day:
        keep = sorted(int(i) for i in stream_rng(cfg.seed, S_IDENTITIES, 2).permutation(n_day1)[: n_day1 - n_new])
        days.append(Day(2, cfg.duration_s + cfg.day_gap_s, keep + list(range(n_day1, n_day1 + n_new)), []))
    for day in days:
        for gt in day.gt_ids:
            rng = stream_rng(cfg.seed, S_MOTION, day.day, gt + 1)
            day.trajectories.append(plan_trajectory(world, rng, cfg.duration_s, cfg.motion, start_s=day.start_s,
                                                    height_m=float(heights_all[gt])))
        if cfg.motion.passing_distance_m > 0 and len(day.trajectories) > 1:  # nobody walks through anybody
            t_crowd = time.perf_counter()
            day.trajectories, day.crowd = keep_apart(world, day.trajectories, day.start_s, cfg.duration_s,
                                                     CrowdConfig(passing_distance_m=cfg.motion.passing_distance_m))
            say(f"day {day.day}: people keep {cfg.motion.passing_distance_m:g} m apart "
                f"({time.perf_counter() - t_crowd:.1f} s): {100 * day.crowd.slowed_share:.0f} % of the time slowed, "
                f"{100 * day.crowd.aside_share:.0f} % off their paths, at most {day.crowd.max_delay_s:.1f} s late")

    bodies = None
    if cfg.bodies is not None:
        assert body_bank is not None
        clothes = assign_clothes(body_bank, days, stream_rng(cfg.seed, S_BODIES))
        say(f"clothes: {len(clothes)} crop identities of {len(body_bank.identity_names)} in {body_bank.bodies_dir} "
            f"({len(body_bank.crops)} crops)")
        bodies = BodyWorld(body_bank, cfg.bodies, clothes,
                           make_measures(heights_all, stream_rng(cfg.seed, S_BODY_MEASURES)),
                           camera_light_gains(cfg.num_cameras, cfg.bodies, stream_rng(cfg.seed, S_BODY_LIGHT)))

    per_camera: list[tuple[int, NDArray[np.float64], DetectionColumns]] = []
    glance_counter = [0]
    t1 = time.perf_counter()
    frames_total = sum(camera_stamps(d.start_s, cfg.duration_s, rate, float(ph)).size for d in days for ph in phases)
    say(f"simulating {len(days)} day(s) x {cfg.duration_s:g} s, {cfg.num_cameras} cameras at {rate:g} Hz "
        f"({frames_total} camera frames, level {cfg.level})")
    frames_done = [0]
    camera_true = CameraTrueLog(focal_px=color_focal_px(cfg.color_resolution, world.cameras[0].intrinsics.width))
    for day in days:
        heights = heights_all[day.gt_ids]
        stamps = [camera_stamps(day.start_s, cfg.duration_s, rate, float(ph)) for ph in phases]
        if cfg.level == "feature":
            for c in range(cfg.num_cameras):
                cols = feature_camera_day(cfg, world, c, day, stamps[c], identities, photo_offsets, heights,
                                          camera_bias[c], glance_counter, bank, bodies, camera_true)
                per_camera.append((c, stamps[c], cols))
        else:
            cols_list = pixel_camera_frames(cfg, world, day, stamps, identities, photo_offsets, heights, bank,
                                            glance_counter, log, frames_done, frames_total, bodies)
            per_camera.extend((c, stamps[c], cols) for c, cols in enumerate(cols_list))
    table = assemble_frames(per_camera, cfg.seed, None if bodies is None else (bodies.dim, bodies.parts))
    oracle = None
    if cfg.oracle_noise_std is not None:  # the one point where observations become oracle evidence
        table, oracle = oracle_table(
            table, [np.stack([p.embeddings[0] for p in ident.photos]) for ident in identities], photo_offsets,
            bank.space, [d.start_s for d in days], cfg.oracle_noise_std, stream_rng(cfg.seed, S_ORACLE, 0),
            stream_rng(cfg.seed, S_ORACLE, 1))
        say(f"oracle evidence: {oracle.face_rows} face and {oracle.body_rows} body rows replaced by their person's "
            f"fixed vector + N(0, {cfg.oracle_noise_std:g})")
    say(f"camera frames done in {time.perf_counter() - t1:.1f} s: {table.stamp_s.size} frames, "
        f"{table.det['gt_id'].size} detections, {table.face['score'].size} faces")
    if cfg.level == "feature":
        bank.save_cache()
        views = bank.view_stats
        say(f"camera-true face views: {views.made} embedded now ({views.redetected} re-detected by YuNet, the rest "
            f"aligned on the photo's scaled landmarks), {views.cached} from the cache")
    gt_arrays, loss_info = sample_ground_truth(cfg, world, days, heights_all)
    document = scenario_document(cfg, bank, world, identities, photo_offsets, days, heights_all, phases, table,
                                 gt_arrays, loss_info, glance_counter[0], bodies, camera_true.record(cfg.level))
    if oracle is not None:
        document["oracle"] = True
        document["oracle_evidence"] = oracle.as_json()
    return SimResult(document, table, gt_arrays)
