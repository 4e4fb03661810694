"""face-reid-up: start this host's nodes of a camera network from one network file, keep them running.

    face-reid-up network.yaml                 # the nodes of the host named like this machine
    face-reid-up network.yaml --host pc-kitchen --role camera
    face-reid-up network.yaml --dry-run       # print the commands (the ros2 run equivalent) and exit

Each node runs as its own process (namespace, params files, parameters and remaps from the file; see
face_reid_master/tools/network_file.py for the format), its log in --log-dir. A node that exits is started
again after 1 s, then 2, 4, ... up to --max-backoff-s (back to 1 s once it ran a minute). Ctrl-C (or SIGTERM)
stops every node and exits 0. The same file drives every PC of the network.
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

from face_reid_camera.common.sealing import load_network_key
from face_reid_master.demo.children import spawn, stop_processes
from face_reid_master.tools.network_file import NodeSpec, load_network_file, network_key_path, node_specs

STABLE_S = 60.0  # a node that ran this long gets its back-off reset


@dataclass
class _Running:
    spec: NodeSpec
    proc: subprocess.Popen[str] | None = None
    started_s: float = 0.0
    backoff_s: float = 1.0
    restart_at_s: float = 0.0
    log: Path = field(default_factory=Path)


def _env(spec: NodeSpec) -> dict[str, str]:
    env = dict(os.environ)
    env.update(dict(spec.env))
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def supervise(specs: list[NodeSpec], log_dir: Path, max_backoff_s: float = 30.0, stop: list[bool] | None = None,
              say: Callable[[str], object] = print) -> int:
    """Run ``specs`` until ``stop[0]`` is set (by the signal handlers): start, watch, restart with back-off."""
    stop = stop if stop is not None else [False]
    log_dir.mkdir(parents=True, exist_ok=True)
    nodes = [_Running(s, log=log_dir / f"{s.name.replace(' ', '_')}.log") for s in specs]

    def start(node: _Running) -> None:
        with open(node.log, "a") as log:
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
                    if ran >= STABLE_S:
                        node.backoff_s = 1.0
                    say(f"face-reid-up: {node.spec.name} exited with status {node.proc.returncode} after {ran:.1f} s; "
                        f"restarting in {node.backoff_s:g} s (last lines in {node.log})")
                    node.proc = None
                    node.restart_at_s = now + node.backoff_s
                    node.backoff_s = min(max_backoff_s, 2.0 * node.backoff_s)
                elif node.proc is None and now >= node.restart_at_s:
                    start(node)
            time.sleep(0.1)
    finally:
        stop_processes([n.proc for n in nodes if n.proc is not None])
        say(f"face-reid-up: stopped {len(nodes)} nodes")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="face-reid-up", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("network", type=Path, help="the network file (YAML)")
    parser.add_argument("--host", default=socket.gethostname(), help="this host's name in the file (default: the "
                        "machine's host name)")
    parser.add_argument("--role", choices=("all", "camera", "master"), default="all")
    parser.add_argument("--log-dir", type=Path, default=Path("face_reid_logs"),
                        help="node logs (default ./face_reid_logs)")
    parser.add_argument("--max-backoff-s", type=float, default=30.0, help="longest wait before a restart (s)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands and exit")
    args = parser.parse_args(argv)
    try:
        network = load_network_file(args.network)
        roles = ("camera", "master") if args.role == "all" else (args.role,)
        specs = node_specs(network, args.host, roles)
        if network_key_path(network) and specs and not args.dry_run:
            load_network_key(network_key_path(network))  # every node would fail on it: say so once, here
    except (OSError, ValueError) as exc:
        print(f"face-reid-up: {exc}", file=sys.stderr)
        return 2
    if not specs:
        print(f"face-reid-up: host {args.host!r} runs no {args.role} node in {args.network}", file=sys.stderr)
        return 2
    if args.dry_run:
        for spec in specs:
            env = " ".join(f"{k}={v}" for k, v in spec.env)
            print(f"# {spec.name}\n{env + ' ' if env else ''}{shlex.join([sys.executable, *spec.args])}")
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
