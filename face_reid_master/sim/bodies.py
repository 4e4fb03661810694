"""Bodies of simulated people (``face-reid-sim --bodies DIR``): clothes from real person crops, body measures.

Every identity wears, per day, a crop identity: a sub-folder of person crops (top of the head to the feet,
:func:`~face_reid_master.training.body.crops.list_crops`). People present on both days **change clothes** (another
crop identity that nobody else wears), as in the paper's long-term experiment, so body appearance must not
carry across days; their body measures (:data:`MEASURE_FIELDS`, drawn once per person) do.

Orientation of a crop: PKU-Reid's ``CC_O`` names number 8 body orientations. Looking at the crops, 7 is the
front, 3 the back, 1 the profile facing the image's left, 5 the profile facing its right, 2 and 4 are
back three-quarter views (turned to the left, right), 8 and 6 front three-quarter views (left, right).
With the *view angle* = the person's facing minus the direction from the person to the camera (counter-
clockwise seen from above; 0 = facing the camera, +90 = facing the image's right, 180 = showing the back),
orientation O shows the view (7 - O) x 45 deg, wrapped to [-180, 180) (:data:`PKU_VIEW_DEG`). Crops of
another naming give no orientation.

Which crop a camera shows (:func:`choose_crops`): a *body glance* is a run of one camera's frames showing the
person (gaps < ``glance_gap_s`` bridged); each glance draws one source camera of the crops (PKU-Reid has two)
and one light level, and each frame then shows that source camera's crop whose orientation is nearest to the
frame's view angle (8 sectors of 45 deg). Without orientations a glance draws one crop of the identity.

Feature level (:func:`feature_bodies`): the real descriptor code
(:func:`~face_reid_camera.body.descriptor.body_descriptor`, then the shipped projection) runs on the crop
after the camera's degradations: its light (a per-camera gain and colour cast, times the glance's level),
its distance (camera-true: the crop reduced to the rows the person spans in the colour image at that range,
:func:`body_rows`, never taller; with 640x480 and 128-row crops that happens only beyond ~6.4 m, past the 6 m
detection range: the crops have less detail than the camera sees), and what the camera cannot see: the crop's
background (only its central columns count, ``silhouette_width``) and the body's horizontal bands
(:func:`~face_reid_master.sim.visibility.body_band_visibility`) that are out of the image or behind
someone. Frames of a glance differ as camera frames do: each shows one of a few real image changes of the
crop (shifted, scaled, sensor noise, blur: :data:`_FRAME_VARIANTS`), plus a little Gaussian noise.
Descriptors are cached per (crop, camera, light level, seen bands, rows, frame change), so a long scenario
computes each variant once. Geometry: the person's measures seen from the frame's view angle (a width
across the line of sight is the extent of an ellipse: front = width, side = depth), plus noise growing
with range; NaN where the band a measure needs is unseen.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import cv2
import numpy as np
from numpy.typing import NDArray

from face_reid_camera.body.descriptor import body_descriptor
from face_reid_camera.body.observation import GEOMETRY_FIELDS
from face_reid_camera.body.person_body import GEOMETRY_BANDS
from face_reid_camera.body.projection import BodyProjection
from face_reid_camera.common.checks import check_int, check_real
from face_reid_camera.faces.photos import PhotoError, read_photo
from face_reid_master.sim.frame_table import BodyRows
from face_reid_master.sim.photos import choose_usable
from face_reid_master.sim.visibility import VisibilityConfig, body_band_visibility, glance_ids
from face_reid_master.sim.world import SimCamera, check_min_max
from face_reid_master.training.body.crop_descriptors import CROP_SILHOUETTE, crop_person_mask
from face_reid_master.training.body.crops import Crop, list_crops

if TYPE_CHECKING:
    from face_reid_master.sim.simulate import Day

__all__ = [
    "MEASURE_FIELDS",
    "NUM_FRAME_VARIANTS",
    "PKU_VIEW_DEG",
    "BodyBank",
    "BodySimConfig",
    "BodyWorld",
    "ClothesIdentity",
    "InsufficientBodiesError",
    "assign_clothes",
    "body_rows",
    "camera_light_gains",
    "choose_crops",
    "feature_bodies",
    "make_measures",
    "part_overlap",
    "view_angle_deg",
]

PKU_VIEW_DEG: dict[int, float] = {o: float(((7 - o) * 45 + 180) % 360 - 180) for o in range(1, 9)}
VIEW_SECTORS = 8  # view angles are matched to crops in sectors of 45 deg
_SECTOR_DEG = 360.0 / VIEW_SECTORS
# True body measures per person (m): what a depth camera measures across / along the line of sight depends
# on the view, so each width comes with the matching depth.
MEASURE_FIELDS = ("head_height_m", "shoulder_width_m", "shoulder_depth_m", "torso_width_m", "torso_depth_m",
                  "hip_width_m", "hip_depth_m")
_GEOMETRY_INDEX = {name: i for i, name in enumerate(GEOMETRY_FIELDS)}
# Frame-to-frame changes of a crop within a glance (index: change), real image changes the descriptor code
# sees: the person a little elsewhere / larger / smaller in the cut-out, sensor noise, focus. One per frame.
_FRAME_VARIANTS: tuple[dict[str, float], ...] = (
    {},
    {"dx": 2.0, "dy": 1.0},
    {"dx": -2.0, "dy": -1.0},
    {"scale": 0.94},
    {"scale": 1.06, "dy": 1.0},
    {"noise": 5.0},
    {"blur": 0.7},
)
NUM_FRAME_VARIANTS = len(_FRAME_VARIANTS)


class InsufficientBodiesError(ValueError):
    """The crops folder is missing, empty or has fewer usable crop identities than the scenario needs."""


@dataclass(frozen=True)
class BodySimConfig:
    """How bodies are simulated (the camera's degradations of a crop, the measurement noise)."""

    light_gain_range: tuple[float, float] = (0.75, 1.25)  # a camera's overall gain on the crops' colours
    light_cast: float = 0.08  # +- per-channel gain of a camera (colour cast)
    glance_light_step: float = 0.06  # a glance's light: the camera's x (1 + step x level), level in {-1, 0, 1}
    # Per-frame Gaussian noise per value, relative to the vector's rms. Matched, with the frame changes, to the
    # pixel level's within-glance spread with an earlier 64 + 32 projection (median pairwise distance 0.30 vs
    # 0.36); with the shipped 32 + 96 projection 0.31 vs 0.47 (README, "Bodies in the simulator").
    descriptor_noise: float = 0.2
    bands: int = 8  # horizontal bands of the body tested for visibility (band 0 at the head top)
    min_visible_fraction: float = 0.25  # below: no appearance descriptor (the camera's default)
    # Central share of a crop's columns taken as the person (dataset crops have no masks; the camera cuts the
    # person out by depth): rendered bodies described by the camera pipeline come nearer to their crop's
    # descriptor (median distance 0.62 -> 0.42 on 10 PKU-Reid front crops at 3 m, other crops ~0.8; with a
    # 64 + 32 PCA projection fitted on the shared crops).
    silhouette_width: float = CROP_SILHOUETTE
    geometry_noise_base_m: float = 0.01  # std of a measured width / height at 0 m ...
    geometry_noise_per_m: float = 0.006  # ... growing with range

    def __post_init__(self) -> None:
        check_min_max("light_gain_range", self.light_gain_range, 0.1, 4.0)
        check_real("silhouette_width", self.silhouette_width, 0.0, 1.0, low_open=True)
        for name, high in (("light_cast", 0.5), ("glance_light_step", 0.3), ("descriptor_noise", 1.0),
                           ("min_visible_fraction", 1.0), ("geometry_noise_base_m", 1.0),
                           ("geometry_noise_per_m", 1.0)):
            check_real(name, getattr(self, name), 0.0, high)
        check_int("bands", self.bands, 1, 64)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def view_angle_deg(camera_xy: NDArray[np.floating], xy: NDArray[np.floating], facing_rad: NDArray[np.floating]
                   ) -> NDArray[np.float64]:
    """The person's facing relative to the direction to the camera (deg in [-180, 180), counter-clockwise):
    0 = facing the camera, 90 = facing the image's right, -90 its left, -180 = back to the camera."""
    pos = np.asarray(xy, dtype=np.float64)
    to_cam = np.asarray(camera_xy, dtype=np.float64)[:2] - pos
    bearing = np.arctan2(to_cam[..., 1], to_cam[..., 0])
    return (np.degrees(np.asarray(facing_rad, dtype=np.float64) - bearing) + 180.0) % 360.0 - 180.0


def _sector(view_deg: NDArray[np.floating]) -> NDArray[np.int64]:
    """The 45-deg sector (0 .. 7, sector s centred on s x 45 deg) of each view angle."""
    return np.rint(np.asarray(view_deg, dtype=np.float64) / _SECTOR_DEG).astype(np.int64) % VIEW_SECTORS


@dataclass(frozen=True)
class ClothesIdentity:
    """A crop identity as clothes: its crops (indices into :attr:`BodyBank.crops`) and, when their orientation
    is known, per source camera the crop shown in each view sector (``sector_crops[c][s]``)."""

    name: str
    crops: tuple[int, ...]
    sector_crops: tuple[tuple[int, ...], ...] = ()

    @property
    def oriented(self) -> bool:
        return bool(self.sector_crops)


class BodyBank:
    """The crop identities of a crops folder (read on demand) and the cached descriptors of degraded crops."""

    def __init__(self, bodies_dir: str | Path, projection: BodyProjection, log: TextIO | None = None) -> None:
        if not isinstance(projection, BodyProjection):
            raise ValueError(f"projection must be a BodyProjection, got {type(projection).__name__}")
        self.bodies_dir = Path(bodies_dir)
        if not self.bodies_dir.is_dir():
            raise InsufficientBodiesError(f"crops folder {self.bodies_dir} does not exist or is not a directory")
        try:
            listed = list_crops(self.bodies_dir)
        except ValueError as exc:
            raise InsufficientBodiesError(str(exc)) from None
        self._by_identity: dict[str, list[Crop]] = {}
        for crop in listed:
            self._by_identity.setdefault(crop.identity, []).append(crop)
        self.projection = projection
        self.log = log
        self.crops: list[Crop] = []  # the crops of the identities loaded so far (the scenario's crops list)
        self._images: list[NDArray[np.uint8]] = []
        self.skipped_unreadable: list[str] = []
        self._descriptors: dict[tuple[int, ...], NDArray[np.float32]] = {}
        self._textures: dict[tuple[int, ...], NDArray[np.uint8]] = {}

    @property
    def identity_names(self) -> list[str]:
        return sorted(self._by_identity)

    def crop_view_deg(self, index: int) -> float | None:
        """The view a crop shows (deg, :data:`PKU_VIEW_DEG`), None when its orientation is unknown."""
        return PKU_VIEW_DEG.get(self.crops[index].orientation)

    def crop_rows(self, index: int) -> int:
        return int(self._images[index].shape[0])

    def image(self, index: int) -> NDArray[np.uint8]:
        return self._images[index]

    def load_identity(self, name: str) -> ClothesIdentity | None:
        """Read one crop identity (None: no readable crop); its crops join :attr:`crops`."""
        indices: list[int] = []
        for crop in self._by_identity[name]:
            try:
                image = read_photo(crop.path)
            except PhotoError:
                image = None
            if image is None or image.shape[0] < 16 or image.shape[1] < 4:
                self.skipped_unreadable.append(crop.path.relative_to(self.bodies_dir).as_posix())
                continue
            indices.append(len(self.crops))
            self.crops.append(crop)
            self._images.append(np.ascontiguousarray(image))
        if not indices:
            return None
        oriented = [i for i in indices if self.crop_view_deg(i) is not None]
        sectors: list[tuple[int, ...]] = []
        for source in sorted({self.crops[i].camera for i in oriented}):
            own = [i for i in oriented if self.crops[i].camera == source]
            views = np.array([self.crop_view_deg(i) for i in own])
            table = []
            for s in range(VIEW_SECTORS):
                gap = np.abs((views - s * _SECTOR_DEG + 180.0) % 360.0 - 180.0)
                table.append(own[int(np.argmin(gap))])  # nearest orientation (ties: the first crop by name)
            sectors.append(tuple(table))
        return ClothesIdentity(name, tuple(oriented or indices), tuple(sectors))

    def choose(self, count: int, rng: np.random.Generator) -> list[ClothesIdentity]:
        """``count`` distinct usable crop identities in a random order (read only as needed)."""
        chosen = choose_usable(self.identity_names, count, rng, self.load_identity)
        if len(chosen) < count:
            raise InsufficientBodiesError(
                f"crops folder {self.bodies_dir} has {len(chosen)} usable crop identities, the scenario needs "
                f"{count} (each day's people wear their own; people on both days change clothes)"
            )
        return chosen

    def lit(self, index: int, gains: NDArray[np.floating], key: tuple[int, ...]) -> NDArray[np.uint8]:
        """The crop under a light (per-channel B, G, R gains), cached by ``key`` (who calls it names the light)."""
        full = (index, *key)
        out = self._textures.get(full)
        if out is None:
            image = self._images[index].astype(np.float32) * np.asarray(gains, dtype=np.float32)
            out = self._textures[full] = np.clip(np.rint(image), 0, 255).astype(np.uint8)
        return out

    def descriptor(self, index: int, gains: NDArray[np.floating], light_key: tuple[int, ...], bands_seen: int,
                   bands: int, rows: int, silhouette: float, variant: int = 0) -> NDArray[np.float32]:
        """The projected descriptor of crop ``index`` under a light, in frame variant ``variant``, with only the
        bands set in the bit mask ``bands_seen`` (bit k = band k of ``bands`` from the head top), at most
        ``rows`` rows and only the central ``silhouette`` share of its columns (the person; a camera cuts the
        background away); cached."""
        key = (index, *light_key, bands_seen, bands, rows, round(silhouette * 1000), variant)
        out = self._descriptors.get(key)
        if out is None:
            image = _frame_variant(self.lit(index, gains, light_key), variant, index)
            h, w = image.shape[:2]
            if rows < h:
                image = cv2.resize(image, (max(2, round(w * rows / h)), rows), interpolation=cv2.INTER_AREA)
                h = rows
            w = image.shape[1]
            band_of_row = np.minimum((np.arange(h) * bands) // h, bands - 1)
            seen_rows = ((bands_seen >> band_of_row) & 1).astype(bool)
            mask = seen_rows[:, None] & crop_person_mask(h, w, silhouette)
            desc = body_descriptor(image, mask, self.projection.descriptor_config)
            out = self._descriptors[key] = self.projection.project(desc)
        return out

    def crops_document(self) -> list[dict[str, Any]]:
        """The scenario's crops list: index, identity, path relative to the crops folder, camera, orientation."""
        return [{"index": i, "identity": c.identity, "path": c.path.relative_to(self.bodies_dir).as_posix(),
                 "camera": c.camera, "orientation": c.orientation, "view_deg": PKU_VIEW_DEG.get(c.orientation)}
                for i, c in enumerate(self.crops)]


def _frame_variant(image: NDArray[np.uint8], variant: int, seed: int) -> NDArray[np.uint8]:
    """One of the frame-to-frame changes of :data:`_FRAME_VARIANTS` (the noise seeded by ``seed``)."""
    spec = _FRAME_VARIANTS[variant]
    out = image
    if "dx" in spec or "dy" in spec or "scale" in spec:
        h, w = out.shape[:2]
        matrix = cv2.getRotationMatrix2D((w / 2.0, h / 2.0), 0.0, spec.get("scale", 1.0))
        matrix[0, 2] += spec.get("dx", 0.0)
        matrix[1, 2] += spec.get("dy", 0.0)
        out = cv2.warpAffine(out, matrix, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if "noise" in spec:
        noise = np.random.default_rng(seed).normal(0.0, spec["noise"], out.shape)
        out = np.clip(np.rint(out + noise), 0, 255).astype(np.uint8)
    if "blur" in spec:
        out = cv2.GaussianBlur(out, (0, 0), spec["blur"])
    return out


def make_measures(heights_m: NDArray[np.floating], rng: np.random.Generator) -> NDArray[np.float64]:
    """(n, len(MEASURE_FIELDS)) plausible body measures of n people of these heights (m)."""
    h = np.asarray(heights_m, dtype=np.float64).reshape(-1)
    n = h.size
    s = h / 1.75
    head = np.clip(0.27 * s + 0.015 * rng.standard_normal(n), 0.20, 0.34)
    shoulder_w = np.clip(0.44 * s + 0.03 * rng.standard_normal(n), 0.34, 0.56)
    shoulder_d = np.clip(0.24 + 0.02 * rng.standard_normal(n), 0.17, 0.32)
    torso_w = shoulder_w * rng.uniform(0.72, 0.86, n)
    torso_d = np.clip(0.23 + 0.025 * rng.standard_normal(n), 0.16, 0.34)
    hip_w = np.clip(0.34 * s + 0.025 * rng.standard_normal(n), 0.26, 0.46)
    hip_d = np.clip(0.22 + 0.02 * rng.standard_normal(n), 0.16, 0.30)
    return np.stack([head, shoulder_w, shoulder_d, torso_w, torso_d, hip_w, hip_d], axis=1)


def camera_light_gains(num_cameras: int, config: BodySimConfig, rng: np.random.Generator) -> NDArray[np.float64]:
    """(cameras, 3) per-channel (B, G, R) gains of each camera's light: an overall gain times a colour cast."""
    gain = rng.uniform(*config.light_gain_range, size=(num_cameras, 1))
    cast = 1.0 + rng.uniform(-config.light_cast, config.light_cast, size=(num_cameras, 3))
    return gain * cast


def part_overlap(part_edges: Sequence[float], bands: int) -> NDArray[np.float64]:
    """(parts, bands): the share of each descriptor part (fractions of the height from the top) that each
    band covers; a part's visibility is this matrix times the bands seen."""
    edges = np.asarray(part_edges, dtype=np.float64)
    lo, hi = np.arange(bands) / bands, (np.arange(bands) + 1) / bands
    overlap = np.clip(np.minimum(hi[None], edges[1:, None]) - np.maximum(lo[None], edges[:-1, None]), 0.0, None)
    return overlap / (edges[1:] - edges[:-1])[:, None]


@dataclass
class BodyWorld:
    """Everything bodies need while simulating: the bank, the clothes per (gt id, day), the measures per gt
    id, the cameras' lights and the body glance counter."""

    bank: BodyBank
    config: BodySimConfig
    clothes: dict[tuple[int, int], ClothesIdentity]
    measures: NDArray[np.float64]
    light: NDArray[np.float64]
    glance_counter: list[int] = field(default_factory=lambda: [0])

    @property
    def space(self) -> str:
        return self.bank.projection.space

    @property
    def dim(self) -> int:
        return self.bank.projection.length

    @property
    def parts(self) -> int:
        return self.bank.projection.descriptor_config.parts

    def glance_gains(self, camera: int, level: int) -> NDArray[np.float64]:
        return self.light[camera] * (1.0 + self.config.glance_light_step * level)


def assign_clothes(bank: BodyBank, days: Sequence[Day], rng: np.random.Generator
                   ) -> dict[tuple[int, int], ClothesIdentity]:
    """Distinct clothes for every (gt id, day): day 1 in gt order, then every day-2 person (returning people
    change clothes, new people get their own); nobody wears another's crop identity on any day."""
    slots = [(gt, d.day) for d in days for gt in d.gt_ids]
    chosen = bank.choose(len(slots), rng)
    return dict(zip(slots, chosen, strict=True))


def choose_crops(bodies: BodyWorld, day: int, gt_ids: Sequence[int], stamps: NDArray[np.float64],
                 present: NDArray[np.bool_], view_deg: NDArray[np.floating], glance_gap_s: float,
                 rng: np.random.Generator) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.int8]]:
    """Crop shown, body glance and light level (F, P) of one camera's frames where ``present`` (-1 / 0 elsewhere).

    Per glance (a run of present frames) one draw picks the source camera of an oriented identity's crops (the
    crop then follows each frame's view sector) or one crop of an identity without orientations, and one
    light level in {-1, 0, 1}; glances are numbered on from ``bodies.glance_counter``.
    """
    crop = np.full(present.shape, -1, dtype=np.int32)
    glance = np.full(present.shape, -1, dtype=np.int32)
    level = np.zeros(present.shape, dtype=np.int8)
    sector = _sector(view_deg)
    for p, gt in enumerate(gt_ids):
        ids, n_glances = glance_ids(stamps, present[:, p], glance_gap_s)
        if n_glances == 0:
            continue
        pick = rng.random(n_glances)
        light = rng.integers(-1, 2, size=n_glances).astype(np.int8)
        clothes = bodies.clothes[(int(gt), day)]
        rows = np.flatnonzero(ids >= 0)
        g = ids[rows]
        if clothes.oriented:
            table = np.asarray(clothes.sector_crops, dtype=np.int32)  # (sources, sectors)
            source = np.minimum((pick * table.shape[0]).astype(np.int64), table.shape[0] - 1)
            crop[rows, p] = table[source[g], sector[rows, p]]
        else:
            options = np.asarray(clothes.crops, dtype=np.int32)
            chosen = options[np.minimum((pick * options.size).astype(np.int64), options.size - 1)]
            crop[rows, p] = chosen[g]
        glance[rows, p] = g + bodies.glance_counter[0]
        level[rows, p] = light[g]
        bodies.glance_counter[0] += n_glances
    return crop, glance, level


def feature_bodies(
    bodies: BodyWorld, camera: SimCamera, cam_index: int, day: int, gt_ids: Sequence[int],
    stamps: NDArray[np.float64], xy: NDArray[np.float64], facing: NDArray[np.float64],
    heights: NDArray[np.float64], in_room: NDArray[np.bool_], detected: NDArray[np.bool_],
    f_idx: NDArray[np.intp], p_idx: NDArray[np.intp], measured_height: NDArray[np.floating],
    range_m: NDArray[np.float64], fx_color: float, glance_gap_s: float, rng: np.random.Generator,
    visibility_config: VisibilityConfig | None = None, rows_log: list[NDArray[np.int64]] | None = None,
) -> BodyRows:
    """Body rows of one camera's true detections (``f_idx``, ``p_idx``) over a day (see the module doc);
    ``rows_log`` (optional) collects the rows of every described crop and whether it was reduced."""
    cfg = bodies.config
    bank = bodies.bank
    view = view_angle_deg(camera.position[:2], xy, facing)
    crop, glance, level = choose_crops(bodies, day, gt_ids, stamps, detected, view, glance_gap_s, rng)
    n = f_idx.size
    seen = body_band_visibility(camera, xy, heights, in_room, cfg.bands, f_idx, p_idx, visibility_config)
    bits = (seen.astype(np.int64) << np.arange(cfg.bands)).sum(axis=1)
    visible = seen.mean(axis=1).astype(np.float32)
    edges = bank.projection.descriptor_config.part_edges
    part_visible = (seen.astype(np.float64) @ part_overlap(edges, cfg.bands).T).astype(np.float32)
    described = visible >= cfg.min_visible_fraction
    c = crop[f_idx, p_idx]
    lv = level[f_idx, p_idx]
    rng_d = range_m[f_idx, p_idx]
    crop_rows = np.array([bank.crop_rows(int(i)) for i in range(len(bank.crops))], dtype=np.int64)
    rows = body_rows(fx_color, heights[p_idx], rng_d, crop_rows[c])
    if rows_log is not None:
        rows_log.append(np.stack([rows[described], rows[described] < crop_rows[c][described]], axis=1))
    descriptor = np.zeros((n, bodies.dim), dtype=np.float32)
    variant = rng.integers(NUM_FRAME_VARIANTS, size=n)
    key = np.stack([c, lv, bits, rows, variant], axis=1)
    todo = np.flatnonzero(described)
    if todo.size:
        unique, inverse = np.unique(key[todo], axis=0, return_inverse=True)
        vectors = np.empty((unique.shape[0], bodies.dim), dtype=np.float32)
        for u, (ci, li, bi, ri, vi) in enumerate(unique.tolist()):
            vectors[u] = bank.descriptor(ci, bodies.glance_gains(cam_index, li), (cam_index, li), bi, cfg.bands, ri,
                                         cfg.silhouette_width, vi)
        descriptor[todo] = vectors[inverse.reshape(-1)]
        if cfg.descriptor_noise > 0:
            rms = np.sqrt(np.mean(descriptor[todo] ** 2, axis=1, keepdims=True))
            noise = rng.standard_normal((todo.size, bodies.dim)) * (cfg.descriptor_noise * rms)
            descriptor[todo] += noise.astype(np.float32)
    geometry = measured_geometry(bodies.measures[np.asarray(gt_ids, dtype=np.int64)[p_idx]], view[f_idx, p_idx],
                                 np.asarray(measured_height, dtype=np.float64), rng_d, seen, cfg, rng)
    return BodyRows(descriptor, described, visible, part_visible, geometry, c.astype(np.int32),
                    view[f_idx, p_idx].astype(np.float32), glance[f_idx, p_idx])


def body_rows(focal_px: float, height_m: NDArray[np.floating], range_m: NDArray[np.floating],
              crop_rows: NDArray[np.integer]) -> NDArray[np.int64]:
    """Rows a crop is described at: the rows the person spans in the colour image (focal x height / range), down to
    a multiple of 16 (a cache step) from 32 rows on (at least 2), never more than the crop has (never enlarged)."""
    span = np.asarray(focal_px * np.asarray(height_m, dtype=np.float64) / np.maximum(range_m, 0.1))
    rows = np.where(span >= 32.0, np.floor(span / 16.0) * 16.0, np.floor(np.maximum(span, 2.0)))
    return np.minimum(rows.astype(np.int64), np.asarray(crop_rows, dtype=np.int64))


# the span of the body (fractions of the height below the head top) a measure needs seen: the camera's bands
_NEEDS = {"head_height_m": (0.0, 0.25),
          **{name: (round(1.0 - hi, 6), round(1.0 - lo, 6)) for name, (lo, hi) in GEOMETRY_BANDS.items()}}


def measured_geometry(measures: NDArray[np.float64], view_deg: NDArray[np.float64], height: NDArray[np.float64],
                      range_m: NDArray[np.float64], seen: NDArray[np.bool_], cfg: BodySimConfig,
                      rng: np.random.Generator) -> NDArray[np.float32]:
    """(n, 6) GEOMETRY_FIELDS as a depth camera measures them from these views and ranges (NaN: band unseen).

    A width across the line of sight is the extent of an ellipse of the measure's width and depth seen at
    the view angle (front: the width, side: the depth); the torso depth is the visible surface's extent along
    the line of sight (the nearest point to the silhouette: half the ellipse's extent along it).
    """
    n = view_deg.size
    a = np.radians(view_deg)
    c2, s2 = np.cos(a) ** 2, np.sin(a) ** 2
    m = {name: measures[:, i] for i, name in enumerate(MEASURE_FIELDS)}

    def across(width: NDArray[np.float64], depth: NDArray[np.float64]) -> NDArray[np.float64]:
        return 2.0 * np.sqrt((width / 2.0) ** 2 * c2 + (depth / 2.0) ** 2 * s2)

    values = {
        "height_m": height,
        "head_height_m": m["head_height_m"],
        "shoulder_width_m": across(m["shoulder_width_m"], m["shoulder_depth_m"]),
        "torso_width_m": across(m["torso_width_m"], m["torso_depth_m"]),
        "torso_depth_m": np.sqrt((m["torso_width_m"] / 2.0) ** 2 * s2 + (m["torso_depth_m"] / 2.0) ** 2 * c2),
        "hip_width_m": across(m["hip_width_m"], m["hip_depth_m"]),
    }
    std = cfg.geometry_noise_base_m + cfg.geometry_noise_per_m * range_m
    noise = rng.standard_normal((n, len(GEOMETRY_FIELDS))) * std[:, None]
    out = np.empty((n, len(GEOMETRY_FIELDS)), dtype=np.float64)
    bands = seen.shape[1]
    for name, col in _GEOMETRY_INDEX.items():
        out[:, col] = values[name] + (noise[:, col] if name != "height_m" else 0.0)  # height: the detection's
        if name in _NEEDS:
            lo, hi = _NEEDS[name]
            first, last = int(lo * bands), min(bands - 1, math.ceil(hi * bands) - 1)
            out[~seen[:, first: last + 1].all(axis=1), col] = np.nan
    return out.astype(np.float32)
