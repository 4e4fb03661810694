"""The files generated from the parameter declarations (config/<node>.yaml, docs/parameters.md) equal what the code
declares, and each node ships at most 25 deployment parameters."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from face_reid_camera.common.param_table import ParamSpec, ParamTable
from face_reid_master.tools.parameter_docs import PAGE, tables, write_all

REPO = Path(__file__).resolve().parents[1]
REGENERATE = "regenerate with: python -m face_reid_master.tools.parameter_docs"


def _generated(tmp_path: Path) -> list[Path]:
    (tmp_path / "config").mkdir()
    (tmp_path / "docs").mkdir()
    return write_all(tmp_path)


def test_the_generated_files_equal_the_declarations(tmp_path: Path) -> None:
    for path in _generated(tmp_path):
        shipped = REPO / path.relative_to(tmp_path)
        assert path.read_text() == shipped.read_text(), f"{shipped.relative_to(REPO)} is stale: {REGENERATE}"


def test_a_changed_declaration_makes_the_page_stale(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The sync check above would fail if a default changed without regenerating: shown on the page itself."""
    import face_reid_master.tools.parameter_docs as docs

    real = docs.tables()
    table = real["master"]
    changed = [dataclasses.replace(s, default=0.9) if s.name == "posterior_threshold" else s for s in table.specs]
    real["master"] = ParamTable(table.node_name, changed, table.title, table.usage,
                                deployment=[s.name for s in table.deployment_specs])
    monkeypatch.setattr(docs, "tables", lambda: real)
    page = _generated(tmp_path)[-1]
    assert page.read_text() != (REPO / PAGE).read_text()
    assert "| `posterior_threshold` | float | `0.9` |" in page.read_text()


def test_each_node_ships_at_most_25_deployment_parameters() -> None:
    for stem, table in tables().items():
        assert len(table.deployment_specs) <= 25, stem
        shipped = (REPO / "config" / f"{stem}.yaml").read_text()
        assert table.load_yaml(REPO / "config" / f"{stem}.yaml") == table.defaults()
        for spec in table.specs:
            listed = f"{spec.name.rpartition('.')[2]}:" in shipped
            assert listed == (table.tier(spec.name) == "deployment") or "." in spec.name, spec.name


def test_an_undeclared_deployment_parameter_is_refused() -> None:
    with pytest.raises(ValueError, match="not declared: \\['nope'\\]"):
        ParamTable("n", [ParamSpec("a", 1, "An a (count).")], "a node", "n", deployment=["nope"])
