"""A node's parameters as one table: declared with descriptions, defaults written to one YAML.

Shared by the camera and the master node (pure Python, no rclpy): the node declares every
:class:`ParamSpec` with its description, offline tools read the same ROS 2 params YAML, and
``config/<node>.yaml`` is generated from the table (tests keep them equal).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

ParamValue = bool | int | float | str | list[float] | list[str]


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter: name (dots = nested YAML), default (fixes the type), description."""

    name: str
    default: ParamValue
    description: str


class ParamTable:
    """The parameters of one node."""

    def __init__(self, node_name: str, specs: Sequence[ParamSpec], title: str) -> None:
        names = [s.name for s in specs]
        if len(names) != len(set(names)):
            raise ValueError(f"duplicate parameter names in {node_name}")
        self.node_name = node_name
        self.specs = tuple(specs)
        self.title = title
        self._by_name = {s.name: s for s in specs}

    def defaults(self) -> dict[str, ParamValue]:
        """All parameters at their default values (lists copied)."""
        return {s.name: list(s.default) if isinstance(s.default, list) else s.default for s in self.specs}

    def check_value(self, name: str, value: Any) -> ParamValue:
        """Validate one value against its declared default's type; ValueError names the parameter."""
        if name not in self._by_name:
            raise ValueError(f"unknown {self.node_name} parameter {name!r}")
        default = self._by_name[name].default
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif isinstance(default, float):
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            value = float(value) if ok else value
        elif isinstance(default, list) and (default == [] or isinstance(default[0], str)):
            ok = isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)
            value = [str(v) for v in value] if ok else value
        elif isinstance(default, list):
            ok = isinstance(value, list | tuple) and len(value) == len(default) and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value
            )
            value = [float(v) for v in value] if ok else value
        else:
            ok = isinstance(value, str)
        if not ok:
            raise ValueError(f"parameter {name!r} must be like {default!r}, got {value!r}")
        return value

    def load_yaml(self, path: str | Path) -> dict[str, ParamValue]:
        """Read a ROS 2 params file (``node: ros__parameters: {...}``) over the defaults."""
        with open(path, encoding="utf-8") as fh:
            doc = yaml.safe_load(fh) or {}
        section = doc.get(self.node_name, doc.get("/**", {})) if isinstance(doc, dict) else {}
        raw = (section or {}).get("ros__parameters", {}) if isinstance(section, dict) else {}
        if not isinstance(raw, dict):
            raise ValueError(f"{path}: '{self.node_name}.ros__parameters' must be a mapping")
        params = self.defaults()
        for key, value in _flatten(raw).items():
            params[key] = self.check_value(key, value)
        return params

    def write_yaml(self, path: str | Path, usage: str) -> None:
        """Write every parameter at its default, each under a comment with its description."""
        lines = [
            f"# Defaults of {self.title}.",
            "# Generated from the parameter table in the code; every parameter with its unit.",
            f"# Use: {usage}",
            f"{self.node_name}:",
            "  ros__parameters:",
        ]
        nested_open = ""
        for spec in self.specs:
            group, _, leaf = spec.name.rpartition(".")
            indent = "    "
            if group:
                if group != nested_open:
                    lines.append(f"    {group}:")
                    nested_open = group
                indent = "      "
            lines.append(f"{indent}# {spec.description}")
            lines.append(f"{indent}{leaf}: {json.dumps(spec.default)}")
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")

    def help_text(self) -> str:
        """One line per parameter, for --help."""
        return "\n".join(f"  {s.name} (default {s.default!r}): {s.description}" for s in self.specs)


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out
