"""Compare master settings on development scenarios: bench/results/choices_NAME.json (docs/results.md shows it).

    python bench/dev_sweep.py NAME --scenarios DIR,DIR,... --body-metric FILE "LABEL:param=value,..." ...

Each variant (``LABEL:`` alone = the defaults) runs the master core over every scenario, as ``face-reid-eval``
does offline (fused evidence), and is summed over them: Table II
right / wrong, recover rate, face and body decisions, wrong identity, wrong names and strangers named per detection.
Choices are
made on these sums (the frontier of wrong decisions against recover rate), on development scenarios only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from record_eval import RESULTS, provenance, shown

from face_reid_master.body.metric_file import load_body_metric
from face_reid_master.core import MasterConfig
from face_reid_master.evaluation.gallery import default_gallery_people, scenario_gallery
from face_reid_master.evaluation.metrics import evaluate_run
from face_reid_master.evaluation.runner import run_master
from face_reid_master.identity.size_likelihood import default_face_likelihood
from face_reid_master.sim.scenario_files import load_scenario
from face_reid_master.tracking.config import TrackerConfig

_SUMS = ("right", "wrong", "reid_success", "reid_cases", "face_right", "face_wrong", "body_right", "body_wrong",
         "gallery_detections", "wrong_names", "other_detections", "others_named", "published_detections",
         "wrong_identity_detections")


def _value(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text, text)


def parse_variant(spec: str) -> tuple[str, dict[str, Any]]:
    """"LABEL:a=1,b=false" -> ("LABEL", {"a": 1, "b": False}); unknown parameters fail in MasterConfig
    (``tracker.NAME`` sets a tracker parameter)."""
    label, sep, rest = spec.partition(":")
    if not sep or not label:
        raise ValueError(f"a variant is LABEL:param=value,... (LABEL: alone = the defaults), got {spec!r}")
    pairs = [p.split("=", 1) for p in rest.split(",") if p]
    if any(len(p) != 2 for p in pairs):
        raise ValueError(f"variant {label!r}: every override is param=value, got {rest!r}")
    return label, {k: _value(v) for k, v in pairs}


def master_config(overrides: dict[str, Any], **defaults: Any) -> MasterConfig:
    """MasterConfig of ``defaults`` and ``overrides``; ``tracker.NAME`` keys go to its TrackerConfig."""
    tracker = {k.removeprefix("tracker."): v for k, v in overrides.items() if k.startswith("tracker.")}
    master = {k: v for k, v in overrides.items() if not k.startswith("tracker.")}
    return MasterConfig(**{**defaults, **master}, **({"tracker": TrackerConfig(**tracker)} if tracker else {}))


def run_variant(scenarios: list[Any], metric: Any, overrides: dict[str, Any]) -> dict[str, int]:
    sums = dict.fromkeys(_SUMS, 0)
    for sc in scenarios:
        space = sc.document["embedding_space"]
        gal = scenario_gallery(sc.document, sc.directory, default_gallery_people(sc.document, None), space=space)
        cfg = master_config(overrides, embedding_space=space)
        log = run_master(sc.frames, sc.frame_gt_ids, cfg, likelihood=default_face_likelihood(space),
                         body_metric=metric, gallery=gal.people or None, days=sc.day_spans)
        m = evaluate_run(log, gallery_people=gal.gt_of_name or None, scenario_summary=sc.summary, with_mot=False)
        t2, reid, ev = m["table_ii"], m["reidentification"], m["calibration"]["by_evidence"]
        dets = m["predefined_people"]["detections"]
        per_detection = m["per_detection"]
        for key, value in (("right", t2["success"]), ("wrong", t2["failure"]), ("reid_success", reid["success"]),
                           ("reid_cases", reid["tracks"]), ("face_right", ev["face"]["right"]),
                           ("face_wrong", ev["face"]["wrong"]), ("body_right", ev["body"]["right"]),
                           ("body_wrong", ev["body"]["wrong"]), ("gallery_detections", dets["gallery_detections"]),
                           ("wrong_names", dets["wrong_name"]), ("other_detections", dets["other_detections"]),
                           ("others_named", dets["other_named"]),
                           ("published_detections", per_detection["published_detections"]),
                           ("wrong_identity_detections", per_detection["wrong_identity"])):
            sums[key] += int(value)
    return sums


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("name")
    p.add_argument("--scenarios", required=True, help="comma-separated development scenario directories")
    p.add_argument("--body-metric", required=True, help="the body metric the scenarios are evaluated with")
    p.add_argument("variants", nargs="+", help='"LABEL:param=value,..." ("LABEL:" = the defaults)')
    args = p.parse_args(argv)
    variants = [parse_variant(v) for v in args.variants]
    for _, overrides in variants:
        master_config(overrides)  # a wrong name or value fails before hours of running
    scenarios = [load_scenario(s) for s in args.scenarios.split(",")]
    metric = load_body_metric(args.body_metric)
    rows = []
    for label, overrides in variants:
        rows.append({"label": label, "overrides": overrides, **run_variant(scenarios, metric, overrides)})
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    doc = {"name": args.name, "command": " ".join(["python bench/dev_sweep.py", *(shown(a) for a in argv)]),
           "scenarios": [{"directory": Path(sc.directory).name, "seed": sc.document.get("seed")} for sc in scenarios],
           **provenance(), "variants": rows}
    out = RESULTS / f"choices_{args.name}.json"
    out.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
