"""The house rules, read from the imports of every module (``import`` statements anywhere in a file):

1. ``face_reid_camera`` never imports ``face_reid_master``;
2. runtime code never imports the simulator, the evaluation, the demo, the tools or offline training;
3. no core module (runtime code outside a ``ros/`` package) imports rclpy or a ROS message package;
4. no runtime class is longer than 400 lines and no runtime module longer than 600 (a class doing several jobs
   is split by responsibility);
5. code both packages use lives in ``face_reid_camera.common``: the master's runtime imports of the camera package
   are that and the camera's face and body models, and ``common`` imports nothing else of the camera package.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TOOLING = ("face_reid_master.sim", "face_reid_master.evaluation", "face_reid_master.demo", "face_reid_master.tools",
           "face_reid_master.training", "face_reid_camera.tools")
MAX_CLASS_LINES = 400
MAX_MODULE_LINES = 600
SHARED = ("face_reid_camera.common",)
CAMERA_MODELS = ("face_reid_camera.faces", "face_reid_camera.body")  # the master embeds gallery photos and bodies
ROS_MODULES = ("rclpy", "rcl_interfaces", "builtin_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs",
               "visualization_msgs", "diagnostic_msgs", "lifecycle_msgs", "face_reid_msgs", "nav_msgs")


def _module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


def _within(name: str, packages: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


def violations(root: Path) -> list[str]:
    """Every broken rule in the packages under ``root``, as 'module imports X (rule N)'."""
    found = []
    for package in ("face_reid_camera", "face_reid_master"):
        for path in sorted((root / package).rglob("*.py")):
            module = _module_name(path, root)
            runtime = not _within(module, TOOLING)
            core = runtime and not any(part == "ros" for part in module.split(".")[1:])
            for name in sorted(_imports(path)):
                if package == "face_reid_camera" and _within(name, ("face_reid_master",)):
                    found.append(f"{module} imports {name} (rule 1: the camera never imports the master)")
                if runtime and _within(name, TOOLING):
                    found.append(f"{module} imports {name} (rule 2: runtime code never imports tooling)")
                if core and _within(name, ROS_MODULES):
                    found.append(f"{module} imports {name} (rule 3: core modules are ROS-free)")
                if _within(name, ("face_reid_camera",)) and not _within(name, SHARED) and (
                        _within(module, SHARED) or (package == "face_reid_master" and runtime
                                                    and not _within(name, CAMERA_MODELS))):
                    found.append(f"{module} imports {name} (rule 5: shared code lives in face_reid_camera.common)")
    return found


def oversized(root: Path) -> list[str]:
    """Every runtime module and class under ``root`` longer than its limit (rule 4), as 'name: N lines (> L)'."""
    found = []
    for package in ("face_reid_camera", "face_reid_master"):
        for path in sorted((root / package).rglob("*.py")):
            module = _module_name(path, root)
            if _within(module, TOOLING):
                continue
            text = path.read_text(encoding="utf-8")
            sizes = {module: (len(text.splitlines()), MAX_MODULE_LINES)}
            for node in ast.walk(ast.parse(text, filename=str(path))):
                if isinstance(node, ast.ClassDef):
                    sizes[f"{module}.{node.name}"] = (node.end_lineno - node.lineno + 1, MAX_CLASS_LINES)
            for name, (lines, limit) in sizes.items():
                if lines > limit:
                    found.append(f"{name}: {lines} lines (> {limit})")
    return found


def test_the_tree_keeps_the_import_rules() -> None:
    assert violations(REPO) == []


def test_runtime_classes_and_modules_keep_their_size() -> None:
    assert oversized(REPO) == []


def test_an_oversized_class_or_module_is_found(tmp_path: Path) -> None:
    body = "".join(f"    x{k} = {k}\n" for k in range(MAX_CLASS_LINES))
    files = {
        "face_reid_master/__init__.py": "",
        "face_reid_master/big.py": "class Big:\n" + body,  # 401 lines
        "face_reid_master/long.py": "x = 0\n" * (MAX_MODULE_LINES + 1),
        "face_reid_master/sim/huge.py": "x = 0\n" * 5000,  # tooling: no limit
        "face_reid_master/ok.py": "class Ok:\n" + body[: -len("    x399 = 399\n")],
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    assert oversized(tmp_path) == [
        "face_reid_master.big.Big: 401 lines (> 400)",
        "face_reid_master.long: 601 lines (> 600)",
    ]


def test_a_violation_of_each_rule_is_found(tmp_path: Path) -> None:
    files = {
        "face_reid_camera/__init__.py": "",
        "face_reid_camera/pipeline.py": "import numpy\nfrom face_reid_master.core import MasterCore\n",
        "face_reid_camera/ros/node.py": "import rclpy\n",
        "face_reid_camera/common/checks.py": "from face_reid_camera.people.heads import HeadFinder\n",
        "face_reid_master/__init__.py": "",
        "face_reid_master/ros/node.py": "from face_reid_camera.pipeline import CameraPipeline\n"
                                        "from face_reid_camera.common.ros.sealed import unpack\n"
                                        "from face_reid_camera.faces.photos import PhotoEmbedder\n",
        "face_reid_master/core.py": "def f():\n    from face_reid_master.sim import simulate\n",
        "face_reid_master/tracking/tracker.py": "from rclpy.node import Node\n",
        "face_reid_master/body/metric_file.py": "from face_reid_master.training.body import xqda\n",
        "face_reid_master/sim/simulate.py": "import rclpy\nfrom face_reid_master.core import MasterCore\n",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    found = violations(tmp_path)
    assert found == [
        "face_reid_camera.common.checks imports face_reid_camera.people.heads "
        "(rule 5: shared code lives in face_reid_camera.common)",
        "face_reid_camera.common.checks imports face_reid_camera.people.heads.HeadFinder "
        "(rule 5: shared code lives in face_reid_camera.common)",
        "face_reid_camera.pipeline imports face_reid_master.core (rule 1: the camera never imports the master)",
        "face_reid_camera.pipeline imports face_reid_master.core.MasterCore "
        "(rule 1: the camera never imports the master)",
        "face_reid_master.body.metric_file imports face_reid_master.training.body "
        "(rule 2: runtime code never imports tooling)",
        "face_reid_master.body.metric_file imports face_reid_master.training.body.xqda "
        "(rule 2: runtime code never imports tooling)",
        "face_reid_master.core imports face_reid_master.sim (rule 2: runtime code never imports tooling)",
        "face_reid_master.core imports face_reid_master.sim.simulate (rule 2: runtime code never imports tooling)",
        "face_reid_master.ros.node imports face_reid_camera.pipeline "
        "(rule 5: shared code lives in face_reid_camera.common)",
        "face_reid_master.ros.node imports face_reid_camera.pipeline.CameraPipeline "
        "(rule 5: shared code lives in face_reid_camera.common)",
        "face_reid_master.tracking.tracker imports rclpy.node (rule 3: core modules are ROS-free)",
        "face_reid_master.tracking.tracker imports rclpy.node.Node (rule 3: core modules are ROS-free)",
    ]
