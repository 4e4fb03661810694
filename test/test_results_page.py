"""docs/results.md is what bench/results_page.py makes of the recorded result files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_the_results_page_is_generated_from_the_result_files() -> None:
    run = subprocess.run([sys.executable, str(REPO / "bench" / "results_page.py"), "--check"], cwd=REPO,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    page = (REPO / "docs" / "results.md").read_text(encoding="utf-8")
    files = sorted((REPO / "bench" / "results").glob("eval_*.json"))
    assert files, "no recorded evaluation results"
    for path in files:
        doc = json.loads(path.read_text(encoding="utf-8"))
        t2 = doc["result"]["table_ii"]
        row = next(line for line in page.splitlines() if line.startswith(f"| {doc['name']} |"))
        assert f"| {t2['success']} / {t2['failure']} |" in row
        assert ("| yes |" in row) == bool(doc["result"]["protocol"]["honest"])
