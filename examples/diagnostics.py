#!/usr/bin/env python3
"""Print each node's status on /diagnostics once (level, name, warnings, values), for a site check without a
ROS 2 installation (with one: ``ros2 topic echo /diagnostics`` or rqt_robot_monitor).

Usage: diagnostics.py [SECONDS]: listen this long (default 5; the nodes publish once a second), Ctrl-C ends it
earlier. Exit status 0 when some node was heard, 1 when none was."""

import os
import signal
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


def main() -> int:
    args = remove_ros_args(sys.argv)[1:]
    if len(args) > 1 or not (args[:1] or ["5"])[0].isdigit():
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    seconds = int(args[0]) if args else 5
    seen: set[str] = set()

    def show(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name not in seen:
                seen.add(status.name)
                level = LEVELS.get(status.level[0] if isinstance(status.level, bytes) else status.level, "?")
                print(level, status.name, "|", status.message)
                print("   ", ", ".join(f"{v.key}={v.value}" for v in status.values), flush=True)

    domain = os.environ.get("ROS_DOMAIN_ID", "0")
    stop = []  # Ctrl-C only asks the loop to end (a KeyboardInterrupt inside rclpy could surface as another error)
    signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("diagnostics_peek")
    executor = SingleThreadedExecutor()  # made before the waiting line: a Ctrl-C then never meets a half-made one
    executor.add_node(node)
    try:
        node.create_subscription(DiagnosticArray, "/diagnostics", show, 10)
        print(f"diagnostics: listening to /diagnostics for {seconds} s (ROS_DOMAIN_ID={domain}); Ctrl-C ends",
              file=sys.stderr, flush=True)
        deadline = time.monotonic() + seconds
        while not stop and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.2)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    if not seen and not stop:  # Ctrl-C: the way to end it early
        print(f"diagnostics: no node heard in {seconds} s on ROS_DOMAIN_ID={domain}: are the nodes running, with "
              "this domain id, and does discovery reach their hosts (ROS_AUTOMATIC_DISCOVERY_RANGE)?",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
