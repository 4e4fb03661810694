"""Record one face-reid-eval result as a result file: bench/results/eval_NAME.json.

    python bench/record_eval.py NAME SCENARIO_DIR [face-reid-eval options ...]

Runs the evaluation (offline, without IDF1 / MOTA) and writes its metrics with what produced them: the
evaluation command, the scenario's simulator settings (``oracle``: a scenario of oracle evidence,
``face-reid-sim --oracle-evidence``), the commit, the date and the machine.
``bench/results_page.py`` turns these files into docs/results.md. An evaluation face-reid-eval refuses
(a loaded model saw the scenario's people) is not recorded unless ``--allow-fitted`` is passed; the page
then marks it as not a test.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

from face_reid_master.evaluation.cli import main as eval_main

RESULTS = Path(__file__).resolve().parent / "results"
_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
# the JSON blocks kept (the rest: per-track detail, plots, timings of this machine's run)
_KEPT = ("scenario", "protocol", "confidence_map", "method", "table_ii", "reidentification", "first_appearance",
         "pure_tracks", "predefined_people", "per_detection", "calibration", "body_metric", "oracle")


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10,
                             cwd=Path(__file__).resolve().parent, check=True)
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"


def provenance() -> dict[str, str]:
    """What produced a result file: the commit, the date (UTC) and the machine."""
    return {"commit": _commit(), "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d"),
            "machine": _machine()}


def shown(option: str) -> str:
    """Paths inside the project are shown relative to it (the command reads the same on every machine)."""
    root = RESULTS.parent.parent
    path = Path(option)
    if path.is_absolute() and path.is_relative_to(root):
        return str(path.relative_to(root))
    return option


def record(name: str, scenario: Path, options: list[str]) -> dict[str, Any]:
    """Evaluate ``scenario`` with ``options`` and return the result document (raises SystemExit on refusal)."""
    argv = [str(scenario), *options, "--no-mot", "--quiet"]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        status = eval_main(argv)
    if status != 0:
        raise SystemExit(f"record_eval: face-reid-eval {' '.join(argv)} exited with status {status}")
    result = json.loads(buf.getvalue())
    doc = json.loads((scenario / "scenario.json").read_text(encoding="utf-8"))
    params = doc.get("parameters", {})
    return {
        "name": name,
        "command": "face-reid-eval " + " ".join([scenario.name, *map(shown, options), "--no-mot"]),
        "simulation": {"faces_dir": doc.get("faces_dir"), "bodies_dir": doc.get("bodies_dir"),
                       "seed": doc.get("seed"), "level": doc.get("level"), "people": params.get("num_people"),
                       "cameras": params.get("num_cameras"), "duration_s": params.get("duration_s"),
                       "second_day": params.get("second_day"), "color_resolution": params.get("color_resolution"),
                       **({"day_gap_s": params.get("day_gap_s")} if params.get("second_day") else {}),
                       **({"oracle": True, "oracle_noise_std": params.get("oracle_noise_std")}
                          if doc.get("oracle") else {})},
        **provenance(),
        "evidence": result.get("parameters", {}).get("evidence"),
        "result": {k: result[k] for k in _KEPT if k in result},
    }


def main(argv: list[str]) -> int:
    if len(argv) < 2 or not _NAME.match(argv[0]):
        print(__doc__, file=sys.stderr)
        return 2
    scenario = Path(argv[1])
    if not (scenario / "scenario.json").is_file():
        print(f"record_eval: {scenario} has no scenario.json (write one with face-reid-sim)", file=sys.stderr)
        return 2
    doc = record(argv[0], scenario, argv[2:])
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"eval_{argv[0]}.json"
    path.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(json.dumps({"wrote": str(path), "table_ii": doc["result"].get("table_ii")}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
