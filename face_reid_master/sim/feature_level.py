"""Feature level: camera messages made directly from the world model, faces from real photo embeddings (fast).

A camera detects each person it can see (misses at ``miss_probability``) with a noisy position (std growing
with distance, plus a per-camera calibration bias) and a noisy height; a visible face is found with a
probability falling off with angle and range, and carries the embedding of a variant of its glance's photo
allowed at its range, plus a little Gaussian noise (``embedding_noise_std`` per dimension). False positives
are clutter in the camera's view, never with a face. With bodies (:mod:`~face_reid_master.sim.bodies`)
every true detection also carries its body (descriptor of its crop as this camera sees it, visibility,
geometry); false positives carry none.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.pipeline import FaceQualityConfig, face_quality
from face_reid_master.sim.bodies import BodyWorld, feature_bodies
from face_reid_master.sim.frame_table import BodyRows, DetectionColumns
from face_reid_master.sim.motion import sample_trajectories
from face_reid_master.sim.photos import IdentityPhotos, glance_photos, range_bucket, valid_variants, variant_eye_px
from face_reid_master.sim.streams import S_BODY_VIEW, S_CAMERA, S_FACES, S_FP, stream_rng
from face_reid_master.sim.visibility import camera_visibility
from face_reid_master.sim.world import World

if TYPE_CHECKING:
    from face_reid_master.sim.simulate import Day, SimConfig

__all__ = ["feature_camera_day"]

_KINECT_FX_PX = 525.0
_EYE_DISTANCE_M = 0.063


def feature_camera_day(
    cfg: SimConfig, world: World, cam_index: int, day: Day, stamps: NDArray[np.float64],
    identities: list[IdentityPhotos], photo_offsets: list[int], heights: NDArray[np.float64],
    camera_bias: NDArray[np.float64], glance_counter: list[int], bodies: BodyWorld | None = None,
) -> DetectionColumns:
    """Camera messages of one camera over one day, made directly from the world model (with ``bodies``: their
    body rows too)."""
    camera = world.cameras[cam_index]
    dim = int(identities[0].photos[0].embeddings.shape[1])
    # colour at its own resolution (same horizontal field of view as depth): faces have more pixels
    fx_color = _KINECT_FX_PX * (cfg.color_resolution[0] / camera.intrinsics.width if cfg.color_resolution else 1.0)
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
    # faces: embedding of a variant allowed at this range (+ noise); detector score and quality
    fi = np.flatnonzero(has_face)
    photos_flat = [ph for ident in identities for ph in ident.photos]
    valid_cache: dict[int, list[list[int]]] = {}
    # photo variants by the range at which a 640x480 Kinect shows a face of this many pixels
    buckets = range_bucket(rng_m[f_idx[fi], p_idx[fi]] * (_KINECT_FX_PX / fx_color))
    picks_u = rng_face.random(fi.size)
    embeddings = np.empty((fi.size, dim), dtype=np.float32)
    variants = np.empty(fi.size, dtype=np.int16)
    variant_px = np.empty(fi.size, dtype=np.float32)  # the size of the face the embedding shows
    face_photo = photo_of[f_idx[fi], p_idx[fi]]
    for k in range(fi.size):
        ph = int(face_photo[k])
        valid = valid_cache.get(ph)
        if valid is None:
            valid = valid_cache[ph] = valid_variants(photos_flat[ph])
        choices = valid[int(buckets[k])]
        v = choices[min(int(picks_u[k] * len(choices)), len(choices) - 1)]
        variants[k] = v
        variant_px[k] = variant_eye_px(photos_flat[ph], v)
        embeddings[k] = photos_flat[ph].embeddings[v]
    if fi.size and cfg.embedding_noise_std > 0:
        embeddings += (cfg.embedding_noise_std * rng_face.normal(size=embeddings.shape)).astype(np.float32)
    face_angle = angle[f_idx[fi], p_idx[fi]]
    face_range = rng_m[f_idx[fi], p_idx[fi]]
    score = np.clip(0.93 - 0.002 * face_angle - 0.02 * face_range + 0.03 * rng_face.normal(size=fi.size), 0.6, 0.99)
    eye_px = fx_color * _EYE_DISTANCE_M / np.maximum(face_range, 0.1) * np.cos(np.radians(face_angle))
    qcfg = FaceQualityConfig()
    quality = np.array([face_quality(float(s), float(e), float(a), qcfg) for s, e, a in
                        zip(score, eye_px, face_angle, strict=True)], dtype=np.float32)
    cols.append(f_idx, gt, pos, std, height, has_face, embeddings, score, quality, face_photo,
                glance_of[f_idx[fi], p_idx[fi]], variants, variant_px)
    if bodies is not None:
        rows = feature_bodies(bodies, camera, cam_index, day.day, day.gt_ids, stamps, xy, facing, heights, in_room,
                              detected, f_idx, p_idx, height, rng_m, fx_color, cfg.glance_gap_s,
                              stream_rng(cfg.seed, S_BODY_VIEW, day.day, cam_index), cfg.visibility)
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
