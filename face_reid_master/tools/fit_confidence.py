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
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from face_reid_master.evaluation.protocol import scenario_crop_identities
from face_reid_master.identity.confidence_map import DECISIONS, ConfidenceMap, save_confidence_map
from face_reid_master.sim.scenario_files import load_scenario_document


def _pooled(right: Sequence[float], count: Sequence[float]) -> list[float]:
    """Pool-adjacent-violators on (right + 1) / (count + 2): a non-decreasing accuracy per bin; empty bins take
    their neighbours' value."""
    blocks: list[list[float]] = []  # [right, count, first bin, last bin]
    for k, (r, n) in enumerate(zip(right, count, strict=True)):
        if n <= 0:
            continue
        blocks.append([r, n, k, k])
        while len(blocks) > 1 and (blocks[-2][0] + 1) / (blocks[-2][1] + 2) > (blocks[-1][0] + 1) / (blocks[-1][1] + 2):
            r2, n2, _, last = blocks.pop()
            blocks[-1][0] += r2
            blocks[-1][1] += n2
            blocks[-1][3] = last
    out = [float("nan")] * len(count)
    if not blocks:
        return [0.5] * len(count)
    for r, n, a, b in blocks:
        for k in range(int(a), int(b) + 1):
            out[k] = (r + 1) / (n + 2)
    last = (blocks[0][0] + 1) / (blocks[0][1] + 2)
    for k in range(len(out)):  # empty bins: the value of the nearest filled bin below (above for the first ones)
        if math.isnan(out[k]):
            out[k] = last
        else:
            last = out[k]
    return out


def fit_confidence_map(results: Iterable[Mapping[str, Any]], identities: Iterable[str] = (),
                       sources: Sequence[str] = ()) -> ConfidenceMap:
    """Fit a map from face-reid-eval results (their ``calibration`` blocks: decisions per kind and bin)."""
    edges: tuple[float, ...] | None = None
    right: dict[str, list[float]] = {}
    count: dict[str, list[float]] = {}
    for res in results:
        cal = res["calibration"]
        e = tuple(float(x) for x in cal["bin_edges"])
        if edges is None:
            edges = e
            right = {k: [0.0] * (len(e) - 1) for k in DECISIONS}
            count = {k: [0.0] * (len(e) - 1) for k in DECISIONS}
        elif e != edges:
            raise ValueError(f"results with other bin edges: {list(e)} vs {list(edges)}")
        if "by_decision" not in cal:
            raise ValueError("a result without decisions per kind (calibration.by_decision): evaluate it again")
        for target, block in cal["by_decision"].items():
            for k, b in enumerate(block.get("bins", ())):
                n = int(b["count"])
                if n:
                    count[target][k] += n
                    right[target][k] += n - int(b["wrong"])
    if edges is None:
        raise ValueError("no results to fit on")
    values = {k: tuple(round(v, 6) for v in _pooled(right[k], count[k])) for k in DECISIONS}
    decisions = {k: tuple(int(n) for n in count[k]) for k in DECISIONS}
    meta = {"tool": "face_reid_master.tools.fit_confidence", "fitted_on": list(sources),
            "identities": sorted(set(identities)),
            "right": {k: int(sum(right[k])) for k in DECISIONS},
            "decisions": {k: int(sum(count[k])) for k in DECISIONS}}
    return ConfidenceMap(edges, values, decisions, meta)


def _result(path: Path) -> dict[str, Any]:
    doc = json.loads(path.read_text(encoding="utf-8"))
    res = doc.get("result", doc)
    if "calibration" not in res or "scenario" not in res:
        raise ValueError(f"{path} is not a face-reid-eval result (no calibration / scenario block)")
    return res


def _people(res: dict[str, Any]) -> list[str]:
    """The scenario's face identities and the crops its people wore (from its scenario.json)."""
    doc = load_scenario_document(Path(str(res["scenario"]["directory"])))
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
