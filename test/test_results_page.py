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
        switched = t2.get("failure_after_switch")
        assert switched is None or f" % | {switched} | " in row
        carried = doc["result"]["per_detection"].get("wrong_identity_carried_rate")
        assert carried is None or f" ({100 * carried:.1f} % carried) |" in row
        assert ("| yes |" in row) == bool(doc["result"]["protocol"]["honest"])
        gap = doc["simulation"].get("day_gap_s")
        if doc["simulation"].get("second_day") and gap:
            assert f"2 days {gap / 3600:g} h apart" in row  # the gap between the days is shown


def test_every_development_sweep_is_on_the_page_with_its_sums() -> None:
    page = (REPO / "docs" / "results.md").read_text(encoding="utf-8")
    for path in sorted((REPO / "bench" / "results").glob("choices_*.json")):
        doc = json.loads(path.read_text(encoding="utf-8"))
        assert f"### {doc['name']}\n" in page and doc["command"] in page
        section = page.split(f"### {doc['name']}\n", 1)[1].split("\n### ", 1)[0]  # labels repeat across sweeps
        for v in doc["variants"]:
            row = next(line for line in section.splitlines() if line.startswith(f"| {v['label']} |"))
            assert f"| {v['right']} / {v['wrong']} |" in row and f"| {v['body_right']} / {v['body_wrong']} |" in row


def test_a_sweep_variant_is_label_colon_settings() -> None:
    sys.path.insert(0, str(REPO / "bench"))
    try:
        from dev_sweep import master_config, parse_variant
    finally:
        sys.path.remove(str(REPO / "bench"))
    assert parse_variant("base:") == ("base", {})
    _, tracker_too = parse_variant("t:tracker.stray_log_odds=-3.5,learn_confidence=0.9")
    cfg = master_config(tracker_too)
    assert cfg.tracker.stray_log_odds == -3.5 and cfg.learn_confidence == 0.9
    assert parse_variant("b:body_max_log_ratio=0.25,body_identity=false,method=bayes") == (
        "b", {"body_max_log_ratio": 0.25, "body_identity": False, "method": "bayes"})
    for bad in ("nolabel", ":a=1", "x:a"):
        try:
            parse_variant(bad)
        except ValueError as exc:
            assert "LABEL" in str(exc) or "param=value" in str(exc)
        else:
            raise AssertionError(f"{bad!r} was accepted")
