"""Write the files generated from the parameter declarations: ``config/<node>.yaml`` (the deployment parameters of
each node at their defaults) and ``docs/parameters.md`` (every parameter). A test keeps them equal to the code.

Usage (from the repository root): ``python -m face_reid_master.tools.parameter_docs``
"""

from __future__ import annotations

import sys
from pathlib import Path

from face_reid_camera.common.param_table import ParamTable

REPO = Path(__file__).resolve().parents[2]
PAGE = Path("docs/parameters.md")


def tables() -> dict[str, ParamTable]:
    """config file stem -> the node's parameter table (imports the nodes' modules: needs rclpy)."""
    from face_reid_camera.ros import params as camera
    from face_reid_master.ros import goto_node, map_node
    from face_reid_master.ros import params as master

    return {"camera": camera.TABLE, "master": master.TABLE, "goto": goto_node.TABLE, "map": map_node.TABLE}


def parameters_page(node_tables: dict[str, ParamTable]) -> str:
    """docs/parameters.md: a section per node, deployment parameters first."""
    head = ["# Parameters", "",
            "Generated from the parameter declarations in the code by "
            "`python -m face_reid_master.tools.parameter_docs`; a test keeps it equal to them.", "",
            "Each node's shipped `config/<node>.yaml` and `--help` list its *deployment* parameters, the ones a "
            "site sets. The *advanced* ones (tuning, detector internals, limits against hostile input) keep their "
            "defaults unless set in a params file or with `-p name:=value`; `--help-all` lists them too. Why the "
            "defaults are what they are: [tuning](tuning.md).", ""]
    counts = [f"- [{t.node_name}](#{t.node_name}): {len(t.deployment_specs)} deployment, "
              f"{len(t.specs) - len(t.deployment_specs)} advanced" for t in node_tables.values()]
    return "\n".join([*head, *counts, ""]) + "\n" + "\n".join(t.markdown() for t in node_tables.values())


def write_all(root: Path = REPO) -> list[Path]:
    """Regenerate every file under ``root``; returns the paths written."""
    node_tables = tables()
    written = []
    for stem, table in node_tables.items():
        path = root / "config" / f"{stem}.yaml"
        table.write_yaml(path)
        written.append(path)
    (root / PAGE).write_text(parameters_page(node_tables), encoding="utf-8")
    return [*written, root / PAGE]


def main(argv: list[str] | None = None) -> int:
    import argparse

    argparse.ArgumentParser(prog="python -m face_reid_master.tools.parameter_docs",
                            description="Regenerate config/<node>.yaml and docs/parameters.md from the parameter "
                                        "declarations.").parse_args(argv)
    for path in write_all():
        print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
