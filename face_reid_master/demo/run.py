"""``face-reid-demo``: the whole suite live over DDS on one machine, playing the built-in scripted scene.

Processes (:mod:`face_reid_master.demo.children`: each in its own process group, all on a private ROS domain
with discovery limited to loopback): per camera an RGB-D *player* (:mod:`face_reid_master.sim.rgbd_player`,
the camera's sensor: renders the camera's frames in real time with licensed face photos pasted on the heads and
everybody in made-up textured clothes) and a ``face-reid-camera`` node (the real camera pipeline, describing faces
and bodies); one ``face-reid-master`` (Bayesian face table, tracking and deciding faceless tracks by body too,
predefined people from a gallery folder, a temporary face database). This process subscribes to
``/tracks_named``, prints a live table of who is where and, at the end, a summary against the ground truth
(:mod:`face_reid_master.demo.report`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from face_reid_camera.common.stamps import stamp_to_seconds
from face_reid_master.demo.children import (
    ChildProcess,
    child_env,
    domain_id_for_run,
    read_events,
    start_child,
    stop_children,
)
from face_reid_master.demo.report import format_summary, format_table, summarize
from face_reid_master.demo.scenario import DEFAULT_SEED, DemoScenario, build_scenario, duration_range_text
from face_reid_master.evaluation.published_tracks import TrackMessage
from face_reid_master.ros.convert import track_from_msg

__all__ = ["DemoError", "main"]


class DemoError(RuntimeError):
    """The demo could not run (a process failed to start or died): the message says which and why."""


def _ros_setting(text: str) -> str:
    """A ``name:=value`` parameter setting (what ``--ros-args -p`` takes)."""
    name, sep, _value = text.partition(":=")
    if not sep or not name or not all(c.isalnum() or c in "_." for c in name):
        raise argparse.ArgumentTypeError(f"expected NAME:=VALUE (a node parameter), got {text!r}")
    return text


def _setting_problems(camera: Sequence[str], master: Sequence[str]) -> tuple[list[str], list[str]]:
    """--camera-param / --master-param checked by the nodes' own loader before anything starts: (what the nodes
    would refuse, names they would ignore), one line each."""
    from face_reid_camera.common.params_files import check_sources
    from face_reid_camera.ros.params import TABLE as CAMERA
    from face_reid_master.ros.params import TABLE as MASTER

    problems, warnings = [], []
    for flag, table, settings in (("--camera-param", CAMERA, camera), ("--master-param", MASTER, master)):
        check = check_sources(table, settings=settings)
        problems += [f"{flag}: {line.removeprefix('-p ')}" for line in check.problems]
        warnings += [f"{flag}: {line.removeprefix('-p ')}" for line in check.warnings]
    return problems, warnings


def _fmt(values: Sequence[float]) -> str:
    return "[" + ", ".join(f"{float(v):.6f}" for v in values) + "]"


def _make_gallery(scenario: DemoScenario, folder: Path) -> None:
    """The master's gallery folder: NAME/photo for the predefined people (photos not shown in the scene)."""
    for person in scenario.people:
        if not person.in_gallery:
            continue
        target = folder / person.name
        target.mkdir(parents=True)
        for photo in person.gallery_photos:
            shutil.copyfile(photo, target / photo.name)


class _Run:
    """One live run: children, the /tracks_named subscriber, the table and the collected messages."""

    def __init__(self, scenario: DemoScenario, args: argparse.Namespace, work: Path, out: TextIO) -> None:
        self.scenario, self.args, self.work, self.out = scenario, args, work, out
        self.children: list[ChildProcess] = []
        self.messages: list[TrackMessage] = []
        self.t0 = math.inf
        self.player_done: dict[str, dict[str, Any]] = {}
        self.interactive = out.isatty() and not os.environ.get("CI")

    # --- start-up --------------------------------------------------------------------------------
    def start(self, domain_id: int, run_id: str) -> None:
        env = child_env(domain_id, run_id)
        logs = self.work / "logs"
        logs.mkdir()
        gallery = self.work / "gallery"
        _make_gallery(self.scenario, gallery)
        master_args = ["-m", "face_reid_master.ros.node", "--ros-args", "-p", f"db_path:={self.work / 'faces.db'}",
                       "-p", "topic_discovery_period_s:=0.5", "-p", "stats_log_period_s:=10.0"]
        if any(p.in_gallery for p in self.scenario.people):
            master_args += ["-p", f"gallery_path:={gallery}"]
        for setting in self.args.master_param:
            master_args += ["-p", setting]
        self.children.append(start_child("master", master_args, env, logs))
        for c, cam in enumerate(self.scenario.cameras):
            x, y, z, roll, pitch, yaw = cam.xyz_rpy
            self.children.append(start_child(f"{cam.camera_id}_node", [
                "-m", "face_reid_camera.ros.node", "--ros-args", "-r", f"__ns:=/{cam.camera_id}",
                "-p", f"camera_id:={cam.camera_id}", "-p", f"camera_pose_xyz_m:={_fmt((x, y, z))}",
                "-p", f"camera_pose_rpy_rad:={_fmt((roll, pitch, yaw))}", "-p", "image_qos:=reliable",
                "-p", "max_frame_age_s:=1.0", *(a for setting in self.args.camera_param for a in ("-p", setting))],
                env, logs))
            spec_path = self.work / f"{cam.camera_id}_player.json"
            spec_path.write_text(json.dumps(self.scenario.player_spec(c, self.args.rate_hz).to_json()))
            self.children.append(start_child(f"{cam.camera_id}_player", [
                "-m", "face_reid_master.sim.rgbd_player", "--spec", str(spec_path),
                "--truth", str(self.work / f"{cam.camera_id}_truth.npz"),
                "--ros-args", "-r", f"__ns:=/{cam.camera_id}"], env, logs, talk=True))
        for child in self.players:
            threading.Thread(target=read_events, args=(child,), daemon=True).start()

    @property
    def players(self) -> list[ChildProcess]:
        return [c for c in self.children if c.name.endswith("_player")]

    def check_alive(self) -> None:
        for child in self.children:
            code = child.proc.poll()
            if code is None or (child in self.players and child.name in self.player_done):
                continue
            if child in self.players and code == 0 and time.time() > self.t0 + self.scenario.duration_s - 1:
                continue
            raise DemoError(f"{child.name} exited with status {code}; last lines of {child.log_path}:\n"
                            f"{child.log_tail()}")

    # --- ROS -----------------------------------------------------------------------------------------
    def ros_loop(self) -> None:
        import rclpy
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions

        from face_reid_master.ros.tracks_in import subscribe_tracks

        rclpy.init(args=["face_reid_demo"], signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("face_reid_demo")
        try:
            qos = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
            got_any = [False]

            def on_tracks(msg: Any) -> None:
                got_any[0] = True
                if not math.isfinite(self.t0):
                    return
                stamp = stamp_to_seconds(msg.header.stamp) - self.t0
                tracks = tuple(track_from_msg(t, lambda s: s - self.t0) for t in msg.tracks)
                self.messages.append(TrackMessage(stamp, tracks))

            subscribe_tracks(node, on_tracks, "/tracks_named", qos=qos)  # the demo's master has no network key
            self._wait_ready(node, rclpy, got_any)
            self._play(node, rclpy)
        finally:
            node.destroy_node()
            rclpy.try_shutdown()

    def _wait_ready(self, node: Any, rclpy: Any, got_any: list[bool]) -> None:
        """Until every player's camera node listens, the master publishes and subscribes to every camera."""
        deadline = time.monotonic() + self.args.startup_timeout_s
        ready: set[str] = set()
        self.say(f"starting {len(self.children)} processes (master, {len(self.scenario.cameras)} camera nodes and "
                 f"their RGB-D players) ...")
        t_start = time.monotonic()
        while True:
            rclpy.spin_once(node, timeout_sec=0.1)
            self.check_alive()
            for child, event in self._player_events():
                if event.get("event") == "ready":
                    ready.add(child.name)
                elif event.get("event") == "error":
                    raise DemoError(f"{child.name}: {event.get('message')}\n{child.log_tail()}")
            topics = [f"/{cam.camera_id}/face_reid/frames" for cam in self.scenario.cameras]
            master_listens = all(node.count_subscribers(t) >= 1 for t in topics)
            if len(ready) == len(self.players) and got_any[0] and master_listens:
                break
            if time.monotonic() > deadline:
                waiting = [c.name for c in self.players if c.name not in ready]
                if not got_any[0]:
                    waiting.append("master (no /tracks_named yet)")
                elif not master_listens:
                    waiting.append("master (not subscribed to every camera topic)")
                tails = "\n".join(f"  {c.name}:\n{c.log_tail(8)}" for c in self.children)
                raise DemoError(f"start-up took longer than {self.args.startup_timeout_s:g} s, still waiting for "
                                f"{', '.join(waiting)}; logs:\n{tails}")
        self.say(f"all processes up in {time.monotonic() - t_start:.1f} s; playing the scenario")

    def _play(self, node: Any, rclpy: Any) -> None:
        self.t0 = time.time() + 0.5
        for child in self.players:
            assert child.proc.stdin is not None
            child.proc.stdin.write(f"start {self.t0:.6f}\n")
            child.proc.stdin.flush()
        period = 1.0 if self.interactive else 5.0
        next_print = self.t0 + period
        end = self.t0 + self.scenario.duration_s + 1.5  # the last frames still reach the master
        while time.time() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
            self.check_alive()
            self._collect_done()
            now = time.time()
            if now >= next_print and now - self.t0 <= self.scenario.duration_s:  # no table after the scene
                next_print += period
                last = self.messages[-1] if self.messages else None
                table = format_table(self.scenario, last, now - self.t0, compact=not self.interactive)
                if self.interactive:
                    self.out.write(f"\x1b[H\x1b[2Jface-reid-demo: who is where (Ctrl-C stops)\n{table}\n")
                else:
                    self.out.write(table + "\n")
                self.out.flush()
        deadline = time.time() + 5.0
        while len(self.player_done) < len(self.players) and time.time() < deadline:
            self._collect_done()
            time.sleep(0.05)

    def _player_events(self) -> list[tuple[ChildProcess, dict[str, Any]]]:
        """The events the players printed since the last call, in order per player."""
        out = []
        for child in self.players:
            while not child.events.empty():
                out.append((child, child.events.get()))
        return out

    def _collect_done(self) -> None:
        """Record the players' "done" events (frames rendered and skipped, render time)."""
        for child, event in self._player_events():
            if event.get("event") == "done":
                self.player_done[child.name] = event

    def say(self, text: str) -> None:
        print(f"[face-reid-demo] {text}", file=self.out, flush=True)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="face-reid-demo",
        description="Run the face-reid suite live on this machine: simulated RGB-D cameras (licensed face photos "
                    "rendered in real time) -> camera nodes -> master, over DDS on loopback only. Prints who is "
                    "where every second and a summary of the re-identifications at the end (about a minute).",
    )
    p.add_argument("--duration-s", type=float, default=50.0,
                   help=f"scenario length in seconds (default 50; {duration_range_text()})")
    p.add_argument("--cameras", type=int, default=2, help="number of cameras, 1-4 (default 2)")
    p.add_argument("--people", type=int, default=4, help="people in the scene, 1-6 (1-4 with one camera; default 4)")
    p.add_argument("--gallery-people", type=int, default=None,
                   help="how many of them are predefined people with a name (default 2, or all of 1)")
    p.add_argument("--rate-hz", type=float, default=5.0, help="frames per second rendered per camera (default 5)")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"scenario seed (default {DEFAULT_SEED})")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID for all the demo's processes, 0..232 (default: the environment's "
                        "ROS_DOMAIN_ID, else random in 1..100)")
    p.add_argument("--faces", type=Path, default=None,
                   help="face photo folder, one sub-folder per person (default: the licensed photos shipped)")
    p.add_argument("--keep-db", action="store_true",
                   help="keep the temporary folder (face database, gallery, logs) instead of deleting it")
    p.add_argument("--json", type=Path, default=None, help="also write the summary as JSON to this file")
    p.add_argument("--floor-plan", type=Path, default=None, metavar="PNG",
                   help="also draw the run seen from above (room, cameras, tracks by name) into this PNG file")
    p.add_argument("--camera-param", action="append", default=[], type=_ros_setting, metavar="NAME:=VALUE",
                   help="a parameter for every camera node (repeatable), e.g. floor_map_period_s:=2.0")
    p.add_argument("--master-param", action="append", default=[], type=_ros_setting, metavar="NAME:=VALUE",
                   help="a parameter for the master (repeatable), e.g. publish_people:=true")
    p.add_argument("--startup-timeout-s", type=float, default=90.0, help="give up if start-up takes longer")
    return p


class _Terminated(Exception):
    """SIGTERM received: clean up like Ctrl-C."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the demo; exit status 0 done, 1 failure of a process, 2 bad arguments, 130 interrupted."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C works even if started with SIGINT ignored
    out = sys.stdout
    try:
        domain_id = domain_id_for_run(args.domain_id)
    except ValueError as exc:
        print(f"face-reid-demo: {exc}", file=sys.stderr)
        return 2
    if not (math.isfinite(args.rate_hz) and 0.5 <= args.rate_hz <= 30):
        print(f"face-reid-demo: --rate-hz must be in [0.5, 30], got {args.rate_hz}", file=sys.stderr)
        return 2
    problems, warnings = _setting_problems(args.camera_param, args.master_param)
    for line in [f"warning: {w}" for w in warnings] + problems:
        print(f"face-reid-demo: {line}", file=sys.stderr)
    if problems:  # the nodes would refuse them
        return 2
    from face_reid_camera.common.resources import demo_faces_dir

    faces = args.faces if args.faces is not None else demo_faces_dir()
    if not faces.is_dir():
        print(f"face-reid-demo: no face photos at {faces}: run from a source checkout or a `pip install .` "
              "(which installs share/face_reid/demo_faces), or pass --faces DIR", file=sys.stderr)
        return 2
    try:
        gallery = min(2, args.people) if args.gallery_people is None else args.gallery_people  # --people 1 works
        scenario = build_scenario(faces, args.seed, args.cameras, args.people, gallery, args.duration_s)
    except ValueError as exc:
        print(f"face-reid-demo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    run_id = uuid.uuid4().hex[:12]
    # this process joins the same private, loopback-only domain before rclpy is imported
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    work = Path(tempfile.mkdtemp(prefix="face-reid-demo-"))
    run = _Run(scenario, args, work, out)
    cast = ", ".join(f"{p.name}{' (gallery)' if p.in_gallery else ''}" for p in scenario.people)
    seed_note = f" (seed {args.seed} skipped: script checks failed)" if scenario.seed != args.seed else ""
    run.say(f"scenario seed {scenario.seed}{seed_note}: {scenario.duration_s:.0f} s, room "
            f"{scenario.world.room.width_m:g} x {scenario.world.room.depth_m:g} m, {len(scenario.cameras)} cameras at "
            f"{args.rate_hz:g} Hz, people: {cast}")
    run.say(f"ROS_DOMAIN_ID={domain_id}, discovery on localhost only; work folder {work}")

    def on_term(signum: int, frame: Any) -> None:
        raise _Terminated()

    previous = signal.signal(signal.SIGTERM, on_term)
    status = 0
    started = time.monotonic()
    try:
        run.start(domain_id, run_id)
        run.ros_loop()
    except DemoError as exc:
        print(f"face-reid-demo: FAILED: {exc}", file=sys.stderr, flush=True)
        status = 1
    except (KeyboardInterrupt, _Terminated):
        print("\nface-reid-demo: interrupted, stopping every process", file=sys.stderr, flush=True)
        status = 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up short
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        stop_children(run.children)
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        if status == 0:
            summary = summarize(scenario, run.messages)
            summary["wall_time_s"] = round(time.monotonic() - started, 1)
            summary["domain_id"] = domain_id
            summary["players"] = {name: {k: v for k, v in ev.items() if k != "event"}
                                  for name, ev in sorted(run.player_done.items())}
            if run.interactive:
                out.write("\n")
            out.write(format_summary(summary) + "\n")
            for name, ev in summary["players"].items():
                out.write(f"{name}: {ev.get('frames')} frames rendered, {ev.get('skipped')} skipped (late), "
                          f"{ev.get('mean_render_ms')} ms per render\n")
            out.write(f"wall time {summary['wall_time_s']:.1f} s\n")
            out.flush()
            if args.json is not None:
                args.json.write_text(json.dumps(summary, indent=2))
            if args.floor_plan is not None:
                from face_reid_master.demo.floor_plan import draw_floor_plan

                draw_floor_plan(scenario, run.messages, args.floor_plan)
                out.write(f"floor plan: {args.floor_plan}\n")
    finally:
        if args.keep_db:
            print(f"face-reid-demo: kept {work} (faces.db, gallery/, logs/)", file=out, flush=True)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return status


if __name__ == "__main__":
    sys.exit(main())
