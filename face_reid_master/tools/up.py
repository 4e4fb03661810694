"""face-reid-up: start this host's nodes of a camera network from one network file, keep them running.

    face-reid-up network.yaml                 # the nodes of the host named like this machine
    face-reid-up network.yaml --host pc-kitchen --role camera
    face-reid-up network.yaml --dry-run       # check everything a start checks, print the commands, exit

Each node runs as its own process (namespace, params files, parameters and remaps from the file; see
face_reid_master/tools/network_file.py for the format), its log in --log-dir. Before any node starts, this
host's nodes are checked as their start would check them: params files exist, parse and hold declared parameters
of the right type and range (the `set:` values too), the key file, the model files, and every camera of the
network on its own topics and node names; each problem is one line and nothing starts (--dry-run: the same
checks, then the commands; exit 2 on a problem). A camera of the network that the master's known_camera_ids would
not hear is a warning. A node that crashes is started again after 1 s, then 2, 4, ...
up to --max-backoff-s (back to 1 s once it ran a minute); one that refuses its configuration (exit status 2,
a FATAL line) is not: its own error line is printed, and face-reid-up exits 2 once no node runs. Ctrl-C (or
SIGTERM) stops every node and exits 0 (2 if a node refused its configuration). The same file drives every PC.
"""

from __future__ import annotations

import argparse
import os
import shlex
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from face_reid_camera.common.errors import CONFIG_EXIT_STATUS, ModelLoadError
from face_reid_camera.common.param_table import ParamTable
from face_reid_camera.common.params_files import ParamsCheck, check_ros_args
from face_reid_camera.common.sealing import load_network_key
from face_reid_master.demo.children import spawn, stop_processes
from face_reid_master.tools.network_file import NodeSpec, load_network_file, network_key_path, node_specs

STABLE_S = 60.0  # a node that ran this long gets its back-off reset
_FILE_ERRORS = (OSError, ValueError, ModelLoadError)  # what a node's configure reports as a FATAL line


def _table(spec: NodeSpec) -> ParamTable:
    """The parameter table of the node a spec runs (camera or master)."""
    if spec.args[1] == "face_reid_camera.ros.node":
        from face_reid_camera.ros.params import TABLE as CAMERA

        return CAMERA
    from face_reid_master.ros.params import TABLE as MASTER

    return MASTER


def _camera_file_problems(values: dict[str, Any]) -> list[str]:
    """The camera's configure: its pipeline config, and the models it loads (missing or unusable)."""
    from face_reid_camera.ros import params as camera_params

    problems = []
    try:
        config = camera_params.pipeline_config(values)
        camera_params.camera_pose(values)
    except ValueError as exc:
        return [str(exc)]
    loads: list[Callable[[], object]] = []
    if config.detect_faces:
        from face_reid_camera.faces.detector import YuNetDetector
        from face_reid_camera.faces.embedder import load_embedder

        loads += [lambda: YuNetDetector(values["detector_model_path"] or None, num_threads=1),
                  lambda: load_embedder(str(values["embedder"]), 1, {"dlib": str(values["dlib_model_path"]),
                                                                     "sface": str(values["sface_model_path"])})]
    if config.describe_bodies:
        from face_reid_camera.body.projection import load_body_projection

        loads.append(lambda: load_body_projection(str(values["body_projection_path"])))
    return problems + _load_problems(loads)


def _load_problems(loads: list[Callable[[], object]]) -> list[str]:
    """Run each load as the node would at configure; the one-line reason of each that fails."""
    problems = []
    for load in loads:
        try:
            load()
        except _FILE_ERRORS as exc:
            problems.append(str(exc))
    return problems


def _master_file_problems(values: dict[str, Any]) -> list[str]:
    """The master's configure: its core config, and the files it reads (models, gallery, world->map)."""
    from face_reid_master.ros import params as master_params

    try:
        config = master_params.master_config(values)
    except ValueError as exc:
        return [str(exc)]
    gallery = str(values["gallery_path"])
    problems = [f"gallery_path {gallery}: no such file or folder"] if gallery and not os.path.exists(
        os.path.expanduser(gallery)) else []
    from face_reid_camera.common.param_table import config_from_values
    from face_reid_master.robot.people_outputs import PeopleOutputConfig, PeopleOutputs

    loads: list[Callable[[], object]] = [  # the /people options and their world->map file, as the node reads them
        lambda: PeopleOutputs(config_from_values(PeopleOutputConfig, values))]
    if values["likelihood_path"]:
        from face_reid_master.identity.size_likelihood import load_face_likelihood

        loads.append(lambda: load_face_likelihood(values["likelihood_path"]))
    else:
        from face_reid_master.identity.size_likelihood import default_face_likelihood

        loads.append(lambda: default_face_likelihood(str(values["embedding_space"])))
    if config.body_appearance_tracking and values["body_metric_path"]:
        from face_reid_master.body.metric_file import load_body_metric

        loads.append(lambda: load_body_metric(str(values["body_metric_path"])))
    if values["confidence_map_path"]:
        from face_reid_master.identity.confidence_map import load_confidence_map

        loads.append(lambda: load_confidence_map(str(values["confidence_map_path"])))
    return problems + _load_problems(loads)


@dataclass(frozen=True)
class _Camera:
    """A camera of the network as its node would run: its name in face-reid-up's lines, id, node and topic."""

    name: str
    camera_id: str
    node: str
    topic: str


def _network_cameras(network: dict[str, Any]) -> list[_Camera]:
    """Every camera of the network (all hosts), with its node name and output topic resolved."""
    keyed = bool(network_key_path(network))
    cameras = []
    for host in network["hosts"]:
        for spec in node_specs(network, host, ("camera",)):
            check = check_ros_args(_table(spec), spec.args)  # another host's files may be there only: values only
            ns = check.namespace.rstrip("/")
            topic = str(check.values["sealed_output_topic" if keyed else "output_topic"])
            cameras.append(_Camera(spec.name, str(check.values["camera_id"]), f"{ns}/{_table(spec).node_name}",
                                   topic if topic.startswith("/") else f"{ns}/{topic}"))
    return cameras


def _topic_problems(network: dict[str, Any]) -> list[str]:
    """Every camera of the network (all hosts) on its own node name and output topic: two in one namespace would
    run as one node name and publish into one topic, the master unable to tell their frames apart."""
    seen_nodes: dict[str, str] = {}
    seen_topics: dict[str, str] = {}
    problems = []
    for camera in _network_cameras(network):
        for seen, key, what in ((seen_nodes, camera.node, "run as the same node"),
                                (seen_topics, camera.topic, "publish on the same topic")):
            if key in seen:
                problems.append(f"{seen[key]} and {camera.name} {what} {key}: give each camera its own namespace "
                                "(or output topic)")
            seen.setdefault(key, camera.name)
    return problems


def _cameras_unheard(network: dict[str, Any], master: dict[str, Any]) -> list[str]:
    """The network's cameras a master with ``known_camera_ids`` (its values ``master``) would not hear: an id it
    does not list (their frames refused), or a topic not under /<a listed id>/ (never subscribed)."""
    from face_reid_master.camera_slots import camera_of_topic
    from face_reid_master.ros.params import clean_list

    known = clean_list(master["known_camera_ids"])
    if not known:  # any camera is accepted
        return []
    lines = []
    for camera in _network_cameras(network):
        if camera.camera_id not in known:
            lines.append(f"known_camera_ids {list(known)} leaves out {camera.name}: the master would refuse its "
                         f"frames (add {camera.camera_id!r})")
        elif camera_of_topic(camera.topic) not in known and camera.topic not in clean_list(master["camera_topics"]):
            lines.append(f"{camera.name} publishes on {camera.topic}, not under /<a known_camera_ids entry>/: the "
                         "master would not subscribe to it (list it in the master's camera_topics)")
    return lines


def preflight(network: dict[str, Any], specs: list[NodeSpec]) -> tuple[list[str], list[str]]:
    """Every check the start of ``specs`` would make, without starting them: (problems, warnings), one line each.

    Params files and ``set:`` values by the nodes' own loader (:func:`check_ros_args`), then what each node's
    configure reads (key file, models, gallery), and the network's camera topics."""
    problems: list[str] = []
    warnings: list[str] = []
    key = network_key_path(network)
    keys_checked: set[str] = set()

    def check_key(path: str, who: str) -> None:
        if path in keys_checked:
            return
        keys_checked.add(path)
        try:
            load_network_key(path)
        except (OSError, ValueError) as exc:
            problems.append(f"{who}{exc}")

    if key and specs:
        check_key(key, "")  # every node would fail on it: said once
    for spec in specs:
        check: ParamsCheck = check_ros_args(_table(spec), spec.args)
        problems += [f"{spec.name}: {p}" for p in check.problems]
        warnings += [f"{spec.name}: {w}" for w in check.warnings]
        if check.values["network_key_path"]:
            check_key(str(check.values["network_key_path"]), f"{spec.name}: ")
        camera = spec.args[1] == "face_reid_camera.ros.node"
        found = (_camera_file_problems if camera else _master_file_problems)(check.values)
        problems += [f"{spec.name}: {p}" for p in found]
        if not camera:
            warnings += [f"{spec.name}: {w}" for w in _cameras_unheard(network, check.values)]
    if any(spec.args[1] == "face_reid_camera.ros.node" for spec in specs):
        problems += _topic_problems(network)
    return problems, warnings


@dataclass
class _Running:
    spec: NodeSpec
    proc: subprocess.Popen[str] | None = None
    started_s: float = 0.0
    backoff_s: float = 1.0
    restart_at_s: float = 0.0
    log: Path = field(default_factory=Path)
    log_start: int = 0  # the log's size when this run started: its own lines come after
    refused: bool = False  # exited with CONFIG_EXIT_STATUS: not restarted


def _error_lines(node: _Running) -> list[str]:
    """The node's own error line(s) of its last run, from its log: its FATAL lines (else its last line)."""
    try:
        with open(node.log, "rb") as log:
            log.seek(node.log_start)
            lines = [ln.strip() for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    except OSError:
        return []
    fatal = [ln for ln in lines if "FATAL" in ln]
    return [ln[:300] for ln in (fatal or lines[-1:])][:10]


def _env(spec: NodeSpec) -> dict[str, str]:
    env = dict(os.environ)
    env.update(dict(spec.env))
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def supervise(specs: list[NodeSpec], log_dir: Path, max_backoff_s: float = 30.0, stop: list[bool] | None = None,
              say: Callable[[str], object] = print) -> int:
    """Run ``specs`` until ``stop[0]`` is set (by the signal handlers): start, watch, restart with back-off.

    A node that exits with CONFIG_EXIT_STATUS (it refused its configuration: starting it again changes nothing) is
    not restarted: its error lines are said; once every node refused, returns CONFIG_EXIT_STATUS (so does a stop
    after one refused)."""
    stop = stop if stop is not None else [False]
    log_dir.mkdir(parents=True, exist_ok=True)
    nodes = [_Running(s, log=log_dir / f"{s.name.replace(' ', '_')}.log") for s in specs]

    def start(node: _Running) -> None:
        with open(node.log, "a") as log:
            node.log_start = log.tell()
            node.proc = spawn(list(node.spec.args), _env(node.spec), stdin=subprocess.DEVNULL, stdout=log, stderr=log)
        node.started_s = time.monotonic()
        say(f"face-reid-up: started {node.spec.name} (pid {node.proc.pid}, log {node.log})")

    for node in nodes:
        start(node)
    try:
        while not stop[0]:
            now = time.monotonic()
            for node in nodes:
                if node.proc is not None and node.proc.poll() is not None:
                    ran = now - node.started_s
                    if node.proc.returncode == CONFIG_EXIT_STATUS:
                        node.refused, node.proc = True, None
                        say(f"face-reid-up: {node.spec.name} refused its configuration (exit status "
                            f"{CONFIG_EXIT_STATUS} after {ran:.1f} s): not restarted; fix it and run face-reid-up "
                            f"again (log {node.log}):")
                        for line in _error_lines(node):
                            say(f"face-reid-up:   {line}")
                        continue
                    if ran >= STABLE_S:
                        node.backoff_s = 1.0
                    say(f"face-reid-up: {node.spec.name} exited with status {node.proc.returncode} after {ran:.1f} s; "
                        f"restarting in {node.backoff_s:g} s (last lines in {node.log})")
                    node.proc = None
                    node.restart_at_s = now + node.backoff_s
                    node.backoff_s = min(max_backoff_s, 2.0 * node.backoff_s)
                elif node.proc is None and not node.refused and now >= node.restart_at_s:
                    start(node)
            if all(node.refused for node in nodes):
                break
            time.sleep(0.1)
    finally:
        stop_processes([n.proc for n in nodes if n.proc is not None])
        stopped = sum(not n.refused for n in nodes)  # running or waiting to restart; a refused node is gone already
        if stopped:
            say(f"face-reid-up: stopped {stopped} node{'s' if stopped > 1 else ''}")
    return CONFIG_EXIT_STATUS if any(node.refused for node in nodes) else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="face-reid-up", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("network", type=Path, help="the network file (YAML)")
    parser.add_argument("--host", default=socket.gethostname(), help="this host's name in the file (default: the "
                        "machine's host name)")
    parser.add_argument("--role", choices=("all", "camera", "master"), default="all",
                        help="start only this host's cameras or only its master (default: all its nodes)")
    parser.add_argument("--log-dir", type=Path, default=Path("face_reid_logs"),
                        help="node logs (default ./face_reid_logs)")
    parser.add_argument("--max-backoff-s", type=float, default=30.0,
                        help="longest wait before a restart (s; default 30)")
    parser.add_argument("--dry-run", action="store_true",
                        help="make every check a start makes, print the commands and exit (2 on a problem)")
    args = parser.parse_args(argv)
    try:
        network = load_network_file(args.network)
        roles = ("camera", "master") if args.role == "all" else (args.role,)
        specs = node_specs(network, args.host, roles)
    except (OSError, ValueError) as exc:
        print(f"face-reid-up: {exc}", file=sys.stderr)
        return 2
    if not specs:
        print(f"face-reid-up: host {args.host!r} runs no {args.role} node in {args.network}", file=sys.stderr)
        return 2
    problems, warnings = preflight(network, specs)
    if args.dry_run:
        for spec in specs:
            env = " ".join(f"{k}={v}" for k, v in spec.env)
            print(f"# {spec.name}\n{env + ' ' if env else ''}{shlex.join([sys.executable, *spec.args])}")
    for line in warnings:
        print(f"face-reid-up: warning: {line}", file=sys.stderr)
    for line in problems:
        print(f"face-reid-up: {line}", file=sys.stderr)
    if problems:  # a start would fail on each: none is made
        return CONFIG_EXIT_STATUS
    if args.dry_run:
        return 0
    stop = [False]

    def on_signal(signum: int, _frame: object) -> None:
        stop[0] = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    return supervise(specs, args.log_dir, args.max_backoff_s, stop,
                     say=lambda line: print(line, file=sys.stderr, flush=True))


if __name__ == "__main__":
    sys.exit(main())
