"""What a decision's posterior is worth: the measured accuracy of decisions taken at that posterior.

The face table's posterior multiplies observations that are far from independent and trusts likelihoods fitted
on other people, so a decision taken at 0.999 is right much less often (see docs/results.md). The published
``identity_confidence`` of a decided track is therefore looked up in a map fitted on evaluated development
scenarios (face_reid_master.tools.fit_confidence): per kind of decision and bin of the raw posterior, the share
of decisions that were right. The kinds: a face re-identified by its face ("face_known"; a body decision its face
later confirmed, "both", counts here too), a new face created for a track ("face_new": right only if the person
was not known, so much less often right on development data) and a face given by body evidence ("body"). The
map records the scenarios' people (``identities``), so that an evaluation can tell whether it saw them. Pure
Python.
"""

from __future__ import annotations

import bisect
import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from face_reid_camera.common.model_files import read_model_json, unusable_model
from face_reid_camera.common.resources import model_path
from face_reid_master.identity.evidence import Evidence

__all__ = ["CONFIDENCE_MAP_FILE", "DECISIONS", "ConfidenceMap", "decision_key", "default_confidence_map",
           "load_confidence_map", "save_confidence_map"]

CONFIDENCE_MAP_FILE = "identity_confidence.json"
FORMAT = "face-reid-confidence-map"
VERSION = 2
DECISIONS = ("face_known", "face_new", "body")


def decision_key(evidence: str, new_face: bool) -> str:
    """The map's kind of a decision by ``evidence`` (an :class:`~.evidence.Evidence`) that did / did not create a
    face: a cue other than the face decides among learned faces as the body does ("body")."""
    if evidence not in (Evidence.FACE, Evidence.BOTH):
        return "body"
    return "face_new" if new_face else "face_known"


@dataclass(frozen=True)
class ConfidenceMap:
    """``edges``: raw posterior bin edges (ascending, 0 .. 1); ``values[kind]`` (kind: :data:`DECISIONS`): the
    calibrated probability of each bin; ``decisions[kind]``: the development decisions behind each bin."""

    edges: tuple[float, ...]
    values: Mapping[str, tuple[float, ...]]
    decisions: Mapping[str, tuple[int, ...]] = field(default_factory=dict)
    metadata: Mapping[str, Any] = field(default_factory=dict)
    raw: bool = False  # publish the raw posterior (what a map is fitted on)

    @classmethod
    def identity(cls) -> ConfidenceMap:
        """The map that publishes the raw posterior unchanged (to measure what a map is fitted on)."""
        return cls((0.0, 1.0), {k: (1.0,) for k in DECISIONS}, metadata={"identities": []}, raw=True)

    def __post_init__(self) -> None:
        e = self.edges
        if len(e) < 2 or e[0] != 0.0 or e[-1] != 1.0 or any(b <= a for a, b in itertools.pairwise(e)):
            raise ValueError(f"edges must rise strictly from 0 to 1, got {list(e)}")
        for kind in DECISIONS:
            v = self.values.get(kind)
            if v is None or len(v) != len(e) - 1 or not all(0.0 <= x <= 1.0 for x in v):
                raise ValueError(f"values[{kind!r}] must hold {len(e) - 1} probabilities in [0, 1], got {v!r}")

    def __call__(self, evidence: str, posterior: float, new_face: bool = False) -> float:
        """The calibrated probability of a decision taken by ``evidence`` at raw ``posterior`` (``new_face``: it
        created a new face)."""
        if self.raw:
            return posterior
        values = self.values[decision_key(evidence, new_face)]
        k = min(max(bisect.bisect_right(self.edges, posterior) - 1, 0), len(values) - 1)
        return values[k]


def save_confidence_map(cmap: ConfidenceMap, path: str | Path) -> None:
    doc = {"format": FORMAT, "version": VERSION, "edges": list(cmap.edges),
           "values": {k: list(v) for k, v in cmap.values.items()},
           "decisions": {k: list(v) for k, v in cmap.decisions.items()}, "metadata": dict(cmap.metadata)}
    Path(path).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


def load_confidence_map(path: str | Path) -> ConfidenceMap:
    """Read a map file: FileNotFoundError when missing, :class:`ModelLoadError` (path and reason) when unusable."""
    doc = read_model_json(path, FORMAT, VERSION, "confidence map", "fit one with face_reid_master.tools.fit_confidence")
    with unusable_model("confidence map", path):
        return ConfidenceMap(tuple(float(x) for x in doc["edges"]),
                             {k: tuple(float(x) for x in doc["values"][k]) for k in DECISIONS},
                             {k: tuple(int(x) for x in doc.get("decisions", {}).get(k, ())) for k in DECISIONS},
                             doc.get("metadata", {}))


def default_confidence_map() -> ConfidenceMap:
    """The shipped map (models/identity_confidence.json)."""
    return load_confidence_map(model_path(CONFIDENCE_MAP_FILE))
