"""What a decision's posterior is worth: the measured accuracy of decisions taken at that posterior.

The face table's posterior multiplies observations that are far from independent and trusts likelihoods fitted
on other people, so a decision taken at 0.999 is right much less often (see docs/results.md). The published
``identity_confidence`` of a decided track is therefore looked up in a map fitted on evaluated development
scenarios: per evidence ("face", "body"; "both" uses "face") and bin of the raw posterior, the share of decisions
that were right, made non-decreasing across bins (pool-adjacent-violators) and smoothed by one right and one
wrong pseudo-decision. The map records the scenarios' people (``identities``), so that an evaluation can tell
whether it saw them. Pure numpy.
"""

from __future__ import annotations

import bisect
import itertools
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from face_reid_camera.common.resources import model_path

__all__ = ["CONFIDENCE_MAP_FILE", "ConfidenceMap", "default_confidence_map", "fit_confidence_map",
           "load_confidence_map", "save_confidence_map"]

CONFIDENCE_MAP_FILE = "identity_confidence.json"
FORMAT = "face-reid-confidence-map"
VERSION = 1
EVIDENCE = ("face", "body")


@dataclass(frozen=True)
class ConfidenceMap:
    """``edges``: raw posterior bin edges (ascending, 0 .. 1); ``values[evidence]``: the calibrated probability
    of each bin; ``decisions[evidence]``: the development decisions behind each bin."""

    edges: tuple[float, ...]
    values: Mapping[str, tuple[float, ...]]
    decisions: Mapping[str, tuple[int, ...]] = field(default_factory=dict)
    metadata: Mapping[str, Any] = field(default_factory=dict)
    raw: bool = False  # publish the raw posterior (what a map is fitted on)

    @classmethod
    def identity(cls) -> ConfidenceMap:
        """The map that publishes the raw posterior unchanged (to measure what a map is fitted on)."""
        return cls((0.0, 1.0), {k: (1.0,) for k in EVIDENCE}, metadata={"identities": []}, raw=True)

    def __post_init__(self) -> None:
        e = self.edges
        if len(e) < 2 or e[0] != 0.0 or e[-1] != 1.0 or any(b <= a for a, b in itertools.pairwise(e)):
            raise ValueError(f"edges must rise strictly from 0 to 1, got {list(e)}")
        for kind in EVIDENCE:
            v = self.values.get(kind)
            if v is None or len(v) != len(e) - 1 or not all(0.0 <= x <= 1.0 for x in v):
                raise ValueError(f"values[{kind!r}] must hold {len(e) - 1} probabilities in [0, 1], got {v!r}")

    def __call__(self, evidence: str, posterior: float) -> float:
        """The calibrated probability of a decision taken by ``evidence`` at raw ``posterior``."""
        if self.raw:
            return posterior
        values = self.values["body" if evidence == "body" else "face"]
        k = min(max(bisect.bisect_right(self.edges, posterior) - 1, 0), len(values) - 1)
        return values[k]


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
        if out[k] != out[k]:
            out[k] = last
        else:
            last = out[k]
    return out


def fit_confidence_map(results: Iterable[Mapping[str, Any]], identities: Iterable[str] = (),
                       sources: Sequence[str] = ()) -> ConfidenceMap:
    """Fit a map from face-reid-eval results (their ``calibration`` blocks: decisions per evidence and bin)."""
    edges: tuple[float, ...] | None = None
    right: dict[str, list[float]] = {}
    count: dict[str, list[float]] = {}
    for res in results:
        cal = res["calibration"]
        e = tuple(float(x) for x in cal["bin_edges"])
        if edges is None:
            edges = e
            right = {k: [0.0] * (len(e) - 1) for k in EVIDENCE}
            count = {k: [0.0] * (len(e) - 1) for k in EVIDENCE}
        elif e != edges:
            raise ValueError(f"results with other bin edges: {list(e)} vs {list(edges)}")
        for kind, block in cal["by_evidence"].items():
            target = "body" if kind == "body" else "face"
            for k, b in enumerate(block.get("bins", ())):
                n = int(b["count"])
                if n:
                    count[target][k] += n
                    right[target][k] += n - int(b["wrong"])
    if edges is None:
        raise ValueError("no results to fit on")
    values = {k: tuple(round(v, 6) for v in _pooled(right[k], count[k])) for k in EVIDENCE}
    decisions = {k: tuple(int(n) for n in count[k]) for k in EVIDENCE}
    meta = {"tool": "face_reid_master.identity.confidence_map.fit_confidence_map", "fitted_on": list(sources),
            "identities": sorted(set(identities)),
            "right": {k: int(sum(right[k])) for k in EVIDENCE}, "decisions": {k: int(sum(count[k])) for k in EVIDENCE}}
    return ConfidenceMap(edges, values, decisions, meta)


def save_confidence_map(cmap: ConfidenceMap, path: str | Path) -> None:
    doc = {"format": FORMAT, "version": VERSION, "edges": list(cmap.edges),
           "values": {k: list(v) for k, v in cmap.values.items()},
           "decisions": {k: list(v) for k, v in cmap.decisions.items()}, "metadata": dict(cmap.metadata)}
    Path(path).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


def load_confidence_map(path: str | Path) -> ConfidenceMap:
    """Read a map file: FileNotFoundError when missing, ValueError (path and reason) when unusable."""
    src = Path(path)
    if not src.is_file():
        raise FileNotFoundError(f"confidence map {src}: No such file")
    try:
        doc = json.loads(src.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("version") != VERSION:
            raise ValueError(f"not a {FORMAT} version {VERSION} file")
        return ConfidenceMap(tuple(float(x) for x in doc["edges"]),
                             {k: tuple(float(x) for x in doc["values"][k]) for k in EVIDENCE},
                             {k: tuple(int(x) for x in doc.get("decisions", {}).get(k, ())) for k in EVIDENCE},
                             doc.get("metadata", {}))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"confidence map {src} is unusable: {exc}") from exc


def default_confidence_map() -> ConfidenceMap:
    """The shipped map (models/identity_confidence.json)."""
    return load_confidence_map(model_path(CONFIDENCE_MAP_FILE))
