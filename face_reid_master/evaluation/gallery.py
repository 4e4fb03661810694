"""The predefined people of a scenario: some of its identities, with photos of their folders it did not use."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["GalleryInfo", "default_gallery_people", "scenario_gallery"]


@dataclass
class GalleryInfo:
    """Predefined people built for a scenario: embeddings per name, their true person, photo sources."""

    people: dict[str, NDArray[np.float32]]
    gt_of_name: dict[str, int]
    photos: dict[str, int]  # name -> gallery photos embedded
    from_scenario_photo: list[str]  # names whose gallery had to reuse a photo the scenario used
    skipped: str = ""  # why no gallery was built (empty when built)

    def as_json(self) -> dict[str, Any]:
        if self.skipped:
            return {"skipped": self.skipped}
        return {"people": {n: {"gt_id": self.gt_of_name[n], "photos": self.photos[n]} for n in sorted(self.people)},
                "reused_a_scenario_photo": sorted(self.from_scenario_photo)}


def default_gallery_people(document: Mapping[str, Any], count: int | None = None) -> list[int]:
    """``count`` (default: half, rounded down) of the day-1 people, chosen by a permutation seeded with the
    scenario seed, sorted by gt id."""
    days = sorted(document.get("days", []), key=lambda d: d["day"])
    day1 = sorted(int(g) for g in days[0]["gt_ids"]) if days else []
    k = len(day1) // 2 if count is None else int(count)
    if not 0 <= k <= len(day1):
        raise ValueError(f"gallery people must be within [0, {len(day1)}] (day-1 people), got {k}")
    order = np.random.default_rng([int(document.get("seed", 0)), 4]).permutation(len(day1))
    return sorted(day1[int(i)] for i in order[:k])


def _resolve_faces_dir(document: Mapping[str, Any], scenario_dir: Path, faces_dir: str | Path | None) -> Path | None:
    candidates = [Path(faces_dir)] if faces_dir is not None else []
    recorded = document.get("faces_dir")
    if recorded:
        candidates += [Path(recorded), scenario_dir / recorded]
    for c in candidates:
        if c.is_dir():
            return c
    return None


def scenario_gallery(
    document: Mapping[str, Any],
    scenario_dir: str | Path,
    gt_ids: Sequence[int],
    *,
    faces_dir: str | Path | None = None,
    embedder: Any | None = None,
    log: Any | None = None,
    space: str = "dlib_resnet_v1",
) -> GalleryInfo:
    """Predefined people for ``gt_ids``: each identity's photos in its faces folder that the scenario did
    NOT use on any day, embedded with the real models (``PhotoEmbedder``). If none is usable, one photo
    the scenario used is taken (and listed in ``from_scenario_photo``). A missing faces folder gives a
    GalleryInfo with ``skipped`` set (the evaluation then has no names). ``space``: the embedder space of
    the master (the photos are embedded by the network(s) it compares; ``embedder`` overrides)."""
    if not gt_ids:
        return GalleryInfo({}, {}, {}, [], skipped="no gallery people requested")
    base = _resolve_faces_dir(document, Path(scenario_dir), faces_dir)
    if base is None:
        return GalleryInfo({}, {}, {}, [], skipped=f"faces folder {document.get('faces_dir')!r} not found "
                                                   "(pass --faces)")
    from face_reid_camera.common.embedding_spaces import embedder_for_space
    from face_reid_camera.faces.embedder import load_embedder
    from face_reid_camera.faces.photos import IMAGE_SUFFIXES, PhotoEmbedder, PhotoError

    emb = embedder if embedder is not None else PhotoEmbedder(embedder=load_embedder(embedder_for_space(space)))
    photo_path = {int(p["index"]): str(p["path"]) for p in document.get("photos", [])}
    idents = {int(i["gt_id"]): i for i in document.get("identities", [])}
    info = GalleryInfo({}, {}, {}, [])
    for gt in gt_ids:
        ident = idents.get(int(gt))
        if ident is None:
            raise ValueError(f"gt id {gt} is not an identity of the scenario")
        name = str(ident["name"])
        used = {photo_path[i] for day_list in ident.get("photos", {}).values() for i in day_list if i in photo_path}
        folder = base / name
        files = sorted(f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES) \
            if folder.is_dir() else []
        rows = []
        for f in files:
            if f.relative_to(base).as_posix() in used:
                continue
            try:
                e = emb.embed_photo(f)
            except PhotoError:
                continue
            if e is not None:
                rows.append(e.embedding)
        if not rows:
            for rel in sorted(used):
                try:
                    e = emb.embed_photo(base / rel)
                except PhotoError:
                    continue
                if e is not None:
                    rows.append(e.embedding)
                    info.from_scenario_photo.append(name)
                    if log is not None:
                        print(f"gallery: {name} has no unused photo; reusing scenario photo {rel}", file=log)
                    break
        if not rows:
            raise ValueError(f"no usable gallery photo for {name} in {folder}")
        info.people[name] = np.stack(rows).astype(np.float32)
        info.gt_of_name[name] = int(gt)
        info.photos[name] = len(rows)
    return info
