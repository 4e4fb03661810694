"""Exception types shared by the face-reid model loaders and converters, and the nodes' exit status for a
configuration they refuse."""

from __future__ import annotations

__all__ = ["CONFIG_EXIT_STATUS", "ModelChecksumError", "ModelFormatError", "ModelLoadError"]

# A node that cannot start with its configuration (bad parameter, params file, key or model file; one FATAL line)
# exits with this status: starting it again changes nothing, so face-reid-up does not restart it.
CONFIG_EXIT_STATUS = 2


class ModelLoadError(RuntimeError):
    """A model file exists but cannot be loaded (corrupt, truncated or not the expected network)."""


class ModelChecksumError(ValueError):
    """A model source file does not have the expected sha256 digest, so it is refused."""


class ModelFormatError(ValueError):
    """A serialized model could not be parsed: unexpected layer, version or truncated data."""
