"""Labelled person crops for body re-id: one folder per identity, the camera read from the file name.

Naming conventions understood (else the camera is unknown): Market-1501 ``0004_c3s3_065819_03.jpg``
(person, camera 3, sequence, frame, box), MARS / DukeMTMC-VideoReID ``0003C4T0003F010.jpg`` (person,
camera 4, tracklet, frame), PKU-Reid ``01_5.png`` (camera 01, body orientation 5 of 8). A ``cameras.csv``
(``file,camera`` rows, file relative to the crops folder) in the crops folder overrides the names.
"""

from __future__ import annotations

import csv
import fnmatch
import re
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from face_reid_camera.faces.photos import list_identity_photos

__all__ = ["Crop", "ReidSplit", "camera_mask", "camera_of", "filter_crops", "list_crops", "reid_splits", "same_camera"]

_MARKET = re.compile(r"^-?\d+_c(\d+)(?:s\d+)?_")
_MARS = re.compile(r"^\d+C(\d+)T\d+F\d+", re.IGNORECASE)
_PKU = re.compile(r"^(\d+)_(\d+)$")


@dataclass(frozen=True)
class Crop:
    """One crop: its identity (folder name), file, camera ("" = unknown) and orientation (0 = unknown)."""

    identity: str
    path: Path
    camera: str = ""
    orientation: int = 0


def camera_of(file_name: str) -> tuple[str, int]:
    """(camera, orientation) from a crop's file name by the conventions above; ("", 0) if none matches."""
    stem = Path(file_name).stem
    for pattern in (_MARKET, _MARS):
        m = pattern.match(stem)
        if m:
            return str(int(m.group(1))), 0
    m = _PKU.match(stem)
    if m:
        return str(int(m.group(1))), int(m.group(2))
    return "", 0


def list_crops(root: str | Path) -> list[Crop]:
    """Every image of ``root``'s identity folders, in name order (ValueError: not a folder, no image)."""
    base = Path(root)
    try:
        photos, _ = list_identity_photos(base)
    except ValueError as exc:
        raise ValueError(str(exc).replace("face folder", "crops folder")) from None
    override: dict[str, str] = {}
    table = base / "cameras.csv"
    if table.is_file():
        with table.open(newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            if not {"file", "camera"} <= set(reader.fieldnames or ()):
                raise ValueError(f"{table}: needs the columns file,camera")
            for row in reader:
                override[str(row["file"]).strip()] = str(row["camera"]).strip()
    crops = []
    for identity, files in photos.items():
        for path in files:
            camera, orientation = camera_of(path.name)
            camera = override.get(f"{identity}/{path.name}", camera)
            crops.append(Crop(identity, path, camera, orientation))
    if not crops:
        raise ValueError(f"crops folder {base} has no images: expected one sub-folder of crops per identity")
    return crops


def filter_crops(crops: Sequence[Crop], include: Sequence[str] = (), exclude: Sequence[str] = (),
                 exclude_identities: Collection[str] = ()) -> list[Crop]:
    """The crops whose identity matches one of the ``include`` globs (none given: every identity), matches
    none of the ``exclude`` globs and is not one of ``exclude_identities`` (ValueError if none is left)."""
    for name, patterns in (("include", include), ("exclude", exclude)):
        if isinstance(patterns, str) or any(not isinstance(p, str) or not p for p in patterns):
            raise ValueError(f"{name} must be a sequence of non-empty glob patterns, got {patterns!r}")

    def keep(identity: str) -> bool:
        if include and not any(fnmatch.fnmatchcase(identity, p) for p in include):
            return False
        return identity not in exclude_identities and not any(fnmatch.fnmatchcase(identity, p) for p in exclude)

    out = [c for c in crops if keep(c.identity)]
    if not out:
        raise ValueError(f"no crop left after --include {list(include)} / --exclude {list(exclude)} and "
                         f"{len(exclude_identities)} excluded identities")
    return out


@dataclass(frozen=True)
class ReidSplit:
    """Indices into the crop list: metric training crops, and probe / gallery crops of the other people
    (a probe is compared with the gallery crops of the other cameras only, see :func:`reid_splits`)."""

    train: np.ndarray
    probe: np.ndarray
    gallery: np.ndarray


def reid_splits(crops: list[Crop], n_splits: int, rng: np.random.Generator, train_fraction: float = 0.5
                ) -> list[ReidSplit]:
    """The second seed's protocol: per split, a random ``train_fraction`` of the identities trains the
    metric; each other identity gives one random probe crop (from a random camera when several saw it) and
    its other crops join the gallery; a probe is then compared with the gallery crops of other cameras only
    (:func:`same_camera`), so its own camera's background and light cannot match it. Identities with one
    crop, or seen by one camera only when cameras are known, join the gallery as distractors."""
    names = sorted({c.identity for c in crops})
    if len(names) < 4:
        raise ValueError(f"need >= 4 identities for disjoint training and test people, got {len(names)}")
    by_id: dict[str, list[int]] = {n: [] for n in names}
    for i, c in enumerate(crops):
        by_id[c.identity].append(i)
    out = []
    for _ in range(n_splits):
        order = rng.permutation(len(names))
        n_train = min(len(names) - 2, max(2, round(train_fraction * len(names))))
        train_ids = [names[k] for k in order[:n_train]]
        probe: list[int] = []
        gallery: list[int] = []
        for n in (names[k] for k in order[n_train:]):
            idx = by_id[n]
            cams = sorted({crops[i].camera for i in idx} - {""})
            if len(idx) < 2 or len(cams) == 1:
                gallery.extend(idx)
                continue
            if cams:
                cam = cams[int(rng.integers(len(cams)))]
                own = [i for i in idx if crops[i].camera == cam]
                p = own[int(rng.integers(len(own)))]
            else:
                p = idx[int(rng.integers(len(idx)))]
            probe.append(p)
            gallery.extend(i for i in idx if i != p)
        train = np.array(sorted(i for n in train_ids for i in by_id[n]), dtype=np.intp)
        out.append(ReidSplit(train, np.array(probe, dtype=np.intp), np.array(sorted(gallery), dtype=np.intp)))
    return out


def same_camera(crops: list[Crop], probe: np.ndarray, gallery: np.ndarray) -> np.ndarray:
    """(probes, gallery) True where a gallery crop was seen by the probe's camera (never for unknown ones)."""
    return camera_mask([crops[i].camera for i in probe], [crops[i].camera for i in gallery])


def camera_mask(probe_cameras: Sequence[str], gallery_cameras: Sequence[str]) -> np.ndarray:
    """(probes, gallery) True where both cameras are known and equal (see :func:`same_camera`)."""
    pc = np.array(list(probe_cameras), dtype=object)
    gc = np.array(list(gallery_cameras), dtype=object)
    return (pc[:, None] == gc[None, :]) & (pc[:, None] != "")
