"""Random streams of the simulator: each concern draws from its own generator, so changing one option does not
reshuffle the others (e.g. feature and pixel level of one seed share the world, the motion and the photos)."""

from __future__ import annotations

import numpy as np

__all__ = ["S_BODIES", "S_BODY_LIGHT", "S_BODY_MEASURES", "S_BODY_VIEW", "S_CAMERA", "S_FACES", "S_FP",
           "S_IDENTITIES", "S_LOOK", "S_MOTION", "S_PHASE", "S_RENDER", "S_SHUFFLE", "S_WORLD", "stream_rng"]

S_WORLD, S_IDENTITIES, S_MOTION, S_CAMERA, S_FACES, S_FP, S_RENDER, S_PHASE, S_LOOK = range(9)
# bodies (--bodies) draw only from their own streams: without them every other file stays the same
S_BODIES, S_BODY_MEASURES, S_BODY_LIGHT, S_BODY_VIEW = range(9, 13)  # clothes, measures, lights, per-frame views
S_SHUFFLE = 99  # order of the detections within a frame


def stream_rng(seed: int, *stream: int) -> np.random.Generator:
    """The generator of ``stream`` (a stream id and sub-indices, e.g. day and camera) for ``seed``."""
    return np.random.default_rng([int(seed), *(int(s) for s in stream)])
