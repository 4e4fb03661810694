"""Exception types shared by the face-reid model loaders and converters."""

from __future__ import annotations

__all__ = ["ModelChecksumError", "ModelFormatError", "ModelLoadError"]


class ModelLoadError(RuntimeError):
    """A model file exists but cannot be loaded (corrupt, truncated or not the expected network)."""


class ModelChecksumError(ValueError):
    """A model source file does not have the expected sha256 digest, so it is refused."""


class ModelFormatError(ValueError):
    """A serialized model could not be parsed: unexpected layer, version or truncated data."""
