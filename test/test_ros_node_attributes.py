"""No node class of the project assigns an attribute that rclpy's own node keeps.

rclpy's ``Node`` holds the entities its executor waits on in plain attributes (``_timers``, ``_services``, ...).
A subclass that assigns one of them replaces rclpy's list: the master node did, and its lifecycle and parameter
services stopped being answered, its timers were waited on twice, and deactivating destroyed the diagnostics timer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NODE_BASES = {"Node", "LifecycleNode", "ManagedNode"}


def _assigned_attributes(cls: ast.ClassDef) -> set[str]:
    """Names ``X`` of every ``self.X = ...`` (plain, annotated, augmented or tuple target) in the class's methods."""
    out: set[str] = set()
    for node in ast.walk(cls):
        targets: list[ast.expr] = []
        if isinstance(node, ast.Assign):
            targets = list(node.targets)
        elif isinstance(node, ast.AnnAssign | ast.AugAssign):
            targets = [node.target]
        for target in targets:
            for t in ast.walk(target):
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id == "self":
                    out.add(t.attr)
    return out


def _node_classes() -> list[tuple[str, ast.ClassDef]]:
    found = []
    for package in ("face_reid_camera", "face_reid_master"):
        for path in sorted((REPO / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef) and {getattr(b, "id", getattr(b, "attr", "")) for b in node.bases} \
                        & NODE_BASES:
                    found.append((f"{path.relative_to(REPO)}:{node.name}", node))
    return found


@pytest.mark.ros
def test_node_classes_leave_rclpys_attributes_alone(ros_context) -> None:
    from rclpy.lifecycle import LifecycleNode

    node = LifecycleNode("attribute_probe", context=ros_context())
    try:
        rclpy_attributes = set(vars(node))
    finally:
        node.destroy_node()
    assert {"_timers", "_services", "_subscriptions"} <= rclpy_attributes  # what this test guards
    classes = _node_classes()
    assert len(classes) >= 4, [name for name, _ in classes]  # master, camera, map, goto, the lifecycle base
    clashes = {name: sorted(_assigned_attributes(cls) & rclpy_attributes) for name, cls in classes}
    assert not {name: attrs for name, attrs in clashes.items() if attrs}
