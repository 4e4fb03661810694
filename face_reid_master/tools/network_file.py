"""The network file of ``face-reid-up``: which nodes run on which host, with their params, and the commands.

    domain_id: 7                      # optional: ROS_DOMAIN_ID of every node (default: the environment's)
    network_key: ~/.config/face_reid/network.key   # optional: network_key_path of every node (secured; a
                                                   # node's own network_key_path in `set` is then an error)
    hosts:
      pc-kitchen:                     # a host name (or any name given to face-reid-up --host)
        cameras:
          - id: cam_kitchen           # camera_id; the node runs in namespace /cam_kitchen unless `namespace`
            params: [config/camera.yaml, poses/cam_kitchen.yaml]   # --params-file, in this order
            set: {embedder: sface}    # -p name:=value (after the files: these win)
            remap: {color/image_raw: /camera/color/image_raw}      # -r from:=to
      pc-master:
        master:
          params: [config/master.yaml]
          set: {admin_services: true}

Relative paths are relative to the network file's folder. YAML aliases (``*name``) are refused (a few bytes of
nested ones expand to gigabytes). Pure Python (yaml), no rclpy.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from face_reid_camera.common.param_table import YamlAliasError, load_yaml_without_aliases
from face_reid_camera.common.params_files import yaml_error_line

__all__ = ["NodeSpec", "load_network_file", "network_key_path", "node_specs"]

_NAMESPACE = re.compile(r"^(/[A-Za-z][A-Za-z0-9_]*)+$")
_CAMERA_KEYS = {"id", "namespace", "params", "set", "remap"}
_MASTER_KEYS = {"params", "set", "remap", "namespace"}


@dataclass(frozen=True)
class NodeSpec:
    """One node process: its name (for logs), ``python`` arguments and extra environment."""

    name: str
    args: tuple[str, ...]
    env: tuple[tuple[str, str], ...] = ()


def load_network_file(path: str | Path) -> dict[str, Any]:
    """The network file, checked (ValueError naming the place of the first problem)."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ValueError(f"network file {path} not found") from None
    except OSError as exc:
        raise ValueError(f"network file {path}: cannot read it ({exc.strerror})") from None
    try:
        data = load_yaml_without_aliases(text)  # a few bytes of nested aliases would expand to gigabytes
    except YamlAliasError as exc:
        raise ValueError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not YAML: {yaml_error_line(exc)}") from None
    if not isinstance(data, dict) or not isinstance(data.get("hosts"), dict) or not data["hosts"]:
        raise ValueError(f"{path}: needs a 'hosts' mapping (host name -> its cameras and/or master)")
    unknown = set(data) - {"hosts", "domain_id", "network_key"}
    if unknown:
        raise ValueError(f"{path}: unknown top-level keys {sorted(unknown)} (hosts, domain_id, network_key)")
    if "domain_id" in data and not (isinstance(data["domain_id"], int) and 0 <= data["domain_id"] <= 232):
        raise ValueError(f"{path}: domain_id must be an integer in 0..232, got {data['domain_id']!r}")
    seen_ids: set[str] = set()
    masters = 0
    for host, nodes in data["hosts"].items():
        where = f"{path}: hosts.{host}"
        if not isinstance(nodes, dict) or not set(nodes) <= {"cameras", "master"} or not nodes:
            raise ValueError(f"{where}: give 'cameras' (a list) and/or 'master'")
        for k, cam in enumerate(nodes.get("cameras") or []):
            _check_node(cam, f"{where}.cameras[{k}]", _CAMERA_KEYS)
            cid = cam.get("id")
            if not isinstance(cid, str) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", cid):
                raise ValueError(f"{where}.cameras[{k}].id: a camera id of letters, digits and _, got {cid!r}")
            if cid in seen_ids:
                raise ValueError(f"{where}.cameras[{k}].id: camera {cid!r} appears twice in the network")
            seen_ids.add(cid)
        if "master" in nodes:
            _check_node(nodes["master"] or {}, f"{where}.master", _MASTER_KEYS)
            masters += 1
    if masters > 1:
        raise ValueError(f"{path}: {masters} masters; a network has one")
    if data.get("network_key"):
        _check_no_own_key(data["hosts"], str(path))
    data["_folder"] = str(path.resolve().parent)
    return data


def _check_no_own_key(hosts: Mapping[str, Any], path: str) -> None:
    """A secured network gives every node its key: a node's own ``network_key_path`` in ``set`` would be overridden
    silently (and an empty one would mean an unsecured node in a secured network): ValueError naming the node."""
    for host, nodes in hosts.items():
        named = [(f"camera {c['id']} (hosts.{host}.cameras[{k}])", c) for k, c in enumerate(nodes.get("cameras") or [])]
        if "master" in nodes:
            named.append((f"the master (hosts.{host}.master)", nodes["master"] or {}))
        for who, node in named:
            if "network_key_path" not in (node.get("set") or {}):
                continue
            if not node["set"]["network_key_path"]:
                raise ValueError(f"{path}: {who}: set network_key_path is empty, but the network is secured "
                                 "(network_key): a secured network cannot have an unsecured node; remove it")
            raise ValueError(f"{path}: {who}: set network_key_path, but network_key gives every node the network's "
                             "key (one key per network); remove it")


def _check_node(node: Any, where: str, keys: set[str]) -> None:
    if not isinstance(node, dict):
        raise ValueError(f"{where}: a mapping, got {type(node).__name__}")
    unknown = set(node) - keys
    if unknown:
        raise ValueError(f"{where}: unknown keys {sorted(unknown)} (allowed: {sorted(keys)})")
    if not isinstance(node.get("params", []), list):
        raise ValueError(f"{where}.params: a list of params files")
    for key in ("set", "remap"):
        if not isinstance(node.get(key, {}), dict):
            raise ValueError(f"{where}.{key}: a mapping")
    ns = node.get("namespace")
    if ns is not None and not (isinstance(ns, str) and _NAMESPACE.fullmatch(ns)):
        raise ValueError(f"{where}.namespace: like /kitchen or /site/cam1, got {ns!r}")


def _value(v: Any) -> str:
    """A YAML value as ROS's -p name:=value reads it."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, str):
        return v if v else "''"
    return repr(v)


def _path(folder: str, p: Any) -> str:
    return str(Path(folder, os.path.expanduser(str(p))).resolve())


def _ros_args(node: Mapping[str, Any], folder: str, extra: list[str]) -> list[str]:
    args: list[str] = []
    if node.get("namespace"):
        args += ["-r", f"__ns:={node['namespace']}"]
    for f in node.get("params") or []:
        args += ["--params-file", _path(folder, f)]
    for name, value in (node.get("set") or {}).items():
        args += ["-p", f"{name}:={_value(value)}"]
    args += extra
    for src, dst in (node.get("remap") or {}).items():
        args += ["-r", f"{src}:={dst}"]
    return args


def network_key_path(network: Mapping[str, Any]) -> str:
    """The file every node of a secured network gets as network_key_path ('' for an unsecured network)."""
    key = network.get("network_key")
    return _path(str(network["_folder"]), key) if key else ""


def node_specs(network: Mapping[str, Any], host: str, roles: tuple[str, ...] = ("camera", "master")) -> list[NodeSpec]:
    """The node processes of ``host`` (only the given roles), in start order: the master first."""
    if host not in network["hosts"]:
        raise ValueError(f"host {host!r} is not in the network file (hosts: {list(network['hosts'])}); "
                         "give --host NAME")
    folder = str(network["_folder"])
    nodes = network["hosts"][host]
    key_file = network_key_path(network)
    key = ["-p", f"network_key_path:={key_file}"] if key_file else []
    env = (("ROS_DOMAIN_ID", str(network["domain_id"])),) if "domain_id" in network else ()
    out = []
    if "master" in nodes and "master" in roles:
        out.append(NodeSpec("master", ("-m", "face_reid_master.ros.node", "--ros-args",
                                       *_ros_args(nodes["master"] or {}, folder, key)), env))
    for cam in (nodes.get("cameras") or []) if "camera" in roles else []:
        cam = {"namespace": f"/{cam['id']}", **cam}
        extra = ["-p", f"camera_id:={cam['id']}", *key]
        out.append(NodeSpec(f"camera {cam['id']}", ("-m", "face_reid_camera.ros.node", "--ros-args",
                                                     *_ros_args({k: v for k, v in cam.items() if k != "id"},
                                                                folder, extra)), env))
    return out
