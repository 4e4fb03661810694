"""Where the suite's data lives: ONNX models, fitted likelihoods and the demo's photos.

Looked up in this order so that a source checkout, an editable install and a normal
``pip install .`` all work without environment set-up:
1. an environment variable (``FACE_REID_MODELS_DIR`` for the models);
2. the folder at the root of a source checkout (next to this package);
3. ``<prefix>/share/face_reid/<folder>`` installed by ``pip install .``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

_SOURCE_ROOT = Path(__file__).resolve().parents[2]


def _lookup(kind: str, env_var: str) -> Path:
    override = os.environ.get(env_var)
    if override:
        return Path(override).expanduser()
    in_checkout = _SOURCE_ROOT / kind
    if in_checkout.is_dir():
        return in_checkout
    return Path(sys.prefix) / "share" / "face_reid" / kind


def models_dir() -> Path:
    """Directory holding the ONNX models and fitted likelihood parameters."""
    return _lookup("models", "FACE_REID_MODELS_DIR")


def model_path(file_name: str) -> Path:
    """Path of one file in the models directory (existence is checked by the loader)."""
    return models_dir() / file_name


def demo_faces_dir() -> Path:
    """Folder of licensed face photos (one sub-folder per identity) played by ``face-reid-demo``.

    ``FACE_REID_DEMO_FACES_DIR`` if set, else ``test/data/faces`` of a source checkout, else
    ``<prefix>/share/face_reid/demo_faces`` installed by ``pip install .``.
    """
    override = os.environ.get("FACE_REID_DEMO_FACES_DIR")
    if override:
        return Path(override).expanduser()
    in_checkout = _SOURCE_ROOT / "test" / "data" / "faces"
    if in_checkout.is_dir():
        return in_checkout
    return Path(sys.prefix) / "share" / "face_reid" / "demo_faces"
