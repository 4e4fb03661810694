"""Did a fitted model see a scenario's people? The check behind an honest evaluation.

A result counts only on people no fitted model has seen: the face likelihoods and naming distance
(face-reid-fit-likelihood), the body projection the cameras described them with and the body metric
(face-reid-fit-body). Each fit tool records what it saw in its file's metadata: ``identities`` (the folder
names used) or, in older face fits, ``excluded`` (the globs and scenario identities left out). This module
compares those with a scenario's face identities and the crop identities its people wore. Pure Python.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from face_reid_master.tools.fit_likelihood import excluded_from_fit

__all__ = ["FitOverlap", "ProtocolCheck", "check_protocol", "fitted_identities", "scenario_crop_identities"]


def _as_value(raw: Any) -> Any:
    """Metadata values written as Python literals in text (older files) are read back; others pass."""
    if isinstance(raw, str):
        try:
            return ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            return raw
    return raw


def fitted_identities(metadata: Mapping[str, Any]) -> frozenset[str] | None:
    """The identities a model's fit used, from its metadata's ``identities``; None when it does not say."""
    value = _as_value(metadata.get("identities"))
    if isinstance(value, list | tuple) and all(isinstance(v, str) for v in value):
        return frozenset(value)
    return None


def _seen_by_exclusions(names: Iterable[str], metadata: Mapping[str, Any]) -> list[str] | None:
    """Names an older face fit may have seen: those its ``excluded`` globs and scenario identities did not
    leave out (it used every other folder of its faces directory); None when it does not say."""
    excluded = _as_value(metadata.get("excluded"))
    if not isinstance(excluded, dict):
        return None
    left_out = set(_as_value(excluded.get("scenario_identities", ())) or ())
    patterns = [str(p) for p in _as_value(excluded.get("patterns", ())) or ()]
    return sorted(n for n in names if not excluded_from_fit(n, patterns, left_out))


@dataclass(frozen=True)
class FitOverlap:
    """One model against the scenario: the scenario's identities it was fitted on (None: the model does not
    record what it saw)."""

    model: str
    source: str  # what the model is (file or "shipped ...")
    seen: tuple[str, ...] | None

    @property
    def clean(self) -> bool:
        return self.seen is not None and not self.seen

    def as_json(self) -> dict[str, Any]:
        return {"model": self.model, "source": self.source,
                "identities_seen": None if self.seen is None else list(self.seen)}


@dataclass(frozen=True)
class ProtocolCheck:
    """Every loaded model's overlap with the scenario; ``honest`` when none saw its people and all say so."""

    overlaps: tuple[FitOverlap, ...] = field(default_factory=tuple)

    @property
    def honest(self) -> bool:
        return all(o.clean for o in self.overlaps)

    def problems(self) -> list[str]:
        """One line per model that saw the scenario's people or does not say what it saw."""
        out = []
        for o in self.overlaps:
            if o.seen is None:
                out.append(f"{o.model} ({o.source}) does not record the identities it was fitted on")
            elif o.seen:
                shown = ", ".join(o.seen[:8]) + (f" and {len(o.seen) - 8} more" if len(o.seen) > 8 else "")
                out.append(f"{o.model} ({o.source}) was fitted on {len(o.seen)} of the scenario's identities: {shown}")
        return out

    def as_json(self) -> dict[str, Any]:
        return {"honest": self.honest, "models": [o.as_json() for o in self.overlaps]}


def scenario_crop_identities(document: Mapping[str, Any]) -> list[str]:
    """The crop identities the scenario's people wore (every day), sorted; empty without bodies."""
    worn = {str(name) for ident in document.get("identities", ()) for name in (ident.get("clothes") or {}).values()}
    return sorted(worn)


def _overlap(model: str, source: str, names: list[str], metadata: Mapping[str, Any],
             use_exclusions: bool = False) -> FitOverlap:
    seen_set = fitted_identities(metadata)
    if seen_set is not None:
        return FitOverlap(model, source, tuple(n for n in names if n in seen_set))
    by_exclusion = _seen_by_exclusions(names, metadata) if use_exclusions else None
    return FitOverlap(model, source, None if by_exclusion is None else tuple(by_exclusion))


def check_protocol(document: Mapping[str, Any], face_metadata: Mapping[str, Any], face_source: str,
                   body_metric_metadata: Mapping[str, Any] | None = None,
                   body_metric_source: str = "", confidence_metadata: Mapping[str, Any] | None = None,
                   confidence_source: str = "") -> ProtocolCheck:
    """The overlap of a scenario (its ``scenario.json`` document) with the face likelihoods, the body projection
    it was described with (recorded by face-reid-sim), the body metric (None: bodies not evaluated) and the
    confidence map (None: not checked; fitted on scenarios, it records their faces and crops alike)."""
    faces = sorted(str(i["name"]) for i in document.get("identities", ()))
    overlaps = [_overlap("face likelihoods and naming distance", face_source, faces, face_metadata,
                         use_exclusions=True)]
    crops = scenario_crop_identities(document)
    if crops:
        projection = document.get("body_projection_fit")
        meta = {"identities": projection} if isinstance(projection, list) else {}
        overlaps.append(_overlap("body projection", str(document.get("body_space", "")), crops, meta))
        if body_metric_metadata is not None:
            overlaps.append(_overlap("body metric", body_metric_source, crops, body_metric_metadata))
    if confidence_metadata is not None:
        overlaps.append(_overlap("confidence map", confidence_source, sorted([*faces, *crops]), confidence_metadata))
    return ProtocolCheck(tuple(overlaps))
