"""What the face store raises."""

from __future__ import annotations

__all__ = ["FaceStoreError", "FaceStoreLockedError"]


class FaceStoreError(RuntimeError):
    """The face store cannot be used (configuration or I/O problem; corruption is recovered instead)."""


class FaceStoreLockedError(FaceStoreError):
    """Another process (normally the running master node) has the store open."""
