"""Pixel level: every camera frame rendered (RGB-D, the glance's photo on the face) and run through the real
:class:`~face_reid_camera.pipeline.CameraPipeline`; its detections are matched to the simulated people by
position (within 0.5 m) for the ground truth.

With bodies (:mod:`~face_reid_master.sim.bodies`) each person's body is textured with the crop of their clothes
whose orientation matches their view from that camera (the glance's source camera and light level, chosen as
at the feature level over the frames the person is in the room; the camera's light applied to the crop) and
their shoulder width is their measure; the camera pipeline describes the bodies (descriptor with the same
projection, geometry, visibility) and those are stored.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TextIO

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics
from face_reid_master.sim.bodies import MEASURE_FIELDS, BodyWorld, choose_crops, view_angle_deg
from face_reid_master.sim.frame_table import BodyRows, DetectionColumns
from face_reid_master.sim.motion import sample_trajectories
from face_reid_master.sim.photos import IdentityPhotos, PhotoBank, glance_photos
from face_reid_master.sim.streams import S_BODY_VIEW, S_FACES, S_LOOK, S_RENDER, stream_rng
from face_reid_master.sim.visibility import camera_visibility
from face_reid_master.sim.world import World

if TYPE_CHECKING:
    from face_reid_camera.pipeline import PersonObservation
    from face_reid_master.sim.simulate import Day, SimConfig

__all__ = ["color_intrinsics", "pixel_camera_frames"]


def color_intrinsics(depth: CameraIntrinsics, resolution: tuple[int, int] | None) -> CameraIntrinsics | None:
    """A colour camera of ``resolution`` (W, H) with the depth camera's horizontal field of view and optical
    frame (square pixels, centred principal point); None: colour registered at the depth resolution."""
    if resolution is None:
        return None
    w, h = resolution
    fx = depth.fx * w / depth.width
    return CameraIntrinsics(fx, fx, (w - 1) / 2.0, (h - 1) / 2.0, w, h)


def pixel_camera_frames(
    cfg: SimConfig, world: World, day: Day, per_cam_stamps: list[NDArray[np.float64]],
    identities: list[IdentityPhotos], photo_offsets: list[int], heights: NDArray[np.float64],
    bank: PhotoBank, glance_counter: list[int], log: TextIO | None, frames_done: list[int], frames_total: int,
    bodies: BodyWorld | None = None,
) -> list[DetectionColumns]:
    """Render every camera frame of one day and run the real camera pipeline on it (``bodies``: textured
    bodies, described by the pipeline)."""
    from scipy.optimize import linear_sum_assignment

    from face_reid_camera.faces.photos import read_photo
    from face_reid_camera.pipeline import CameraPipeline, CameraPipelineConfig
    from face_reid_master.sim.renderer import SyntheticPerson, crop_face_for_rendering, render_scene

    photos_flat = [ph for ident in identities for ph in ident.photos]
    crops: dict[int, NDArray[np.uint8]] = {}

    def crop_of(photo: int) -> NDArray[np.uint8]:
        if photo not in crops:
            ph = photos_flat[photo]
            crops[photo] = crop_face_for_rendering(read_photo(bank.faces_dir / ph.rel_path), ph.box_xywh)
        return crops[photo]

    embedder = bank.photo_embedder
    look = stream_rng(cfg.seed, S_LOOK, day.day)
    clothes = {gt: (tuple(int(c) for c in look.integers(20, 230, 3)), tuple(int(c) for c in look.integers(20, 120, 3)),
                    tuple(int(c) for c in look.integers(10, 90, 3))) for gt in day.gt_ids}
    floor = float(max(world.room.width_m, world.room.depth_m) + 4.0)
    out: list[DetectionColumns] = []
    step = max(1, frames_total // 10)
    for cam_index, stamps in enumerate(per_cam_stamps):
        camera = world.cameras[cam_index]
        color_intr = color_intrinsics(camera.intrinsics, cfg.color_resolution)
        rng_face = stream_rng(cfg.seed, S_FACES, day.day, cam_index)
        # no embedding budget: it follows the wall clock, and a simulation must be reproducible
        pipeline = CameraPipeline(
            CameraPipelineConfig(camera_id=camera.camera_id, embed_budget_ms=0.0, describe_bodies=bodies is not None),
            camera.pose, embedder.detector, embedder.embedder,
            body_projection=bodies.bank.projection if bodies is not None else None)
        cols = DetectionColumns(dim=bank.dim)
        out.append(cols)
        if stamps.size == 0:
            continue
        xy, facing = sample_trajectories(day.trajectories, stamps)
        in_room = world.room.contains(xy)
        vis = camera_visibility(camera, xy, facing, heights, in_room, cfg.visibility)
        photo_of, glance_of = glance_photos(stamps, vis.face_visible, day.gt_ids, day.day, identities, photo_offsets,
                                            cfg.glance_gap_s, rng_face, glance_counter)
        if bodies is not None:
            view = view_angle_deg(camera.position[:2], xy, facing)
            body_crop, body_glance, light = choose_crops(bodies, day.day, day.gt_ids, stamps, in_room, view,
                                                       cfg.glance_gap_s, stream_rng(cfg.seed, S_BODY_VIEW, day.day,
                                                                                    cam_index))
        for f in range(stamps.size):
            people, index = [], []
            for p, gt in enumerate(day.gt_ids):
                if not in_room[f, p]:
                    continue
                face = crop_of(int(photo_of[f, p])) if photo_of[f, p] >= 0 else None
                body, legs, hair = clothes[gt]
                texture, shoulders = None, 0.45
                if bodies is not None:
                    level = int(light[f, p])
                    texture = bodies.bank.lit(int(body_crop[f, p]), bodies.glance_gains(cam_index, level),
                                              (cam_index, level))
                    shoulders = float(np.clip(bodies.measures[gt, MEASURE_FIELDS.index("shoulder_width_m")], 0.3, 0.8))
                people.append(SyntheticPerson(float(xy[f, p, 0]), float(xy[f, p, 1]), float(heights[p]),
                                              float(facing[f, p]), face_image_bgr=face, body_color_bgr=body,
                                              legs_color_bgr=legs, hair_color_bgr=hair, shoulder_width_m=shoulders,
                                              body_texture_bgr=texture))
                index.append(p)
            render = dict(max_face_angle_deg=cfg.visibility.max_face_angle_deg, floor_size_m=floor,
                          max_range_m=cfg.visibility.max_range_m)  # the depth range of the world model
            frame = render_scene(people, camera.intrinsics, camera.pose,
                                 rng=stream_rng(cfg.seed, S_RENDER, day.day, cam_index, f), **render)
            depth = frame.depth_mm.astype(np.float32) / np.float32(1000.0)
            depth[frame.depth_mm == 0] = np.nan
            color = frame.rgb_bgr
            if color_intr is not None:  # colour at its own resolution: rendered again at that size
                color = render_scene(people, color_intr, camera.pose,
                                     rng=stream_rng(cfg.seed, S_RENDER, day.day, cam_index, f), **render).rgb_bgr
            result = pipeline.process(color, depth, camera.intrinsics, color_intr)
            dets = result.people
            gt_ids = np.full(len(dets), -1, dtype=np.int32)
            matched_p = np.full(len(dets), -1, dtype=np.int64)
            if dets and index:
                det_xy = np.array([d.position_world[:2] for d in dets])
                true_xy = xy[f, index]
                cost = np.linalg.norm(det_xy[:, None] - true_xy[None], axis=2)
                rows, cols_ = linear_sum_assignment(cost)
                for r, c in zip(rows, cols_, strict=True):
                    if cost[r, c] <= 0.5:
                        matched_p[r] = index[c]
                        gt_ids[r] = day.gt_ids[index[c]]
            has_face = np.array([d.face is not None for d in dets], dtype=bool)
            fi = np.flatnonzero(has_face)
            emb = np.array([dets[i].face.embedding for i in fi], dtype=np.float32).reshape(-1, bank.dim)  # type: ignore[union-attr]
            eye = np.array([dets[i].face.eye_distance_px for i in fi], dtype=np.float32)  # type: ignore[union-attr]
            score = np.array([dets[i].face.detection.score for i in fi], dtype=np.float32)  # type: ignore[union-attr]
            quality = np.array([dets[i].face.quality for i in fi], dtype=np.float32)  # type: ignore[union-attr]
            photo = np.array([photo_of[f, matched_p[i]] if matched_p[i] >= 0 else -1 for i in fi], dtype=np.int32)
            glance = np.array([glance_of[f, matched_p[i]] if matched_p[i] >= 0 else -1 for i in fi], dtype=np.int32)
            cols.append(np.full(len(dets), f), gt_ids,
                    np.array([d.position_world for d in dets]).reshape(-1, 3),
                    np.array([d.position_std_m for d in dets]), np.array([d.height_m for d in dets]),
                    has_face, emb, score, quality, photo, glance, np.full(fi.size, -1, np.int16), eye)
            if bodies is not None:
                has_body = np.array([d.body is not None for d in dets], dtype=bool)
                cols.append_bodies(has_body, _body_rows(bodies, dets, has_body, matched_p, f, body_crop, view,
                                                        body_glance))
            frames_done[0] += 1
            if log is not None and (frames_done[0] % step == 0 or frames_done[0] == frames_total):
                log.write(f"  rendered + processed {frames_done[0]}/{frames_total} frames\n")
                log.flush()
    return out


def _body_rows(bodies: BodyWorld, dets: list[PersonObservation], has_body: NDArray[np.bool_],
               matched_p: NDArray[np.int64], f: int, crop_of: NDArray[np.int32], view: NDArray[np.float64],
               glance: NDArray[np.int32]) -> BodyRows:
    """The body rows of one frame's detections that the camera pipeline described."""
    rows = [dets[i] for i in np.flatnonzero(has_body)]
    matched = matched_p[has_body]
    n = len(rows)
    descriptor = np.zeros((n, bodies.dim), dtype=np.float32)
    described = np.zeros(n, dtype=bool)
    part_visible = np.zeros((n, bodies.parts), dtype=np.float32)
    for k, d in enumerate(rows):
        assert d.body is not None
        vec = np.asarray(d.body.descriptor, dtype=np.float32).reshape(-1)
        if vec.size == bodies.dim and d.body.space == bodies.space:
            descriptor[k] = vec
            described[k] = True
        parts = np.asarray(d.body.part_visible, dtype=np.float32)[: bodies.parts]
        part_visible[k, : parts.size] = parts
    ok = matched >= 0
    p = np.maximum(matched, 0)
    return BodyRows(
        descriptor, described, np.array([d.body.visible_fraction for d in rows if d.body], dtype=np.float32),
        part_visible, np.array([d.body.geometry.vector() for d in rows if d.body], dtype=np.float32).reshape(n, 6),
        np.where(ok, crop_of[f, p], -1).astype(np.int32),
        np.where(ok, view[f, p], np.nan).astype(np.float32),
        np.where(ok, glance[f, p], -1).astype(np.int32),
    )
