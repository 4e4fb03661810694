"""Feature level: camera messages made directly from the world model, faces from real photo embeddings (fast).

A camera detects each person it can see (misses at ``miss_probability``) with a noisy position (std growing
with distance, plus a per-camera calibration bias) and a noisy height; a visible face is found with a
probability falling off with angle and range, and carries the camera-true embedding of its glance's photo
(:meth:`~face_reid_master.sim.photos.PhotoBank.camera_view`: the glance's frame change, down-sampled to the eye
distance the camera's colour focal length, the range and the face's angle give, re-detected and re-embedded),
plus a little Gaussian noise (``embedding_noise_std`` per dimension); a face whose eyes would be closer than
``MIN_EYE_PX`` in the image is not found. False positives
are clutter in the camera's view, never with a face. With bodies (:mod:`~face_reid_master.sim.bodies`)
every true detection also carries its body (descriptor of its crop as this camera sees it, visibility,
geometry); false positives carry none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.pipeline import FaceQualityConfig, face_quality
from face_reid_master.sim.bodies import BodyWorld, feature_bodies
from face_reid_master.sim.frame_table import BodyRows, DetectionColumns
from face_reid_master.sim.motion import sample_trajectories
from face_reid_master.sim.photos import (
    EYE_LEVEL_STEP,
    MIN_EYE_PX,
    NATIVE_LEVEL,
    NUM_FRAME_CHANGES,
    TOO_SMALL_LEVEL,
    IdentityPhotos,
    PhotoBank,
    eye_level,
    glance_photos,
    level_eye_px,
)
from face_reid_master.sim.streams import S_BODY_VIEW, S_CAMERA, S_FACES, S_FP, stream_rng
from face_reid_master.sim.visibility import camera_visibility
from face_reid_master.sim.world import World

if TYPE_CHECKING:
    from face_reid_master.sim.simulate import Day, SimConfig

__all__ = ["EYE_DISTANCE_M", "KINECT_FX_PX", "CameraTrueLog", "color_focal_px", "face_eye_px", "feature_camera_day"]

KINECT_FX_PX = 525.0  # the depth camera's focal length at 640 px wide
EYE_DISTANCE_M = 0.063  # interpupillary distance of every simulated face


@dataclass
class CameraTrueLog:
    """What the camera gave the faces and bodies of a scenario (collected over cameras and days): per face found
    the geometry's eye distance, the eye distance shown, shown at the photo's own size, re-detected by YuNet;
    per described body its rows and whether the crop was reduced to them; faces too small to be found."""

    focal_px: float = 0.0
    faces: list[NDArray[np.float64]] = field(default_factory=list)
    bodies: list[NDArray[np.int64]] = field(default_factory=list)
    too_small: int = 0

    def record(self, level: str) -> dict[str, Any]:
        """The ``summary.camera_true`` record of scenario.json (pixel level: frames are rendered at the camera's
        resolution, camera-true by construction)."""
        out: dict[str, Any] = {"camera_true": True, "level": level, "focal_px": round(self.focal_px, 3),
                               "eye_distance_m": EYE_DISTANCE_M}
        if level != "feature":
            return out
        faces = np.concatenate(self.faces) if self.faces else np.zeros((0, 4))
        bodies = np.concatenate(self.bodies) if self.bodies else np.zeros((0, 2), dtype=np.int64)

        def spread(values: NDArray[Any]) -> dict[str, float] | None:
            if values.size == 0:
                return None
            p10, p50, p90 = np.percentile(values, [10, 50, 90])
            return {"p10": round(float(p10), 2), "median": round(float(p50), 2), "p90": round(float(p90), 2)}

        out.update({
            "eye_level_step": EYE_LEVEL_STEP, "min_eye_px": MIN_EYE_PX,
            "face_eye_px_geometry": spread(faces[:, 0]), "face_eye_px_shown": spread(faces[:, 1]),
            "faces_at_photo_size": round(float(faces[:, 2].mean()), 4) if faces.size else None,
            "faces_redetected": round(float(faces[:, 3].mean()), 4) if faces.size else None,
            "faces_too_small": int(self.too_small),
            "body_rows": spread(bodies[:, 0]),
            "bodies_reduced": round(float(bodies[:, 1].mean()), 4) if bodies.size else None,
        })
        return out


def color_focal_px(color_resolution: tuple[int, int] | None, depth_width_px: int) -> float:
    """The colour camera's focal length (px): same horizontal field of view as depth, at its own width."""
    return KINECT_FX_PX * (color_resolution[0] / depth_width_px if color_resolution else 1.0)


def face_eye_px(focal_px: float, range_m: NDArray[np.floating], angle_deg: NDArray[np.floating]
                ) -> NDArray[np.float64]:
    """Eye distance (px) the camera's geometry gives a face at this range, turned this far from the camera."""
    return focal_px * EYE_DISTANCE_M / np.maximum(np.asarray(range_m, dtype=np.float64), 0.1) * np.cos(
        np.radians(angle_deg))


def feature_camera_day(
    cfg: SimConfig, world: World, cam_index: int, day: Day, stamps: NDArray[np.float64],
    identities: list[IdentityPhotos], photo_offsets: list[int], heights: NDArray[np.float64],
    camera_bias: NDArray[np.float64], glance_counter: list[int], bank: PhotoBank, bodies: BodyWorld | None = None,
    camera_true: CameraTrueLog | None = None,
) -> DetectionColumns:
    """Camera messages of one camera over one day, made directly from the world model (with ``bodies``: their
    body rows too); ``bank`` makes the faces' camera views; ``camera_true`` (optional) collects their sizes."""
    camera = world.cameras[cam_index]
    dim = int(identities[0].photos[0].embeddings.shape[1])
    fx_color = color_focal_px(cfg.color_resolution, camera.intrinsics.width)
    rng_det = stream_rng(cfg.seed, S_CAMERA, day.day, cam_index)
    rng_face = stream_rng(cfg.seed, S_FACES, day.day, cam_index)
    rng_fp = stream_rng(cfg.seed, S_FP, day.day, cam_index)
    cols = DetectionColumns(dim=dim)
    n_f, n_p = stamps.size, len(day.gt_ids)
    if n_f == 0:
        return cols
    xy, facing = sample_trajectories(day.trajectories, stamps)
    in_room = world.room.contains(xy)
    vis = camera_visibility(camera, xy, facing, heights, in_room, cfg.visibility)
    detected = vis.detectable & (rng_det.random((n_f, n_p)) >= cfg.miss_probability)
    photo_of, glance_of = glance_photos(stamps, vis.face_visible, day.gt_ids, day.day, identities, photo_offsets,
                                        cfg.glance_gap_s, rng_face, glance_counter)
    angle = vis.face_angle_deg
    rng_m = vis.range_m
    p_face = cfg.face_detect_probability * (1.0 - 0.3 * np.clip((angle - 30.0) / 20.0, 0.0, 1.0)) * (
        1.0 - 0.3 * np.clip((rng_m - 3.5) / 1.0, 0.0, 1.0))
    face_found = detected & vis.face_visible & (rng_face.random((n_f, n_p)) < p_face)
    f_idx, p_idx = np.nonzero(detected)
    n = f_idx.size
    horiz = np.hypot(*(xy[f_idx, p_idx] - camera.position[:2]).T) if n else np.zeros(0)
    std = cfg.position_noise_base_m + cfg.position_noise_per_m * horiz
    pos = np.zeros((n, 3))
    pos[:, :2] = xy[f_idx, p_idx] + camera_bias + rng_det.normal(size=(n, 2)) * std[:, None]
    height = heights[p_idx] + cfg.height_noise_m * rng_det.normal(size=n)
    gt = np.asarray(day.gt_ids, dtype=np.int32)[p_idx]
    has_face = face_found[f_idx, p_idx]
    # faces: the camera-true view of the glance's photo (a frame change, the geometry's eye distance) + noise
    fi = np.flatnonzero(has_face)
    photos_flat = [ph for ident in identities for ph in ident.photos]
    picks_u = rng_face.random(fi.size)
    face_photo = photo_of[f_idx[fi], p_idx[fi]]
    eye_px = face_eye_px(fx_color, rng_m[f_idx[fi], p_idx[fi]], angle[f_idx[fi], p_idx[fi]])
    native = np.array([photos_flat[int(ph)].eye_px for ph in face_photo], dtype=np.float64)
    levels = eye_level(eye_px, native)
    seen = levels != TOO_SMALL_LEVEL  # eyes closer than MIN_EYE_PX: no detector finds that face
    has_face[fi[~seen]] = False
    fi, picks_u, face_photo, eye_px, native, levels = (a[seen] for a in (fi, picks_u, face_photo, eye_px, native,
                                                                         levels))
    # one frame change per glance (its light and head roll), drawn at its first face
    _, first, inverse = np.unique(glance_of[f_idx[fi], p_idx[fi]], return_index=True, return_inverse=True)
    per_glance = np.minimum((picks_u[first] * NUM_FRAME_CHANGES).astype(np.int16), NUM_FRAME_CHANGES - 1)
    variants = per_glance[inverse.reshape(-1)]
    variant_px = level_eye_px(levels, native).astype(np.float32)  # the size of the face the embedding shows
    embeddings = np.empty((fi.size, dim), dtype=np.float32)
    redetected = np.empty(fi.size, dtype=bool)
    for k in range(fi.size):
        embeddings[k], redetected[k] = bank.camera_view(photos_flat[int(face_photo[k])], int(variants[k]),
                                                        int(levels[k]))
    if camera_true is not None:
        camera_true.focal_px = fx_color
        camera_true.too_small += int((~seen).sum())
        camera_true.faces.append(np.stack([eye_px, variant_px, levels == NATIVE_LEVEL, redetected], axis=1))
    if fi.size and cfg.embedding_noise_std > 0:
        embeddings += (cfg.embedding_noise_std * rng_face.normal(size=embeddings.shape)).astype(np.float32)
    face_angle = angle[f_idx[fi], p_idx[fi]]
    face_range = rng_m[f_idx[fi], p_idx[fi]]
    score = np.clip(0.93 - 0.002 * face_angle - 0.02 * face_range + 0.03 * rng_face.normal(size=fi.size), 0.6, 0.99)
    qcfg = FaceQualityConfig()
    quality = np.array([face_quality(float(s), float(e), float(a), qcfg) for s, e, a in
                        zip(score, eye_px, face_angle, strict=True)], dtype=np.float32)
    cols.append(f_idx, gt, pos, std, height, has_face, embeddings, score, quality, face_photo,
                glance_of[f_idx[fi], p_idx[fi]], variants, variant_px)
    if bodies is not None:
        rows = feature_bodies(bodies, camera, cam_index, day.day, day.gt_ids, stamps, xy, facing, heights, in_room,
                              detected, f_idx, p_idx, height, rng_m, fx_color, cfg.glance_gap_s,
                              stream_rng(cfg.seed, S_BODY_VIEW, day.day, cam_index), cfg.visibility,
                              None if camera_true is None else camera_true.bodies)
        cols.append_bodies(np.ones(n, dtype=bool), rows)
    # false positives: clutter somewhere in the camera's view, never with a face
    n_fp = rng_fp.poisson(cfg.false_positives_per_frame, size=n_f)
    fp_frames = np.repeat(np.arange(n_f), n_fp)
    if fp_frames.size:
        m = fp_frames.size
        hfov = math.atan2(camera.intrinsics.width / 2.0, camera.intrinsics.fx)
        yaw = camera.xyz_rpy[5]
        dist = rng_fp.uniform(1.0, 0.8 * cfg.visibility.max_range_m, size=m)
        bearing = yaw + rng_fp.uniform(-hfov, hfov, size=m)
        fp_xy = camera.position[:2] + dist[:, None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=1)
        keep = world.room.contains(fp_xy)
        m = int(keep.sum())
        fp_pos = np.zeros((m, 3))
        fp_pos[:, :2] = fp_xy[keep]
        fp_std = (cfg.position_noise_base_m + cfg.position_noise_per_m * dist[keep]).astype(np.float32)
        cols.append(fp_frames[keep], np.full(m, -1, np.int32), fp_pos, fp_std,
                rng_fp.uniform(1.0, 2.0, size=m), np.zeros(m, bool), np.zeros((0, dim), np.float32),
                np.zeros(0), np.zeros(0), np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, np.int16))
        if bodies is not None:
            cols.append_bodies(np.zeros(m, dtype=bool), BodyRows.empty(bodies.dim, bodies.parts))
    return cols
