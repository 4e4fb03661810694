"""Params files and ``-p`` settings read and checked by the rules a node's start applies: the one loader of the
nodes' start-up check, ``face-reid-replay --params`` and ``face-reid-up --dry-run``.

The rules are rcl's and rclpy's, so that what one reader accepts the node accepts: a file that is missing or not
YAML is refused; a value must have the parameter's ROS type as rcl reads the YAML (``60`` is an integer, which a
float parameter refuses; a list mixing ``0`` and ``1.5`` is refused by rcl itself: "Sequence should be of same
type"); then the declared range or choices (:meth:`ParamSpec.check`). A name the node does not declare is a
warning (the node ignores it), not a refusal. Every problem is one line naming its file or ``-p`` setting.
Pure Python (yaml), no rclpy.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from face_reid_camera.common.param_table import (
    ParamError,
    ParamSpec,
    ParamTable,
    ParamValue,
    YamlAliasError,
    load_yaml_without_aliases,
)

__all__ = ["ParamsCheck", "check_ros_args", "check_ros_value", "check_sources", "flatten_params", "load_params_file",
           "read_yaml_file", "yaml_error_line"]

_VALUE_OPTIONS = {"-p", "--param", "--params-file", "-r", "--remap", "-e", "--enclave", "--log-level",
                  "--log-file-name", "--log-config-file"}


@dataclass
class ParamsCheck:
    """What a node would start with: ``values`` (over the defaults), ``problems`` (each refuses the start, one line)
    and ``warnings`` (names the node ignores)."""

    values: dict[str, ParamValue]
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    namespace: str = ""


def yaml_error_line(exc: yaml.YAMLError) -> str:
    """A YAML error in one line: 'line 4, column 1: expected ',' or ']', but got '<stream end>''."""
    if isinstance(exc, YamlAliasError):
        return str(exc)
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return f"{where}{problem}"


def read_yaml_file(path: str | Path, what: str) -> Any:
    """The YAML document of ``what`` at ``path`` (aliases refused); ParamError in one line naming the file when it
    is missing, a folder, unreadable or not YAML."""
    src = Path(path)
    try:
        text = src.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ParamError(f"{what} {src}: no such file") from None
    except IsADirectoryError:
        raise ParamError(f"{what} {src}: is a folder, not a file") from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ParamError(f"{what} {src}: cannot read it ({reason})") from None
    try:
        return load_yaml_without_aliases(text)
    except yaml.YAMLError as exc:
        raise ParamError(f"{what} {src}: not YAML: {yaml_error_line(exc)}") from None


def flatten_params(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested ``ros__parameters`` as flat names (``person: {max_depth_m: 5.0}`` -> ``person.max_depth_m``)."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten_params(value, name + "."))
        else:
            out[name] = value
    return out


def _section_keys(node_name: str, namespace: str) -> tuple[str, ...]:
    """The sections of a params file rcl applies to the node ``namespace/node_name``."""
    fqn = f"{namespace.rstrip('/')}/{node_name}" if namespace else f"/{node_name}"
    return ("/**", "/**/" + node_name, node_name, f"/{node_name}", fqn, fqn.lstrip("/"))


def _file_values(path: str | Path, node_name: str, namespace: str) -> dict[str, Any]:
    """The flat values a params file gives the node (ParamError, one line, on a file rcl refuses)."""
    doc = read_yaml_file(path, "params file")
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise ParamError(f"params file {path}: a mapping of node names to sections (e.g. '/**:'), got a "
                         f"{type(doc).__name__}")
    raw: dict[str, Any] = {}
    for key in dict.fromkeys(_section_keys(node_name, namespace)):
        if key not in doc:
            continue
        params = doc[key].get("ros__parameters") if isinstance(doc[key], dict) else None
        if not isinstance(params, dict):
            raise ParamError(f"params file {path}: '{key}' needs a 'ros__parameters' mapping")
        raw.update(flatten_params(params))
    return raw


def _scalar_kind(value: Any) -> str:
    if isinstance(value, bool):
        return "booleans"
    if isinstance(value, int):
        return "integers"
    if isinstance(value, float):
        return "floats"
    if isinstance(value, str):
        return "strings"
    return type(value).__name__


def check_ros_value(spec: ParamSpec, value: Any) -> ParamValue:
    """``value`` as the node takes it (see the module docstring); ParamError naming the parameter otherwise."""
    if isinstance(value, list):
        kinds = list(dict.fromkeys(_scalar_kind(v) for v in value))
        if len(kinds) > 1:
            hint = "; write every number with a decimal point, e.g. 1.0" if set(kinds) == {"integers", "floats"} else ""
            raise ParamError(f"parameter {spec.name!r}: a list mixing {' and '.join(kinds)} ({json.dumps(value)}) is "
                             f"refused by ROS (Sequence should be of same type){hint}")
    ints = _scalar_kind(value) == "integers" or (
        isinstance(value, list) and bool(value) and all(_scalar_kind(v) == "integers" for v in value))
    if spec.kind in ("float", "float_list") and ints:
        raise ParamError(f"parameter {spec.name!r} must be a {spec.type_text()} like {json.dumps(spec.default)}, "
                         f"got {json.dumps(value)} (write numbers with a decimal point, e.g. 2.0)")
    return spec.check(value)


def _check_one(table: ParamTable, check: ParamsCheck, name: str, value: Any, where: str) -> None:
    if name not in table.names():
        check.warnings.append(f"{where}: {name!r} is not a parameter of {table.node_name}: ignored"
                              f"{table.suggest(name)}")
        return
    try:
        check.values[name] = check_ros_value(table[name], value)
    except ParamError as exc:
        check.problems.append(f"{where}: {exc}")


def check_sources(table: ParamTable, files: Sequence[str | Path] = (), settings: Sequence[str] = (),
                  namespace: str = "", node_name: str = "") -> ParamsCheck:
    """The node's values from params ``files`` (in order) then ``settings`` (``name:=value``, as ``-p``: these
    win), every problem and warning collected (one line each)."""
    node = node_name or table.node_name
    check = ParamsCheck(table.defaults(), namespace=namespace)
    for path in files:
        try:
            raw = _file_values(path, node, namespace)
        except ParamError as exc:
            check.problems.append(str(exc))
            continue
        for name, value in raw.items():
            _check_one(table, check, name, value, f"params file {path}")
    for setting in settings:
        name, sep, text = setting.partition(":=")
        if ":" in name:  # -p node_name:param:=value applies to that node only
            target, _, name = name.rpartition(":")
            if target != node:
                continue
        where = f"-p {setting}"
        if not sep or not name:
            check.problems.append(f"{where}: not name:=value")
            continue
        try:
            value = yaml.safe_load(text) if text else None
        except yaml.YAMLError as exc:
            check.problems.append(f"{where}: not a YAML value: {yaml_error_line(exc)}")
            continue
        if value is None:
            check.problems.append(f"bad --ros-args: {where} has no value; an empty string value is written name:=''")
            continue
        _check_one(table, check, name, value, where)
    return check


def check_ros_args(table: ParamTable, args: Sequence[str]) -> ParamsCheck:
    """:func:`check_sources` for a node's command line: its ``--params-file`` and ``-p`` / ``--param`` settings
    (and ``__ns`` / ``__node`` remaps, which choose the sections of a params file that apply)."""
    files: list[str] = []
    settings: list[str] = []
    namespace, node = "", table.node_name
    in_ros, k = False, 0
    while k < len(args):
        arg = args[k]
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        elif in_ros and arg in _VALUE_OPTIONS and k + 1 < len(args):
            value = args[k + 1]
            if arg == "--params-file":
                files.append(value)
            elif arg in ("-p", "--param"):
                settings.append(value)
            elif arg in ("-r", "--remap") and value.startswith("__ns:="):
                namespace = value.removeprefix("__ns:=")
            elif arg in ("-r", "--remap") and value.startswith("__node:="):
                node = value.removeprefix("__node:=")
            k += 1
        k += 1
    return check_sources(table, files, settings, namespace, node)


def load_params_file(table: ParamTable, path: str | Path) -> ParamsCheck:
    """One params file over the defaults (replay, tools): ParamError with every problem when the node would refuse
    it; the warnings (names the node ignores) are the caller's to show."""
    check = check_sources(table, [path])
    if check.problems:
        raise ParamError("; ".join(check.problems))
    return check
