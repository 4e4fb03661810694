"""The scenario directory: what :func:`write_scenario` writes and :func:`load_scenario` reads back.

- ``scenario.json``: ``format`` ("face-reid-scenario"), ``version``, ``level``, ``seed``,
  ``parameters`` (every setting), ``room``, ``doors``, ``cameras`` (id, xyz_rpy, rotation, translation,
  intrinsics, frame phase), ``photos`` (index, identity, path relative to ``faces_dir``),
  ``identities`` (gt_id, name, height_m, days, photos per day as photo indices), ``days`` (day,
  start_s, end_s, gt_ids) and ``summary`` (frames, detections, faces, glances, false positives, track
  losses and visible segments per person and in total, coverage, skipped photos; per day also
  ``closest_approach_m``, the closest two people in the room came at the ground truth's samples, and, when
  people kept ``parameters.motion.passing_distance_m`` apart, ``giving_way``: shares of the time in the room
  slowed and off the planned path, the largest delay, steps blocked; :mod:`face_reid_master.sim.crowd`).
- ``frames.npz``: camera frames in stamp order (ties: camera order) and their detections, flat:
  ``frame_camera`` (F,) int16 index into cameras, ``frame_stamp_s`` (F,) float64, ``frame_offsets``
  (F+1,) int64: detections of frame i are rows offsets[i]:offsets[i+1] of ``det_position`` (D, 3)
  float64 world m, ``det_std_m`` (D,) float32, ``det_height_m`` (D,) float32, ``det_gt_id`` (D,) int32
  (-1 = false positive), ``det_face`` (D,) int32 row into the face arrays or -1; ``face_embedding``
  (E, dim) float32 in the space ``embedding_space`` of scenario.json (dlib_resnet_v1 when absent: 128
  values; 256 for both embedders), ``face_score``, ``face_quality`` (E,) float32, ``face_photo`` (E,) int32
  photo index (-1 unknown), ``face_glance`` (E,) int32, ``face_variant`` (E,) int16 (the frame change,
  -1 at pixel level),
  ``face_eye_px`` (E,) float32 size of the face the embedding shows (optional: 0 = unknown).
  Bodies (optional, scenarios made with ``--bodies``; :mod:`face_reid_master.sim.bodies`): ``det_body`` (D,)
  int32 row into the body arrays or -1 (false positives at feature level, undescribed detections at pixel
  level); ``body_descriptor`` (B, k) float32 projected appearance in space ``body_space`` (zeros where not
  ``body_described`` (B,) bool: too little visible); ``body_visible`` (B,) float32 share of the height seen;
  ``body_part_visible`` (B, parts) float32; ``body_geometry`` (B, 6) float32 in GEOMETRY_FIELDS order
  (height, head height, shoulder / torso width, torso depth, hip width; m, NaN = not measured);
  ``body_crop`` (B,) int32 index into ``body_crops`` (the crop shown, -1 unknown); ``body_view_deg`` (B,)
  float32 the true view angle (the person's facing relative to the direction to the camera, counter-
  clockwise, 0 = facing it; NaN unknown); ``body_glance`` (B,) int32 (-1 unknown).
  scenario.json then has ``bodies_dir``, ``body_space``, ``body_descriptor_length``, ``body_crops`` (index,
  identity = crop folder, path relative to ``bodies_dir``, camera, orientation, view_deg),
  ``body_orientation_view_deg`` (the view each PKU-Reid orientation code is taken to show), and per identity
  ``clothes`` ({"1": crop folder worn on day 1, "2": ... on day 2}) and ``body_measures`` (m).
- ``ground_truth.npz``: ``t_s`` (T,) at ``ground_truth_rate_hz`` for each day, ``day`` (T,) int8,
  ``gt_id`` (P,) int32, ``xy`` (P, T, 2) float32 (NaN when the person is absent that day),
  ``facing_rad`` (P, T) float32, ``in_room`` (P, T), ``in_view`` (P, T, M), ``face_visible`` (P, T, M) bool.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.camera_model import CameraIntrinsics, CameraPose
from face_reid_camera.common.atomic_file import write_atomically, write_npz
from face_reid_camera.common.embedding_spaces import DLIB_SPACE, space_dim
from face_reid_master.records import BodyRecord, CameraFrameRecord, PersonRecord
from face_reid_master.sim.visibility import coverage_fraction
from face_reid_master.sim.world import SimCamera, World

if TYPE_CHECKING:
    from face_reid_master.sim.bodies import BodyWorld
    from face_reid_master.sim.frame_table import FrameTable
    from face_reid_master.sim.photos import IdentityPhotos, PhotoBank
    from face_reid_master.sim.simulate import Day, SimConfig

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "GroundTruth",
    "Scenario",
    "ScenarioFormatError",
    "SimResult",
    "load_scenario",
    "load_scenario_document",
    "scenario_document",
    "write_scenario",
]

FORMAT_NAME = "face-reid-scenario"
FORMAT_VERSION = 1

class ScenarioFormatError(ValueError):
    """A scenario directory is missing files or holds inconsistent data."""


@dataclass
class SimResult:
    """What :func:`~face_reid_master.sim.simulate.simulate` produced: the json document, the frame table, the
    ground truth arrays (the contents of a scenario directory)."""

    document: dict[str, Any]
    frames: FrameTable
    ground_truth: dict[str, NDArray[Any]]


def scenario_document(cfg: SimConfig, bank: PhotoBank, world: World, identities: list[IdentityPhotos],
                      photo_offsets: list[int], days: list[Day], heights: NDArray[np.float64],
                      phases: NDArray[np.float64], table: FrameTable, gt: dict[str, NDArray[Any]],
                      loss_info: list[dict[str, Any]], n_glances: int, bodies: BodyWorld | None = None,
                      camera_true: dict[str, Any] | None = None) -> dict[str, Any]:
    """The ``scenario.json`` document of a simulated scenario (``bodies``: with its body keys; ``camera_true``:
    what the camera's geometry gave the faces and bodies, in the summary)."""
    photos = []
    for ident, offset in zip(identities, photo_offsets, strict=True):
        for k, ph in enumerate(ident.photos):
            photos.append({"index": int(offset + k), "identity": ident.name, "path": ph.rel_path})
    ident_docs = []
    for gt_id, (ident, offset) in enumerate(zip(identities, photo_offsets, strict=True)):
        present = [d.day for d in days if gt_id in d.gt_ids]
        ident_docs.append({
            "gt_id": gt_id,
            "name": ident.name,
            "height_m": round(float(heights[gt_id]), 4),
            "days": present,
            "photos": {str(d): [int(offset + i) for i in ident.day_photos[0 if d == 1 else 1]] for d in present},
        })
    n_det = int(table.det["gt_id"].size)
    summary = {
        "duration_s": cfg.duration_s,
        "days": len(days),
        "people_per_day": cfg.num_people,
        "identities": len(identities),
        "cameras": len(world.cameras),
        "frames": int(table.stamp_s.size),
        "detections": n_det,
        "false_positives": int((table.det["gt_id"] < 0).sum()),
        "face_detections": int(table.face["score"].size),
        "glances": int(n_glances),
        "losses": int(sum(d["losses"] for d in loss_info)),
        "visible_segments": int(sum(d["visible_segments"] for d in loss_info)),
        "coverage_fraction": round(coverage_fraction(world, cfg.visibility), 4),
        "per_day": loss_info,
        "skipped_unreadable": sorted(set(bank.skipped_unreadable)),
        "skipped_no_face": sorted(set(bank.skipped_no_face)),
        "identities_with_too_few_photos": sorted(set(bank.too_few_photos)),
    }
    if camera_true is not None:
        summary["camera_true"] = camera_true
    document = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "generator": "face-reid-sim",
        "level": cfg.level,
        "embedding_space": bank.space,
        "seed": int(cfg.seed),
        "faces_dir": str(bank.faces_dir),
        "parameters": cfg.to_json(),
        "room": {"width_m": world.room.width_m, "depth_m": world.room.depth_m},
        "doors": [{"centre_xy": [round(float(v), 4) for v in d.centre_xy],
                   "inward_normal": [float(v) for v in d.inward_normal], "width_m": d.width_m} for d in world.doors],
        "cameras": [{
            "camera_id": c.camera_id,
            "xyz_rpy": [round(float(v), 6) for v in c.xyz_rpy],
            "rotation": np.round(c.pose.rotation, 9).tolist(),
            "translation": np.round(c.pose.translation, 9).tolist(),
            "intrinsics": {"fx": c.intrinsics.fx, "fy": c.intrinsics.fy, "cx": c.intrinsics.cx, "cy": c.intrinsics.cy,
                           "width": c.intrinsics.width, "height": c.intrinsics.height},
            "frame_phase_s": round(float(ph), 9),
        } for c, ph in zip(world.cameras, phases, strict=True)],
        "photos": photos,
        "identities": ident_docs,
        "days": [{"day": d.day, "start_s": d.start_s, "end_s": d.start_s + cfg.duration_s, "gt_ids": d.gt_ids}
                 for d in days],
        "summary": summary,
    }
    if bodies is not None:
        _add_bodies(document, bodies, table)
    return document


def _add_bodies(document: dict[str, Any], bodies: BodyWorld, table: FrameTable) -> None:
    """The body keys of scenario.json: crops folder and list, space, clothes and measures per identity."""
    from face_reid_master.sim.bodies import MEASURE_FIELDS, PKU_VIEW_DEG

    bank = bodies.bank
    document["bodies_dir"] = str(bank.bodies_dir)
    document["body_space"] = bodies.space
    # what the projection was fitted on, so that face-reid-eval can tell whether its people were seen
    fitted = bank.projection.metadata.get("identities")
    document["body_projection_fit"] = sorted(str(n) for n in fitted) if isinstance(fitted, list | tuple) else None
    document["body_descriptor_length"] = bodies.dim
    document["body_crops"] = bank.crops_document()
    document["body_orientation_view_deg"] = {str(o): v for o, v in PKU_VIEW_DEG.items()}
    for ident in document["identities"]:
        gt = ident["gt_id"]
        ident["clothes"] = {str(d): bodies.clothes[(gt, d)].name for d in ident["days"]}
        ident["body_measures"] = {name: round(float(v), 4) for name, v in
                                  zip(MEASURE_FIELDS, bodies.measures[gt], strict=True)}
    rows = table.body
    summary = document["summary"]
    summary["body_detections"] = 0 if rows is None else int(rows.described.size)
    summary["body_descriptors"] = 0 if rows is None else int(rows.described.sum())
    summary["body_glances"] = int(bodies.glance_counter[0])
    summary["body_crops_skipped_unreadable"] = sorted(set(bank.skipped_unreadable))


def write_scenario(result: SimResult, out_dir: str | Path) -> Path:
    """Write scenario.json, frames.npz and ground_truth.npz into ``out_dir`` (created if needed)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table = result.frames
    arrays = {
        "frame_camera": table.camera, "frame_stamp_s": table.stamp_s, "frame_offsets": table.offsets,
        "det_position": table.det["position"], "det_std_m": table.det["std_m"], "det_height_m": table.det["height_m"],
        "det_gt_id": table.det["gt_id"], "det_face": table.det["face"],
        "face_embedding": table.face["embedding"], "face_score": table.face["score"],
        "face_quality": table.face["quality"], "face_photo": table.face["photo"], "face_glance": table.face["glance"],
        "face_variant": table.face["variant"], "face_eye_px": table.face["eye_px"],
    }
    if table.body is not None:
        arrays["det_body"] = table.det["body"]
        arrays.update(table.body.arrays())
    write_npz(out / "frames.npz", arrays)
    write_npz(out / "ground_truth.npz", result.ground_truth)
    text = json.dumps(result.document, indent=1, sort_keys=True) + "\n"
    write_atomically(out / "scenario.json", lambda f: f.write(text.encode("utf-8")))
    return out


@dataclass(frozen=True)
class GroundTruth:
    """True state sampled on a regular grid per day (see the module doc for shapes)."""

    t_s: NDArray[np.float64]
    day: NDArray[np.int8]
    gt_id: NDArray[np.int32]
    xy: NDArray[np.float32]
    facing_rad: NDArray[np.float32]
    in_room: NDArray[np.bool_]
    in_view: NDArray[np.bool_]
    face_visible: NDArray[np.bool_]


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario: the frames as master-core records in stamp order, plus parallel ground truth.

    ``frame_gt_ids[i][j]`` is the true person (gt_id, -1 = false positive) of ``frames[i].people[j]``;
    ``frame_face_photos[i][j]`` the photo index its face came from (-1: no face / unknown);
    ``frame_body_crops[i][j]`` the index into ``body_crops`` of the crop its body showed (-1: no body / unknown).
    """

    directory: Path
    document: dict[str, Any]
    cameras: tuple[SimCamera, ...]
    frames: list[CameraFrameRecord]
    frame_gt_ids: list[NDArray[np.int32]]
    frame_face_photos: list[NDArray[np.int32]]
    ground_truth: GroundTruth
    frame_body_crops: list[NDArray[np.int32]] = field(default_factory=list)

    @property
    def level(self) -> str:
        return str(self.document["level"])

    @property
    def seed(self) -> int:
        return int(self.document["seed"])

    @property
    def identities(self) -> list[dict[str, Any]]:
        return list(self.document["identities"])

    @property
    def days(self) -> list[dict[str, Any]]:
        return list(self.document["days"])

    @property
    def day_spans(self) -> list[tuple[int, float, float, list[int]]]:
        """(day, start s, end s, gt ids) of every day: what run_master's ``days`` takes."""
        return [(int(d["day"]), float(d["start_s"]), float(d["end_s"]), [int(g) for g in d["gt_ids"]])
                for d in self.document["days"]]

    @property
    def summary(self) -> dict[str, Any]:
        return dict(self.document["summary"])


_FRAME_KEYS = ("frame_camera", "frame_stamp_s", "frame_offsets", "det_position", "det_std_m", "det_height_m",
               "det_gt_id", "det_face", "face_embedding", "face_score", "face_quality", "face_photo", "face_glance",
               "face_variant")
_BODY_KEYS = ("det_body", "body_descriptor", "body_described", "body_visible", "body_part_visible", "body_geometry",
              "body_crop", "body_view_deg", "body_glance")
_GT_KEYS = ("t_s", "day", "gt_id", "xy", "facing_rad", "in_room", "in_view", "face_visible")


def _read_npz(path: Path, keys: Sequence[str], optional: Sequence[str] = ()) -> dict[str, NDArray[Any]]:
    if not path.is_file():
        raise ScenarioFormatError(f"scenario file {path} is missing")
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in keys if k not in data.files]
            if missing:
                raise ScenarioFormatError(f"{path} lacks arrays {missing}")
            return {k: data[k] for k in (*keys, *(k for k in optional if k in data.files))}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        if isinstance(exc, ScenarioFormatError):
            raise
        raise ScenarioFormatError(f"{path} is not a readable npz file: {exc}") from exc


def load_scenario_document(directory: str | Path) -> dict[str, Any]:
    """The checked ``scenario.json`` of a scenario directory; ScenarioFormatError if missing or foreign."""
    base = Path(directory)
    doc_path = base / "scenario.json"
    if not doc_path.is_file():
        raise ScenarioFormatError(f"{base} is not a scenario directory (no scenario.json)")
    try:
        doc = json.loads(doc_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ScenarioFormatError(f"{doc_path} is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
        raise ScenarioFormatError(f"{doc_path} is not a {FORMAT_NAME} document")
    if doc.get("version") != FORMAT_VERSION:
        raise ScenarioFormatError(f"{doc_path} has format version {doc.get('version')!r}, this reader knows "
                                  f"{FORMAT_VERSION}")
    if not isinstance(doc.get("identities"), list):
        raise ScenarioFormatError(f"{doc_path} has no identities list")
    return doc


def load_scenario(directory: str | Path) -> Scenario:
    """Read a scenario directory written by :func:`write_scenario`; ScenarioFormatError if it is broken."""
    base = Path(directory)
    doc_path = base / "scenario.json"
    doc = load_scenario_document(base)
    try:
        cameras = tuple(
            SimCamera(c["camera_id"], CameraIntrinsics(**c["intrinsics"]),
                       CameraPose(np.array(c["rotation"], dtype=np.float64),
                                  np.array(c["translation"], dtype=np.float64)),
                       tuple(float(v) for v in c["xyz_rpy"]))
            for c in doc["cameras"])
        n_ids = len(doc["identities"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ScenarioFormatError(f"{doc_path} has malformed cameras/identities: {exc}") from exc
    a = _read_npz(base / "frames.npz", _FRAME_KEYS, ("face_eye_px", *_BODY_KEYS))
    space = str(doc.get("embedding_space", DLIB_SPACE))
    try:
        dim = space_dim(space)
    except ValueError as exc:
        raise ScenarioFormatError(f"{doc_path}: {exc}") from None
    n_f, n_d, n_e = a["frame_stamp_s"].size, a["det_gt_id"].size, a["face_score"].size
    offsets = a["frame_offsets"]
    problems = []
    if a["frame_camera"].shape != (n_f,) or offsets.shape != (n_f + 1,):
        problems.append("frame arrays disagree in length")
    elif offsets[0] != 0 or offsets[-1] != n_d or np.any(np.diff(offsets) < 0):
        problems.append("frame_offsets are not a monotone 0..detections partition")
    if n_f and (a["frame_camera"].min() < 0 or a["frame_camera"].max() >= len(cameras)):
        problems.append("frame_camera index out of range")
    if n_f > 1 and np.any(np.diff(a["frame_stamp_s"]) < 0):
        problems.append("frames are not in stamp order")
    if a["det_position"].shape != (n_d, 3) or any(a[k].shape != (n_d,) for k in ("det_std_m", "det_height_m",
                                                                                   "det_face")):
        problems.append("detection arrays disagree in shape")
    eye_px = a.get("face_eye_px", np.zeros(n_e, dtype=np.float32))
    if a["face_embedding"].shape != (n_e, dim) or eye_px.shape != (n_e,) or any(
            a[k].shape != (n_e,) for k in ("face_quality", "face_photo", "face_glance", "face_variant")):
        problems.append("face arrays disagree in shape")
    if n_d and (a["det_face"].max() >= n_e or a["det_face"].min() < -1 or a["det_gt_id"].max() >= n_ids
                or a["det_gt_id"].min() < -1):
        problems.append("det_face / det_gt_id out of range")
    if not (np.isfinite(a["det_position"]).all() and np.isfinite(a["face_embedding"]).all()
            and np.isfinite(a["frame_stamp_s"]).all()):
        problems.append("non-finite positions, stamps or embeddings")
    problems.extend(_body_problems(a, doc, n_d))
    if problems:
        raise ScenarioFormatError(f"{base / 'frames.npz'}: " + "; ".join(problems))
    g = _read_npz(base / "ground_truth.npz", _GT_KEYS)
    ground_truth = GroundTruth(**g)
    frames: list[CameraFrameRecord] = []
    gt_ids: list[NDArray[np.int32]] = []
    face_photos: list[NDArray[np.int32]] = []
    camera_ids = [c.camera_id for c in cameras]
    pos, std, height, det_face, det_gt = (a["det_position"], a["det_std_m"].tolist(), a["det_height_m"].tolist(),
                                          a["det_face"].tolist(), a["det_gt_id"])
    emb, f_score, f_quality, f_photo = a["face_embedding"], a["face_score"].tolist(), a["face_quality"].tolist(), \
        a["face_photo"]
    f_eye = eye_px.tolist()
    bodies = _body_records(a, doc)
    det_crop = np.full(n_d, -1, dtype=np.int32)
    if "det_body" in a:
        has_body = a["det_body"] >= 0
        det_crop[has_body] = a["body_crop"][a["det_body"][has_body]]
    body_crops: list[NDArray[np.int32]] = []
    for i in range(n_f):
        lo, hi = int(offsets[i]), int(offsets[i + 1])
        people = []
        photos = np.full(hi - lo, -1, dtype=np.int32)
        for j in range(lo, hi):
            k = det_face[j]
            body = bodies[j]
            if k >= 0:
                people.append(PersonRecord(pos[j], std[j], height[j], emb[k], f_score[k], f_quality[k], space,
                                           f_eye[k], body))
                photos[j - lo] = f_photo[k]
            else:
                people.append(PersonRecord(pos[j], std[j], height[j], body=body))
        frames.append(CameraFrameRecord(camera_ids[int(a["frame_camera"][i])], float(a["frame_stamp_s"][i]),
                                        tuple(people)))
        gt_ids.append(det_gt[lo:hi])
        face_photos.append(photos)
        body_crops.append(det_crop[lo:hi])
    return Scenario(base, doc, cameras, frames, gt_ids, face_photos, ground_truth, body_crops)


def _body_problems(a: dict[str, NDArray[Any]], doc: dict[str, Any], n_d: int) -> list[str]:
    """What is wrong with the optional body arrays (all or none, consistent shapes, a body space)."""
    present = [k for k in _BODY_KEYS if k in a]
    if not present:
        return []
    if len(present) != len(_BODY_KEYS):
        return [f"body arrays incomplete: lacks {[k for k in _BODY_KEYS if k not in a]}"]
    if not isinstance(doc.get("body_space"), str):
        return ["body arrays without a body_space in scenario.json"]
    n_b = a["body_described"].size
    problems = []
    if a["det_body"].shape != (n_d,) or (n_d and (a["det_body"].min() < -1 or a["det_body"].max() >= n_b)):
        problems.append("det_body does not index the body arrays")
    if (a["body_descriptor"].ndim != 2 or a["body_descriptor"].shape[0] != n_b or a["body_geometry"].shape != (n_b, 6)
            or a["body_part_visible"].ndim != 2 or a["body_part_visible"].shape[0] != n_b
            or any(a[k].shape != (n_b,) for k in ("body_visible", "body_crop", "body_view_deg", "body_glance"))):
        problems.append("body arrays disagree in shape")
    elif not np.isfinite(a["body_descriptor"]).all():
        problems.append("non-finite body descriptors")
    n_crops = len(doc.get("body_crops", []))
    if n_b and (a["body_crop"].min() < -1 or a["body_crop"].max() >= n_crops):
        problems.append("body_crop out of range of body_crops")
    return problems


def _body_records(a: dict[str, NDArray[Any]], doc: dict[str, Any]) -> list[BodyRecord | None]:
    """The BodyRecord of every detection (None: no body; every one None for scenarios without bodies)."""
    n_d = a["det_gt_id"].size
    if "det_body" not in a:
        return [None] * n_d
    space = str(doc["body_space"])
    desc, described, visible = a["body_descriptor"], a["body_described"], a["body_visible"].tolist()
    geometry, parts = a["body_geometry"], a["body_part_visible"]
    empty = np.zeros(0, dtype=np.float32)
    records: list[BodyRecord | None] = []
    for b in a["det_body"].tolist():
        if b < 0:
            records.append(None)
            continue
        records.append(BodyRecord(desc[b] if described[b] else empty, space, visible[b], geometry[b], parts[b]))
    return records
