"""``face-reid-eval --live``: replay a recorded scenario through the real master node over DDS.

A ``face_reid_master.ros.node`` process (temporary face database, the evaluation's predefined people as an
``.npz`` gallery, the Bayesian table) runs on a private ROS domain with discovery on loopback only. This
process publishes the scenario's camera frames as ``face_reid_msgs/CameraFrame`` on
``/<camera_id>/face_reid/frames`` in real time (recorded inter-frame timing, stamps = now) and records every
``/tracks_named`` message. The metrics are then computed from what the master PUBLISHED
(:mod:`face_reid_master.evaluation.published_tracks`: each confirmed track attributed to the nearest true person).

Later days are replayed after a pause of ``lost_after_s + delete_after_s + 1`` s with the master kept
running (every track of the previous day deleted, its learned faces kept), instead of the recorded gap.
rclpy is imported only inside :func:`run_live`: the caller sets ``ROS_DOMAIN_ID`` first.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from face_reid_camera.common.stamps import stamp_to_seconds
from face_reid_master.demo.children import ChildProcess, child_env, start_child, stop_children
from face_reid_master.evaluation.published_tracks import TrackMessage, TruthLookup
from face_reid_master.records import CameraFrameRecord
from face_reid_master.ros.convert import frame_record_to_msg, track_from_msg
from face_reid_master.tracking.config import TrackerConfig

__all__ = ["LiveError", "LiveRun", "run_live", "scenario_truth"]

_STAMP_QUANTUM_S = 1e-4  # sent stamps are multiples of this, so a reply's float stamp finds its frame exactly
_TRUTH_MARGIN_S = 2.0  # ground truth is looked up this far beyond a day's ends (clamped to its first/last sample)
_TAIL_S = 1.5  # after the last frame: the last replies still arrive


class LiveError(RuntimeError):
    """The live run failed (the master did not start or died): the message says why, with its log."""


def scenario_truth(ground_truth: Any, days: Sequence[tuple[int, float, float, Sequence[int]]]) -> TruthLookup:
    """True positions of a simulated scenario at any scene time: the nearest ground-truth sample of the day
    containing it (up to ``_TRUTH_MARGIN_S`` beyond the day, clamped); nobody is in the room outside days."""
    t_all = np.asarray(ground_truth.t_s, dtype=np.float64)
    day_of_sample = np.asarray(ground_truth.day)
    xy_all = np.asarray(ground_truth.xy, dtype=np.float64)  # (P, T, 2)
    room_all = np.asarray(ground_truth.in_room, dtype=bool) & np.isfinite(xy_all).all(axis=2)
    spans = []
    for day, start, end, _ in days:
        idx = np.flatnonzero(day_of_sample == day)
        if idx.size:
            spans.append((start - _TRUTH_MARGIN_S, end + _TRUTH_MARGIN_S, int(idx[0]), int(idx[-1])))

    def lookup(t_s: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        t = np.asarray(t_s, dtype=np.float64)
        n_people = xy_all.shape[0]
        xy = np.zeros((t.size, n_people, 2))
        inside = np.zeros((t.size, n_people), dtype=bool)
        for lo_t, hi_t, first, last in spans:
            sel = np.flatnonzero((t >= lo_t) & (t <= hi_t))
            if not sel.size:
                continue
            grid = t_all[first:last + 1]
            k = np.clip(np.searchsorted(grid, t[sel]), 1, max(1, grid.size - 1))
            nearer_left = np.abs(t[sel] - grid[k - 1]) <= np.abs(grid[np.minimum(k, grid.size - 1)] - t[sel])
            k = first + np.where(nearer_left, k - 1, np.minimum(k, grid.size - 1))
            xy[sel] = np.nan_to_num(xy_all[:, k].transpose(1, 0, 2))
            inside[sel] = room_all[:, k].T
        return xy, inside

    return lookup


@dataclass
class LiveRun:
    """What a live run recorded: /tracks_named messages (scene seconds) and transport statistics."""

    messages: list[TrackMessage]
    transport: dict[str, Any]


def last_master_stats(log_path: Path) -> dict[str, int] | None:
    """The counters of the master's last 'stats: {...}' log line (None: no such line)."""
    import ast

    try:
        lines = log_path.read_text(errors="replace").splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        if "stats: {" in line:
            try:
                return dict(ast.literal_eval(line.split("stats: ", 1)[1]))
            except (ValueError, SyntaxError):
                return None
    return None


def frame_latencies(sent_s: NDArray[np.float64], reply_stamp_s: NDArray[np.float64],
                    reply_recv_s: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Per frame sent at ``sent_s`` (its stamp): seconds until the first /tracks_named message stamped at or after
    it arrived (the master applies a cycle's frames in stamp order and stamps its message with the newest), and
    which frames got one. Stamps compare with a 1 us tolerance (float round trips)."""
    sent = np.asarray(sent_s, dtype=np.float64)
    if not np.asarray(reply_stamp_s).size:
        return np.zeros(0), np.zeros(sent.shape, dtype=bool)
    order = np.argsort(reply_stamp_s, kind="stable")
    stamps = np.asarray(reply_stamp_s, dtype=np.float64)[order]
    recv = np.asarray(reply_recv_s, dtype=np.float64)[order]
    earliest = np.minimum.accumulate(recv[::-1])[::-1]  # first arrival among messages stamped >= stamps[i]
    idx = np.searchsorted(stamps, sent - 1e-6)
    has = idx < stamps.size
    return earliest[idx[has]] - sent[has], has


def _segments_to_scene(segments: Sequence[tuple[float, float]]) -> Any:
    """Wall time -> scene time: each day's frames were played from wall time ``w0`` with scene = wall + offset."""
    starts = np.array([w0 for w0, _ in segments])
    offsets = np.array([off for _, off in segments])

    def to_scene(wall_s: float) -> float:
        k = max(0, int(np.searchsorted(starts - 1.0, wall_s, side="right")) - 1)
        return float(wall_s + offsets[k])

    return to_scene


def run_live(frames: Sequence[CameraFrameRecord], day_of_frame: Sequence[int], gallery: Mapping[str, Any],
             domain_id: int, run_id: str, *, startup_timeout_s: float = 60.0,
             log: TextIO | None = None, keep_dir: Path | None = None,
             likelihood_path: Path | None = None, embedding_space: str = "dlib_resnet_v1",
             body_appearance_tracking: bool = True, body_metric_path: Path | None = None,
             confidence_map_path: Path | None = None) -> LiveRun:
    """Start the master node, publish ``frames`` in real time (stamps = now), collect /tracks_named.

    ``day_of_frame[i]``: the day of ``frames[i]`` (a pause between days, see the module doc). ``gallery``:
    name -> (k, 128) embeddings of the predefined people. The caller has set ``ROS_DOMAIN_ID`` = ``domain_id``
    and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` in this process before (rclpy is imported here).
    Every child is stopped on return or exception (Ctrl-C included); the work folder (face database, gallery,
    master log) is deleted unless ``keep_dir`` is given.
    """
    from face_reid_master.storage.gallery import save_gallery_npz

    def say(text: str) -> None:
        if log is not None:
            print(text, file=log, flush=True)

    work = Path(tempfile.mkdtemp(prefix="face-reid-eval-live-")) if keep_dir is None else keep_dir
    work.mkdir(parents=True, exist_ok=True)
    say(f"live: work folder {work} (face database, gallery, master log; deleted at the end)")
    master_args = ["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={work / 'faces.db'}",
                   "-p", "max_publish_rate_hz:=0.0",  # every cycle's state: the evaluation samples them all
                   "-p", "topic_discovery_period_s:=0.5", "-p", "stats_log_period_s:=1.0",
                   "-p", f"embedding_space:={embedding_space}",
                   "-p", f"body_appearance_tracking:={'true' if body_appearance_tracking else 'false'}"]
    if gallery:
        save_gallery_npz(gallery, work / "gallery.npz")
        master_args += ["-p", f"gallery_path:={work / 'gallery.npz'}"]
    if likelihood_path is not None:
        master_args += ["-p", f"likelihood_path:={Path(likelihood_path).resolve()}"]
    if body_metric_path is not None:
        master_args += ["-p", f"body_metric_path:={Path(body_metric_path).resolve()}"]
    if confidence_map_path is not None:
        master_args += ["-p", f"confidence_map_path:={Path(confidence_map_path).resolve()}"]
    children: list[ChildProcess] = []
    try:
        children.append(start_child("master", master_args, child_env(domain_id, run_id), work))
        return _play(frames, day_of_frame, children[0], startup_timeout_s, say)
    finally:
        stop_children(children)
        if keep_dir is None:
            shutil.rmtree(work, ignore_errors=True)


def _play(frames: Sequence[CameraFrameRecord], day_of_frame: Sequence[int], master: ChildProcess,
          startup_timeout_s: float, say: Any) -> LiveRun:
    """Wait for the master, publish the frames on schedule while collecting /tracks_named, then convert."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions

    from face_reid_master.ros.tracks_in import subscribe_tracks
    from face_reid_msgs.msg import CameraFrame

    def check_master() -> None:
        code = master.proc.poll()
        if code is not None:
            raise LiveError(f"the master node exited with status {code}; last lines of {master.log_path}:\n"
                            f"{master.log_tail()}")

    rclpy.init(args=["face_reid_eval_live"], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("face_reid_eval_live")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    received: list[tuple[float, Any]] = []  # (receive wall time, message)
    got_any = [False]
    master_stats: dict[str, int] | None = None
    try:
        qos = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)

        def on_tracks(msg: Any) -> None:
            got_any[0] = True
            received.append((time.time(), msg))

        subscribe_tracks(node, on_tracks, "/tracks_named", qos=qos)  # an unsecured master (no network key)
        cameras = sorted({f.camera_id for f in frames})
        pubs = {c: node.create_publisher(CameraFrame, f"/{c}/face_reid/frames", qos) for c in cameras}

        def spin_until(wall_s: float) -> None:
            while (left := wall_s - time.time()) > 0:
                executor.spin_once(timeout_sec=min(left, 0.05))

        t_start = time.monotonic()
        say(f"live: starting the master node; waiting for it to subscribe to {len(cameras)} camera topics")
        while not (got_any[0] and all(p.get_subscription_count() >= 1 for p in pubs.values())):
            executor.spin_once(timeout_sec=0.1)
            check_master()
            if time.monotonic() - t_start > startup_timeout_s:
                missing = [c for c, p in pubs.items() if p.get_subscription_count() < 1]
                raise LiveError(f"the master was not ready after {startup_timeout_s:g} s (no /tracks_named: "
                                f"{not got_any[0]}, camera topics without subscriber: {missing}); log:\n"
                                f"{master.log_tail()}")
        startup_s = time.monotonic() - t_start
        say(f"live: master ready in {startup_s:.1f} s; publishing {len(frames)} frames in real time")
        received.clear()

        tcfg = TrackerConfig()
        day_pause_s = tcfg.lost_after_s + tcfg.delete_after_s + 1.0
        segments: list[tuple[float, float]] = []  # (wall start, scene - wall offset) per day
        sent: dict[int, float] = {}  # quantized stamp -> send wall time
        lags: list[float] = []
        detections = 0
        last_q = -1
        day = None
        wall0 = scene0 = 0.0
        next_print = time.time() + 10.0
        for i, frame in enumerate(frames):
            if day_of_frame[i] != day:
                if day is not None:
                    say(f"live: day {day} done; pausing {day_pause_s:g} s (every track deleted) before day "
                        f"{day_of_frame[i]}")
                    spin_until(time.time() + day_pause_s)
                day = day_of_frame[i]
                wall0, scene0 = time.time() + 0.5, float(frame.stamp_s)
                segments.append((wall0, scene0 - wall0))
            due = wall0 + (float(frame.stamp_s) - scene0)
            spin_until(due)
            now = time.time()
            q = max(round(now / _STAMP_QUANTUM_S), last_q + 1)  # unique, exactly recoverable stamps
            last_q = q
            stamp = q * _STAMP_QUANTUM_S
            pubs[frame.camera_id].publish(frame_record_to_msg(frame, stamp))
            sent[q] = now
            lags.append(now - due)
            detections += len(frame.people)
            if now >= next_print:
                next_print += 10.0
                check_master()
                say(f"  live: {i + 1}/{len(frames)} frames sent, {len(received)} /tracks_named received")
        spin_until(time.time() + _TAIL_S)
        check_master()
        master_stats = last_master_stats(master.log_path)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()

    to_scene = _segments_to_scene(segments) if segments else (lambda s: s)
    messages: list[TrackMessage] = []
    first_reply: dict[int, float] = {}  # a sent frame's quantized stamp -> when a message with that stamp arrived
    for recv, msg in received:
        wall = stamp_to_seconds(msg.header.stamp)
        q = round(wall / _STAMP_QUANTUM_S)
        if q in sent and q not in first_reply:
            first_reply[q] = recv
        messages.append(TrackMessage(to_scene(wall), tuple(track_from_msg(t, to_scene) for t in msg.tracks)))
    qs = sorted(first_reply)
    lat_s, has = frame_latencies(np.array(sorted(sent)) * _STAMP_QUANTUM_S, np.array(qs) * _STAMP_QUANTUM_S,
                                 np.array([first_reply[q] for q in qs]))
    latencies, answered = lat_s.tolist(), int(np.count_nonzero(has))
    lag = np.asarray(lags) if lags else np.zeros(1)
    lat = np.asarray(latencies) * 1e3

    def ms(values: NDArray[np.float64], pct: float) -> float | None:
        return round(float(np.percentile(values, pct)), 2) if values.size else None

    transport = {
        "startup_s": round(startup_s, 2),
        "frames_sent": len(sent),
        "detections_sent": detections,
        "frames_answered": answered,
        # what the master refused or dropped (its stats line, logged every second)
        "master_frames_not_applied": None if master_stats is None else
        master_stats.get("frames_received", 0) - master_stats.get("frames_applied", 0)
        + master_stats.get("frames_dropped_overload", 0),
        "tracks_named_messages": len(received),
        "send_lag_ms": {"median": round(float(np.median(lag)) * 1e3, 2), "max": round(float(lag.max()) * 1e3, 2)},
        "frames_sent_late_50ms": int(np.sum(lag > 0.05)),
        "frame_to_tracks_latency_ms": {"median": ms(lat, 50), "p95": ms(lat, 95),
                                       "max": round(float(lat.max()), 2) if lat.size else None},
        "day_pause_s": day_pause_s if len(segments) > 1 else None,
    }
    return LiveRun(messages, transport)
