"""Fit the confidence map (models/identity_confidence.json) on evaluated development scenarios.

    python -m face_reid_master.tools.fit_confidence --out models/identity_confidence.json RESULT.json ...

Each RESULT is a face-reid-eval JSON of a development scenario run with ``--confidence-map raw`` (or a
bench/record_eval.py file holding one): its calibration block says, per evidence and bin of the raw posterior,
how many decisions were taken and how many were wrong. The map records the scenarios' face and crop identities,
so that face-reid-eval refuses to report on those people with it.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from face_reid_master.evaluation.protocol import scenario_crop_identities
from face_reid_master.identity.confidence_map import fit_confidence_map, save_confidence_map


def _result(path: Path) -> dict[str, Any]:
    doc = json.loads(path.read_text(encoding="utf-8"))
    res = doc.get("result", doc)
    if "calibration" not in res or "scenario" not in res:
        raise ValueError(f"{path} is not a face-reid-eval result (no calibration / scenario block)")
    return res


def _people(res: dict[str, Any]) -> list[str]:
    """The scenario's face identities and the crops its people wore (from its scenario.json)."""
    scenario = Path(str(res["scenario"]["directory"])) / "scenario.json"
    doc = json.loads(scenario.read_text(encoding="utf-8"))
    return [str(i["name"]) for i in doc.get("identities", ())] + scenario_crop_identities(doc)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fit_confidence", description=__doc__.split("\n\n")[0])
    p.add_argument("results", nargs="+", type=Path, help="face-reid-eval JSON files of development scenarios")
    p.add_argument("--out", type=Path, required=True, help="the map file to write")
    args = p.parse_args(argv)
    try:
        results = [_result(r) for r in args.results]
        mapped = [str(r) for r, res in zip(args.results, results, strict=True)
                  if res.get("confidence_map", "raw") != "raw"]
        if mapped:
            raise ValueError(f"evaluated through a confidence map, not raw: {', '.join(mapped)} "
                             "(run face-reid-eval with --confidence-map raw)")
        people = sorted({n for res in results for n in _people(res)})
        cmap = fit_confidence_map(results, people, [str(r) for r in args.results])
    except (OSError, ValueError, KeyError) as exc:
        print(f"fit_confidence: error: {exc}", file=sys.stderr)
        return 2
    save_confidence_map(cmap, args.out)
    summary = {k: {"decisions": cmap.metadata["decisions"][k], "right": cmap.metadata["right"][k],
                   "values": list(cmap.values[k])} for k in cmap.values}
    print(json.dumps({"wrote": str(args.out), "people": len(people), **summary}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
