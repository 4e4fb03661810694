"""README.md and docs/*.md: every relative link and anchor resolves, and every code block marked runnable
(info string ``bash runnable``: commands that need no camera) runs as written from the repository root."""

from __future__ import annotations

import os
import re
import subprocess
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
