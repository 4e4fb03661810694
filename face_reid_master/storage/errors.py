"""What the face store raises, and how its errors are said."""

from __future__ import annotations

__all__ = ["FaceStoreError", "FaceStoreLockedError", "reason_of"]


class FaceStoreError(OSError):
    """The face store cannot be used (configuration or I/O problem; corruption is recovered instead). An OSError:
    its message is a sentence for the operator, said as it is (no class name in front)."""


class FaceStoreLockedError(FaceStoreError):
    """Another process (normally the running master node) has the store open for writing."""


def reason_of(exc: BaseException) -> str:
    """An error as said to the operator: the message of the store's own errors and of OSError / ValueError (they
    are written as sentences), the class name in front of anything else (an unexpected error)."""
    if isinstance(exc, OSError | ValueError):
        return str(exc) or type(exc).__name__
    return f"{type(exc).__name__}: {exc}"
