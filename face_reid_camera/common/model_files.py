"""Reading the suite's fitted-model JSON files with one set of errors: missing, or there but unusable."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from face_reid_camera.common.errors import ModelLoadError

__all__ = ["read_model_json", "unusable_model"]


@contextmanager
def unusable_model(what: str, path: str | Path) -> Iterator[None]:
    """Whatever goes wrong reading ``what`` at ``path`` inside the block becomes a :class:`ModelLoadError` naming
    the file and the reason (a missing key, a wrong type, an inconsistent value)."""
    try:
        yield
    except (OSError, ValueError, KeyError, TypeError) as exc:  # JSONDecodeError is a ValueError
        raise ModelLoadError(f"{what} {path} is unusable: {exc}") from exc


def read_model_json(path: str | Path, file_format: str, version: int, what: str, fit_hint: str = "") -> dict[str, Any]:
    """The document of a model file of ``file_format`` / ``version``: FileNotFoundError when missing (with
    ``fit_hint``: how to make one), :class:`ModelLoadError` when not JSON or another format or version."""
    src = Path(path)
    if not src.is_file():
        raise FileNotFoundError(f"{what} {src}: No such file" + (f" ({fit_hint})" if fit_hint else ""))
    with unusable_model(what, src):
        doc = json.loads(src.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != file_format or doc.get("version") != version:
            raise ValueError(f"not a {file_format} version {version} file")
    return doc
