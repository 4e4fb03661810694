"""README.md and docs/*.md: every relative link and anchor resolves, and every code block marked runnable
(info string ``bash runnable``: commands that need no camera) runs as written from the repository root."""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
_FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```", re.S | re.M)
_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$", re.M)
_EXPLICIT = re.compile(r"<a\s+(?:id|name)=\"([^\"]+)\"")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation other than '-' and '_' dropped, spaces -> '-'."""
    text = re.sub(r"[`*]", "", heading).strip().lower()
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _prose(text: str) -> str:
    return _FENCE.sub("", text)


def anchors(path: Path) -> set[str]:
    text = _prose(path.read_text(encoding="utf-8"))
    seen: dict[str, int] = {}
    out = set(_EXPLICIT.findall(text))
    for heading in _HEADING.findall(text):
        base = slug(heading)
        n = seen.get(base, 0)
        out.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1
    return out


def broken_links(page: Path, root: Path = REPO) -> list[str]:
    found = []
    for match in _LINK.finditer(_prose(page.read_text(encoding="utf-8"))):
        target = match.group(1) or match.group(2)
        if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        dest = (page.parent / path_part).resolve() if path_part else page
        if not dest.exists():
            found.append(f"{page.relative_to(root)}: {target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            found.append(f"{page.relative_to(root)}: {target} (no such anchor)")
    return found


def test_the_link_checker_finds_a_broken_file_and_anchor(tmp_path: Path) -> None:
    (tmp_path / "a.md").write_text("# Two words: `code`\n\n[ok](#two-words-code) [bad](#nope) [gone](b.md)\n")
    page = tmp_path / "a.md"
    assert anchors(page) == {"two-words-code"}
    assert broken_links(page, tmp_path) == ["a.md: #nope (no such anchor)", "a.md: b.md (no such file)"]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(page: Path) -> None:
    assert broken_links(page) == []


def _runnable_blocks() -> list[tuple[str, str]]:
    blocks = []
    for page in PAGES:
        for info, body in _FENCE.findall(page.read_text(encoding="utf-8")):
            if info.split()[1:2] == ["runnable"]:
                blocks.append((f"{page.relative_to(REPO)}:{len(blocks)}", body))
    return blocks


def test_there_are_runnable_commands_in_the_readme() -> None:
    assert any(name.startswith("README.md") for name, _ in _runnable_blocks())


@pytest.mark.slow  # runs the tools (~20 s for all the pages' commands)
@pytest.mark.parametrize(("name", "script"), _runnable_blocks(), ids=[n for n, _ in _runnable_blocks()])
def test_every_runnable_command_works(name: str, script: str, tmp_path: Path) -> None:
    if not (REPO / ".venv" / "bin" / "python").exists():
        pytest.skip("the commands use .venv/bin: run scripts/setup.sh first")
    env = {**os.environ, "HOME": str(tmp_path), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    run = subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=REPO, env=env, capture_output=True,
                         text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert run.returncode == 0, f"{name} failed:\n{script}\n{run.stdout[-2000:]}\n{run.stderr[-2000:]}"


_EXAMPLE_COMMAND = re.compile(r"^(\.venv/bin/python examples/(\w+)\.py\b[^#\n]*?)\s*(?:#.*)?$", re.M)
_KEY_ARGUMENT = " ~/.config/face_reid/network.key"
_DEMO_GALLERY = ("Colin Powell", "Ariel Sharon")  # the demo's predefined people (docs/demo.md)


def _check_commands() -> dict[str, str]:
    """Every command of README and docs that runs an example on a live network (README step 7, the deployment
    check step, the diagnostics section, robots.md): command -> where it is written."""
    found: dict[str, str] = {}
    for page in PAGES:
        for _, body in _FENCE.findall(page.read_text(encoding="utf-8")):
            for match in _EXAMPLE_COMMAND.finditer(body):
                found.setdefault(match.group(1), str(page.relative_to(REPO)))
    return found


def test_the_step_7_checks_are_found() -> None:
    commands = _check_commands()
    readme = [c for c, page in commands.items() if page == "README.md"]
    assert any("examples/diagnostics.py" in c for c in readme) and any("examples/who_is_where.py 0" in c
                                                                        for c in readme), commands


@pytest.mark.slow  # a demo of about a minute
@pytest.mark.ros
def test_the_step_7_checks_work_as_written_on_a_running_demo(ros_domain_id: int, tmp_path: Path) -> None:
    """README step 7's checks (and the same commands elsewhere in the docs), each as written, on a live demo:
    diagnostics.py shows the master, who_is_where.py prints a named track and ends on Ctrl-C with status 0. The
    demo has no network key: the key file argument of who_is_where is left out (reading sealed tracks with a key
    is the subscription's own test)."""
    import select
    import signal
    import time

    if not (REPO / ".venv" / "bin" / "python").exists():
        pytest.skip("the commands use .venv/bin: run scripts/setup.sh first")
    env = {**os.environ, "HOME": str(tmp_path), "ROS_DOMAIN_ID": str(ros_domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    demo_log = tmp_path / "demo.log"
    with open(demo_log, "w") as log:
        demo = subprocess.Popen([str(REPO / ".venv" / "bin" / "face-reid-demo"), "--domain-id", str(ros_domain_id),
                                 "--cameras", "1", "--people", "2", "--gallery-people", "2", "--duration-s", "120"],
                                cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)

    def lines(proc: subprocess.Popen[str], until: float) -> Iterator[str]:
        """``proc``'s output lines as they come, until it ends or ``until`` (time.monotonic) passes."""
        assert proc.stdout is not None
        while time.monotonic() < until:
            if select.select([proc.stdout], [], [], 0.5)[0]:
                line = proc.stdout.readline()
                if not line:
                    return
                yield line

    def run(command: str, named_track: bool) -> str:
        proc = subprocess.Popen(["bash", "-c", command], cwd=REPO, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
        out: list[str] = []
        try:
            for line in lines(proc, time.monotonic() + 150.0):  # a barrier: until a named track is printed
                out.append(line)
                if named_track and re.search(rf"track \d+: ({'|'.join(_DEMO_GALLERY)}) at ", line):
                    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C
            rest, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
        assert proc.returncode == 0 and "Traceback" not in err, (command, proc.returncode, "".join(out), err)
        return "".join(out) + rest

    try:
        # a barrier: the demo says when every process is up and the scene plays
        deadline = time.monotonic() + 240.0
        while "playing the scenario" not in demo_log.read_text() and demo.poll() is None:
            assert time.monotonic() < deadline, demo_log.read_text()
            time.sleep(0.5)
        assert demo.poll() is None, demo_log.read_text()
        for command, page in _check_commands().items():
            assert command.endswith(_KEY_ARGUMENT) or _KEY_ARGUMENT not in command, (page, command)
            as_run = command.removesuffix(_KEY_ARGUMENT)
            if "examples/diagnostics.py" in command:
                out = run(as_run, named_track=False)
                assert re.search(r"^(OK|WARN|ERROR) face_reid_master \| ", out, re.M), (page, command, out)
            elif "examples/who_is_where.py 0" in command:
                out = run(as_run, named_track=True)
                assert re.search(rf"track \d+: ({'|'.join(_DEMO_GALLERY)}) at ", out), (page, command, out)
            else:  # a count of updates: ends by itself
                assert " people in 'world':" in run(as_run, named_track=False), (page, command)
    finally:
        os.killpg(demo.pid, signal.SIGINT)
        try:
            demo.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(demo.pid, signal.SIGKILL)


def _recipe() -> str:
    text = (REPO / "docs" / "tuning.md").read_text(encoding="utf-8")
    return text.split("## Tuning a site, step by step", 1)[1].split("\n## ", 1)[0]


def test_the_tuning_recipe_names_real_parameters_and_diagnostics_values() -> None:
    """The parameters the recipe says to touch first are declared ones (docs/parameters.md), and every value it
    says to read on /diagnostics is one a node publishes (its name in the nodes' code)."""
    recipe = _recipe()
    declared = set(re.findall(r"^\| `([^`]+)` \|", (REPO / "docs" / "parameters.md").read_text(), re.M))
    first = re.findall(r"^- \*\*`([^`]+)`\*\*", recipe, re.M)
    assert len(first) >= 3 and set(first) <= declared, set(first) - declared
    code = "\n".join(p.read_text(encoding="utf-8") for package in ("face_reid_camera", "face_reid_master")
                     for p in (REPO / package).rglob("*.py"))
    table = [line for line in recipe.splitlines() if line.startswith("| ") and ": `" in line.split("|")[1]]
    values = {v for line in table for v in re.findall(r"`([a-z_]+)(?:_\*)?`", line.split("|")[1])}
    assert len(values) >= 15, values
    # published values are dict keys ("name": ...), counters (name: int = 0) or built from a prefix (rejected_*)
    def published(name: str) -> bool:
        return bool(re.search(rf"[\"'{{]{name}[\"'_]|\b{name}: int\b", code))

    missing = [v for v in values if not published(v) and not published(v.removeprefix("rejected_"))]
    assert not missing, missing
