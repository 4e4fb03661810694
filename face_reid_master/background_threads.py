"""Background worker threads of the master run at a lower CPU priority than its frame loop.

The face store's commits and the online body-metric re-fits are bursts of work on the master's core; at the
same priority the scheduler halves the frame loop's share during a burst, and frames queue up behind it.
At ``BACKGROUND_NICE`` the workers use what the frame loop leaves. Linux sets the niceness of one thread;
elsewhere (or when refused) the worker keeps its priority.
"""

from __future__ import annotations

import logging
import os
import sys
import threading

__all__ = ["BACKGROUND_NICE", "lower_this_thread"]

_LOG = logging.getLogger(__name__)

BACKGROUND_NICE = 10  # niceness added to a worker thread (0..19; 19 = lowest priority)


def lower_this_thread(nice: int = BACKGROUND_NICE) -> None:
    """Raise the calling thread's niceness by ``nice`` (a ``ThreadPoolExecutor`` initializer); Linux only."""
    if nice <= 0 or not sys.platform.startswith("linux"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))
    except OSError as exc:  # e.g. a seccomp profile: the worker runs at the frame loop's priority
        _LOG.debug("could not lower the priority of thread %s: %s", threading.current_thread().name, exc)
