"""The console-script entry point shared by the nodes: --help without ROS, start, spin, clean shutdown."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from face_reid_camera.common.param_table import ParamTable


def run_node(
    prog: str, usage: str, table: ParamTable, make_node: Callable[[], Any],
    fatal: tuple[type[BaseException], ...], argv: list[str] | None = None,
) -> int:
    """Run ``make_node()`` until Ctrl-C / shutdown; returns the exit status.

    ``--help`` (without ``--ros-args``) prints ``usage`` and every parameter without starting ROS.
    An exception of a ``fatal`` type while building the node (a missing model, a bad parameter)
    is printed as one line and gives exit status 2 instead of a traceback.
    """
    argv = list(sys.argv if argv is None else argv)
    if any(a in ("-h", "--help") for a in argv[1:]) and "--ros-args" not in argv:
        print(usage + table.help_text())
        return 0
    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=argv)
    try:
        node = make_node()
    except fatal as exc:
        print(f"[{prog}] FATAL: cannot start: {exc}", file=sys.stderr, flush=True)
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
