"""One declaration per parameter: type (from the default), description with unit, range or choices, read-only.

Pure Python (no rclpy). The same :class:`ParamSpec` gives the ROS ``ParameterDescriptor``
(``face_reid_camera.ros.declare``), ``--help``, the generated ``config/<node>.yaml`` and the one
validator (:meth:`ParamSpec.check`). Core configuration dataclasses declare their fields with
:func:`param`, so a core's own parameters are declared once, where they are used: the node's table is
built from them (:func:`config_specs`) and the dataclass validates itself with the same specs
(:func:`validate_fields`).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

__all__ = [
    "ParamError",
    "ParamSpec",
    "ParamTable",
    "ParamValue",
    "YamlAliasError",
    "config_from_values",
    "config_specs",
    "load_yaml_without_aliases",
    "param",
    "validate_fields",
]

ParamValue = bool | int | float | str | list[float] | list[str]
_META_KEY = "face_reid_param"


class YamlAliasError(yaml.YAMLError):
    """A YAML file uses an alias (``*name``): refused, see :func:`load_yaml_without_aliases`."""


class _NoAliasLoader(yaml.SafeLoader):
    """YAML's safe loader refusing aliases (``*name``): a few hundred bytes of nested ones ("billion laughs")
    expand to gigabytes for whoever walks the result, and no params or network file needs them."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise YamlAliasError(f"line {event.start_mark.line + 1}: YAML aliases (*{event.anchor}) are not allowed "
                                 "(nested ones expand to gigabytes): write the value out")
        return super().compose_node(parent, index)


def load_yaml_without_aliases(stream: Any) -> Any:
    """``yaml.safe_load`` that refuses aliases (a yaml.YAMLError naming the line): for files people write."""
    return yaml.load(stream, Loader=_NoAliasLoader)


class ParamError(ValueError):
    """A parameter value that is of the wrong type, out of range or not one of the choices."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: ``name`` (dots = nested YAML), ``default`` (fixes the type), ``description`` with unit.

    ``low`` / ``high``: closed range of a number (or of every element of a number list); ``low_open`` /
    ``high_open`` make an end exclusive (the ROS descriptor range stays closed: the node's own check
    refuses the end). ``choices``: allowed strings. ``length``: required length of a number list
    (default: the default's length). ``read_only``: cannot be changed once the node started.
    """

    name: str
    default: ParamValue
    description: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()
    read_only: bool = False
    length: int | None = None

    def __post_init__(self) -> None:
        if not self.name or not self.description:
            raise ValueError(f"parameter {self.name!r} needs a name and a description")
        if self.choices and not isinstance(self.default, str):
            raise ValueError(f"parameter {self.name!r}: choices only apply to strings")
        if self.kind == "float_list" and self.length is None and isinstance(self.default, list) and self.default:
            object.__setattr__(self, "length", len(self.default))
        object.__setattr__(self, "default", self.check(self.default))

    @property
    def kind(self) -> str:
        """bool, int, float, str, float_list or str_list."""
        d = self.default
        if isinstance(d, bool):
            return "bool"
        if isinstance(d, int):
            return "int"
        if isinstance(d, float):
            return "float"
        if isinstance(d, str):
            return "str"
        if isinstance(d, list) and d and all(isinstance(v, str) for v in d):
            return "str_list"
        if isinstance(d, list) and d:
            return "float_list"
        raise ValueError(f"parameter {self.name!r}: unsupported default {d!r} (an empty list has no type)")

    def range_text(self) -> str:
        """'[0, 1]', '(0, inf]', 'one of: a, b' or '' (for --help and the YAML comments)."""
        if self.choices:
            return "one of: " + ", ".join(self.choices)
        if self.low is None and self.high is None:
            return ""
        lo = "-inf" if self.low is None else _num(self.low)
        hi = "inf" if self.high is None else _num(self.high)
        return f"{'(' if self.low_open else '['}{lo}, {hi}{')' if self.high_open else ']'}"

    def notes(self) -> str:
        """'range [0, 1]; read-only' (for --help and the YAML comments), or ''."""
        rng = self.range_text()
        rng = rng if not rng or self.choices else f"range {rng}"
        return "; ".join(t for t in (rng, "read-only" if self.read_only else "") if t)

    def type_text(self) -> str:
        if self.kind == "float_list":
            return f"list of {self.length} floats" if self.length else "list of floats"
        return {"bool": "true/false", "int": "integer", "float": "float", "str": "string",
                "str_list": "list of strings"}[self.kind]

    def check(self, value: Any) -> ParamValue:
        """The value, normalised (ints accepted for floats); ParamError naming the parameter otherwise."""
        kind = self.kind
        ok = True
        if kind == "bool":
            ok = isinstance(value, bool)
        elif kind == "int":
            ok = isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
            value = int(value) if ok else value
        elif kind == "float":
            ok = _is_number(value)
            value = float(value) if ok else value
        elif kind == "str":
            ok = isinstance(value, str)
        elif kind == "str_list":
            ok = isinstance(value, list | tuple) and all(isinstance(v, str) for v in value)
            value = [str(v) for v in value] if ok else value
        else:
            ok = isinstance(value, list | tuple) and all(_is_number(v) for v in value) and (
                self.length is None or len(value) == self.length)
            value = [float(v) for v in value] if ok else value
        if not ok:
            raise ParamError(f"parameter {self.name!r} must be a {self.type_text()} like "
                             f"{json.dumps(self.default)}, got {value!r}")
        if self.choices and value not in self.choices:
            raise ParamError(f"parameter {self.name!r} must be one of {', '.join(self.choices)}; got {value!r}")
        if kind in ("int", "float", "float_list") and (self.low is not None or self.high is not None):
            for v in value if isinstance(value, list) else [value]:
                if not self._in_range(float(v)):
                    raise ParamError(f"parameter {self.name!r} must be in {self.range_text()}, got {v!r}")
        return value

    def _in_range(self, v: float) -> bool:
        if math.isnan(v):
            return False
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            return False
        return not (self.high is not None and (v > self.high or (self.high_open and v == self.high)))


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool | np.bool_)


def _num(x: float) -> str:
    return "inf" if x == math.inf else "-inf" if x == -math.inf else f"{x:g}"


# ------------------------------------------------------------------------------------- dataclass fields
def param(
    default: ParamValue, description: str, *, low: float | None = None, high: float | None = None,
    low_open: bool = False, high_open: bool = False, choices: Sequence[str] = (), read_only: bool = False,
) -> Any:
    """A dataclass field that is also a parameter declaration (see :func:`config_specs`)."""
    meta = {"description": description, "low": low, "high": high, "low_open": low_open, "high_open": high_open,
            "choices": tuple(choices), "read_only": read_only}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata={_META_KEY: meta})
    return dataclasses.field(default=default, metadata={_META_KEY: meta})


def _field_spec(f: dataclasses.Field[Any], prefix: str) -> ParamSpec:
    meta = f.metadata[_META_KEY]
    default = f.default_factory() if f.default is dataclasses.MISSING else f.default  # type: ignore[misc]
    if isinstance(default, tuple):
        default = list(default)
    return ParamSpec(f"{prefix}{f.name}", default, **meta)


def config_specs(cls: type, prefix: str = "") -> list[ParamSpec]:
    """The parameters a config dataclass declares with :func:`param`, named ``prefix + field``."""
    return [_field_spec(f, prefix) for f in dataclasses.fields(cls) if _META_KEY in f.metadata]


def validate_fields(obj: Any) -> None:
    """Check every :func:`param` field of a config dataclass instance with its spec (call in __post_init__).

    Normalises in place (ints given for floats become floats, lists stay lists); ParamError names the field.
    """
    for f in dataclasses.fields(obj):
        if _META_KEY not in f.metadata:
            continue
        spec = _field_spec(f, "")
        value = getattr(obj, f.name)
        checked = spec.check(list(value) if isinstance(value, tuple) and spec.kind.endswith("list") else value)
        if isinstance(value, tuple):
            checked = tuple(checked)  # type: ignore[arg-type]
        object.__setattr__(obj, f.name, checked)


def config_from_values(cls: type, values: Mapping[str, Any], prefix: str = "", **extra: Any) -> Any:
    """Build a config dataclass from flat parameter values (its :func:`param` fields), plus ``extra``."""
    kwargs = {f.name: values[f"{prefix}{f.name}"] for f in dataclasses.fields(cls)
              if _META_KEY in f.metadata and f"{prefix}{f.name}" in values}
    return cls(**kwargs, **extra)


# ------------------------------------------------------------------------------------------- the table
class ParamTable:
    """The parameters of one node, in declaration order.

    ``deployment``: the names a site sets (the shipped YAML and ``--help`` show these; empty = all); the others
    are advanced: declared, validated and documented alike, at their defaults unless set.
    """

    def __init__(self, node_name: str, specs: Iterable[ParamSpec], title: str, usage: str,
                 deployment: Sequence[str] = ()) -> None:
        self.node_name = node_name
        self.specs = tuple(specs)
        self.title = title
        self.usage = usage
        names = [s.name for s in self.specs]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"duplicate parameter names in {node_name}: {sorted(dup)}")
        self._by_name = {s.name: s for s in self.specs}
        unknown = [n for n in deployment if n not in self._by_name]
        if unknown:
            raise ValueError(f"deployment parameters of {node_name} that are not declared: {unknown}")
        self._deployment = frozenset(deployment or names)

    def tier(self, name: str) -> str:
        """'deployment' (a site sets it) or 'advanced' (tuning and internals)."""
        return "deployment" if name in self._deployment else "advanced"

    @property
    def deployment_specs(self) -> tuple[ParamSpec, ...]:
        return tuple(s for s in self.specs if s.name in self._deployment)

    def __getitem__(self, name: str) -> ParamSpec:
        return self._by_name[name]

    def names(self) -> list[str]:
        return [s.name for s in self.specs]

    def defaults(self) -> dict[str, ParamValue]:
        """All parameters at their default values (lists copied)."""
        return {s.name: list(s.default) if isinstance(s.default, list) else s.default for s in self.specs}

    def check_value(self, name: str, value: Any) -> ParamValue:
        """Validate one value; ParamError for an unknown name (with the closest known ones)."""
        spec = self._by_name.get(name)
        if spec is None:
            raise ParamError(f"unknown {self.node_name} parameter {name!r}{self.suggest(name)}")
        return spec.check(value)

    def suggest(self, name: str) -> str:
        """' (did you mean ...?)' for a misspelt name, else ''."""
        close = difflib.get_close_matches(name, self.names(), n=2, cutoff=0.75)
        return f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""

    def check_all(self, values: Mapping[str, Any]) -> dict[str, ParamValue]:
        """Every parameter's value checked (missing ones at their default)."""
        out = self.defaults()
        for name, value in values.items():
            out[name] = self.check_value(name, value)
        return out

    def load_yaml(self, path: str | Path) -> dict[str, ParamValue]:
        """Read a ROS 2 params file over the defaults, by the node's rules (one loader:
        :func:`face_reid_camera.common.params_files.load_params_file`); ParamError naming every problem."""
        from face_reid_camera.common.params_files import load_params_file  # it builds on this module

        return load_params_file(self, path).values

    def write_yaml(self, path: str | Path) -> None:
        """Write the deployment parameters at their defaults under ``/**`` (applies whatever the node's name and
        namespace), each under a comment with its description and range."""
        advanced = len(self.specs) - len(self.deployment_specs)
        lines = [
            f"# Defaults of {self.title}.",
            "# Generated from the parameter declarations in the code (a test keeps them equal).",
            "# '/**' applies the file to the node whatever its name or namespace.",
            f"# Use: {self.usage}",
        ]
        if advanced:
            lines.append(f"# The {advanced} advanced parameters keep their defaults unless set here: "
                         "docs/parameters.md, or --help-all.")
        lines += ["/**:", "  ros__parameters:"]
        nested_open = ""
        for spec in self.deployment_specs:
            group, _, leaf = spec.name.rpartition(".")
            indent = "    "
            if group:
                if group != nested_open:
                    lines.append(f"    {group}:")
                    nested_open = group
                indent = "      "
            notes = spec.notes()
            lines.append(f"{indent}# {spec.description}" + (f" ({notes})" if notes else ""))
            lines.append(f"{indent}{leaf}: {json.dumps(spec.default)}")
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")

    def help_text(self, advanced: bool = False) -> str:
        """One line per deployment parameter (every parameter with ``advanced``), for --help / --help-all."""
        out = []
        for s in self.specs if advanced else self.deployment_specs:
            notes = s.notes()
            out.append(f"  {s.name} (default {json.dumps(s.default)}{'; ' + notes if notes else ''}): {s.description}")
        hidden = len(self.specs) - len(self.deployment_specs)
        if hidden and not advanced:
            out.append(f"  ... and {hidden} advanced parameters: --help-all, or docs/parameters.md")
        return "\n".join(out)

    def markdown(self) -> str:
        """This node's section of docs/parameters.md: every parameter with type, default, range, tier."""
        rows = [f"## {self.node_name}", "", f"{self.title[0].upper()}{self.title[1:]}. Use: `{self.usage}`", "",
                "| parameter | type | default | range | tier | description |", "|---|---|---|---|---|---|"]
        for s in sorted(self.specs, key=lambda s: (self.tier(s.name) != "deployment", self.specs.index(s))):
            rng = "; ".join(t for t in (s.range_text(), "read-only" if s.read_only else "") if t)
            default = json.dumps(s.default).replace("|", "\\|")
            rows.append(f"| `{s.name}` | {s.type_text()} | `{default}` | {rng.replace('|', '/')} | {self.tier(s.name)} "
                        f"| {s.description.replace('|', '/')} |")
        return "\n".join(rows) + "\n"

