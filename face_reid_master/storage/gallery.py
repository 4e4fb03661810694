"""Predefined-people gallery (Koide et al. 2017, Sec. III-F): names and face embeddings from disk.

A gallery is either a folder with one sub-folder per person (``NAME/*.jpg|png``, name = folder name,
one embedding per photo: its largest face) or a precomputed ``.npz`` (name -> (k, dim) float32)
written by :func:`save_gallery_npz`, which starts instantly and needs no photos on the robot.
"""

from __future__ import annotations

import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from face_reid_camera.common.embedding_spaces import EMBEDDER_CHOICES, embedder_space, space_dim

if TYPE_CHECKING:
    from face_reid_camera.faces.photos import PhotoEmbedder

__all__ = ["GalleryResult", "load_gallery", "save_gallery_npz", "validate_person_name"]

_LENGTHS = frozenset(space_dim(embedder_space(choice)) for choice in EMBEDDER_CHOICES)


def validate_person_name(name: object) -> str:
    """The name itself if it is a non-empty string without surrounding whitespace or '/'; else ValueError."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"person name must be a non-empty string, got {name!r}")
    if name != name.strip():
        raise ValueError(f"person name {name!r} has leading or trailing whitespace")
    if "/" in name or "\\" in name or "\x00" in name:
        raise ValueError(f"person name {name!r} must not contain '/', '\\' or NUL")
    return name


def _validate_embeddings(name: str, value: npt.ArrayLike) -> npt.NDArray[np.float32]:
    arr = np.asarray(value)
    if arr.ndim != 2 or arr.shape[0] < 1 or arr.shape[1] not in _LENGTHS:
        raise ValueError(f"embeddings of {name!r} must have shape (k >= 1, {' or '.join(map(str, sorted(_LENGTHS)))}),"
                         f" got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)) or arr.dtype == np.bool_:
        raise ValueError(f"embeddings of {name!r} must be real numbers, got dtype {arr.dtype}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"embeddings of {name!r} contain NaN or Inf")
    out = np.array(arr, dtype=np.float32)  # own copy
    out.flags.writeable = False
    return out


@dataclass
class GalleryResult:
    """Named people's embeddings and the gallery photos that could not be used.

    ``people``: name -> (k, dim) float32 (read-only), names sorted. ``skipped_unreadable`` /
    ``skipped_no_face``: photos not decodable / without a detectable face (always empty for an .npz).
    """

    people: dict[str, npt.NDArray[np.float32]]
    skipped_unreadable: list[Path] = field(default_factory=list)
    skipped_no_face: list[Path] = field(default_factory=list)

    def skipped_summary(self, root: str | Path = "", max_named: int = 5) -> str:
        """The photos left out, named (relative to ``root`` where below it, the first ``max_named`` of each kind):
        the operator must know which file to fix; '' when none was."""
        def named(paths: list[Path]) -> str:
            shown_paths = []
            for p in paths[:max_named]:
                try:
                    shown_paths.append(repr(str(Path(p).relative_to(root))) if root else repr(str(p)))
                except ValueError:
                    shown_paths.append(repr(str(p)))
            more = f" and {len(paths) - max_named} more" if len(paths) > max_named else ""
            return ", ".join(shown_paths) + more

        parts = []
        if self.skipped_unreadable:
            parts.append(f"skipped {len(self.skipped_unreadable)} unreadable photo(s): "
                         f"{named(self.skipped_unreadable)}")
        if self.skipped_no_face:
            parts.append(f"skipped {len(self.skipped_no_face)} photo(s) without a detectable face: "
                         f"{named(self.skipped_no_face)}")
        return "; ".join(parts)

    def __post_init__(self) -> None:
        if not self.people:
            raise ValueError("a gallery needs at least one person")
        checked = {validate_person_name(n): _validate_embeddings(n, e) for n, e in self.people.items()}
        self.people = dict(sorted(checked.items()))


def save_gallery_npz(people: Mapping[str, npt.ArrayLike], path: str | Path) -> None:
    """Write name -> (k, dim) embeddings as an uncompressed ``.npz`` (one array per name)."""
    result = GalleryResult(dict(people))  # validates names and arrays
    p = Path(path)
    if p.suffix.lower() != ".npz":
        raise ValueError(f"gallery file must end in .npz, got {p}")
    # zip entries written directly: np.savez(**people) breaks on a person called "file"
    with zipfile.ZipFile(p, "w", compression=zipfile.ZIP_STORED) as zf:
        for name, emb in result.people.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as entry:
                np.lib.format.write_array(entry, np.ascontiguousarray(emb), allow_pickle=False)


def _load_npz(path: Path) -> GalleryResult:
    try:
        if not zipfile.is_zipfile(path):  # np.load would take a .npy as one array, or offer to unpickle the rest
            raise ValueError("not a zip of .npy arrays (one NAME.npy of embeddings per person)")
        with np.load(path, allow_pickle=False) as data:
            people = {name: data[name] for name in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f"gallery {path} is not a readable .npz of embeddings: {exc}") from None
    if not people:
        raise ValueError(f"gallery {path} holds no people")
    try:
        return GalleryResult(people)
    except ValueError as exc:
        raise ValueError(f"gallery {path}: {exc}") from None


def load_gallery(path: str | Path, photo_embedder: PhotoEmbedder | None = None) -> GalleryResult:
    """Load a gallery from a ``NAME/*.jpg|png`` folder (embedding every photo) or a precomputed ``.npz``.

    ``photo_embedder``: a :class:`face_reid_camera.faces.photos.PhotoEmbedder` used for folders (None:
    one with the default models is created). Unreadable photos and photos without a face are reported
    in the result; ValueError if nothing usable is found or a name is invalid.
    """
    p = Path(path)
    if p.is_file():
        if p.suffix.lower() != ".npz":
            raise ValueError(f"gallery file {p} must be a .npz (or give a folder with one sub-folder per person)")
        return _load_npz(p)
    if not p.is_dir():
        raise ValueError(f"gallery {p} does not exist (expected a folder of NAME/ sub-folders or a .npz file)")
    from face_reid_camera.faces.photos import PhotoEmbedder  # cv2 / onnxruntime only when photos are embedded

    embedder = photo_embedder if photo_embedder is not None else PhotoEmbedder()
    if not isinstance(embedder, PhotoEmbedder):
        raise ValueError(f"photo_embedder must be a PhotoEmbedder, got {type(embedder).__name__}")
    try:
        folder = embedder.embed_folder_tree(p)
    except ValueError as exc:
        raise ValueError(f"gallery {p}: {exc}") from None
    people = {}
    for folder_name, embeddings in folder.identities.items():
        name = folder_name.strip()
        if name in people:
            raise ValueError(f"gallery {p}: two folders are named {name!r} once stripped of whitespace")
        people[validate_person_name(name)] = np.stack([e.embedding for e in embeddings])
    return GalleryResult(people, list(folder.skipped_unreadable), list(folder.skipped_no_face))
