"""face-reid-eval-body: body re-identification on labelled crops, CMC and mAP per feature and metric.

As the camera and master would: the camera's descriptor code (:mod:`face_reid_camera.body.descriptor`)
describes every crop; per random split half of the identities are the training people: the per-block PCA
projection (what a camera sends) is fitted on their crops, then KISSME and XQDA on their projected vectors;
the other half are probes (one camera) against a gallery (the other cameras), as in the second seed.
Euclidean distances are reported on the raw descriptors and on the projected vectors. The components kept,
the regularisation and XQDA's subspace cap are chosen per split by cross-validation over the training
identities only (:mod:`face_reid_master.training.body.model_selection`). Splits and folds without a person seen by
two cameras are left out and counted (``left_out``); only a folder where nothing is left fails. Prints one
JSON object; ``--plot`` saves the CMC curves.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_camera.body.projection import FEATURES
from face_reid_master.body.features import (
    METRIC_FEATURES,
    feature_columns,
    fit_projection,
    parse_pca_dims,
    raw_feature,
)
from face_reid_master.body.linear_metric import euclidean_metric
from face_reid_master.training.body.cmc import RankScores, rank_scores
from face_reid_master.training.body.crop_descriptors import CROP_SILHOUETTE, describe_crops
from face_reid_master.training.body.crops import Crop, filter_crops, list_crops, reid_splits, same_camera
from face_reid_master.training.body.kissme import fit_kissme
from face_reid_master.training.body.model_selection import (
    DEFAULT_MAX_LENGTH,
    NoCrossCameraMatch,
    SearchGrid,
    Selection,
    dims_candidates,
    select_parameters,
)
from face_reid_master.training.body.xqda import fit_xqda

__all__ = ["METHODS", "evaluate", "main"]

RANKS = (1, 5, 10, 20)
METHODS = ("euclidean_raw", "euclidean_pca", "kissme", "xqda")


def _split_scores(features: Mapping[str, npt.NDArray[np.floating]], labels: npt.NDArray[Any], cameras: list[str],
                  train: npt.NDArray[np.intp], grid: SearchGrid, folds: int, rng: np.random.Generator
                  ) -> tuple[dict[str, dict[str, Callable[[npt.NDArray[np.intp], npt.NDArray[np.intp]], Any]]],
                             Selection, dict[str, int]]:
    """Per feature and method a distance function (probe rows, gallery rows) fitted on the ``train`` rows, the
    parameters chosen on them and each feature's XQDA subspace dimension r."""
    train_features = {b: features[b][train] for b in FEATURES}
    grid = grid.capped(train.size)
    widest = fit_projection(train_features, grid.max_dims())
    scores = widest.project_many(train_features)
    selection = select_parameters({b: scores[:, s] for b, s in widest.slices().items()}, labels[train],
                                  [cameras[i] for i in train], grid, folds, rng)
    projection = fit_projection(train_features, selection.pca_dims)  # what a camera would send
    wire = projection.project_many(features).astype(np.float64)
    out: dict[str, dict[str, Any]] = {}
    subspace: dict[str, int] = {}
    for f in METRIC_FEATURES:
        raw = raw_feature(features, f)
        x = wire[:, feature_columns(projection.slices(), f)]
        xq, ks = selection.xqda[f], selection.kissme[f]
        metrics = {
            "euclidean_raw": (euclidean_metric(raw.shape[1]), raw),
            "euclidean_pca": (euclidean_metric(x.shape[1]), x),
            "kissme": (fit_kissme(x[train], labels[train], regularisation=ks.regularisation), x),
            "xqda": (fit_xqda(x[train], labels[train], regularisation=xq.regularisation, max_dims=xq.max_dims), x),
        }
        out[f] = {m: (lambda p, g, metric=metric, data=data: metric.distances(data[p], data[g]))
                  for m, (metric, data) in metrics.items()}
        subspace[f] = int(metrics["xqda"][0].projection.shape[1])
    return out, selection, subspace


def _summary(runs: list[RankScores]) -> dict[str, Any]:
    r1 = np.array([s.rank(1) for s in runs])
    longest = max(s.cmc.size for s in runs)
    curve = np.mean([np.pad(s.cmc, (0, longest - s.cmc.size), mode="edge") for s in runs], axis=0)
    return {
        **{f"rank{k}": round(float(np.mean([s.rank(k) for s in runs])), 4) for k in RANKS},
        "rank1_std": round(float(r1.std()), 4),
        "map": round(float(np.mean([s.mean_average_precision for s in runs])), 4),
        "probes_per_split": round(float(np.mean([s.probes for s in runs])), 1),
        "cmc": [round(float(v), 4) for v in curve[:50]],
    }


def evaluate(features: Mapping[str, npt.NDArray[np.floating]], labels: npt.NDArray[Any], cameras: list[str],
             n_splits: int, seed: int, grid: SearchGrid, folds: int = 3,
             progress: Callable[[int], None] | None = None
             ) -> tuple[dict[str, dict[str, dict[str, Any]]], list[dict[str, Any]], dict[str, Any]]:
    """Rank-k and mAP per feature and method, mean (and std of rank-1) over the evaluated ones of ``n_splits``
    random splits of the identities (``seed``), each evaluated split's chosen parameters
    (:meth:`Selection.to_dict` and the XQDA subspace dimensions), and what was left out and why (a split
    without a test person seen by two cameras, or whose cross-validation has none). ``features``: per block
    of ``FEATURES`` the raw descriptors (n, d). ValueError if nothing is left to evaluate."""
    rng = np.random.default_rng(seed)
    inner_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    pseudo = [Crop(str(lab), Path(""), cam) for lab, cam in zip(labels.tolist(), cameras, strict=True)]
    cams_of: dict[str, list[str]] = {}
    for c in pseudo:
        cams_of.setdefault(c.identity, []).append(c.camera)
    # as reid_splits: a person is a probe when seen twice and not by one known camera only
    matchable = sum(len(v) >= 2 and len(set(v) - {""}) != 1 for v in cams_of.values())
    if not matchable:
        raise ValueError(f"no person is seen by two cameras ({len(cams_of)} identities, each seen by one camera "
                         f"or in one crop): nothing to evaluate")
    splits = reid_splits(pseudo, n_splits, rng)
    scores: dict[str, dict[str, list[RankScores]]] = {f: {m: [] for m in METHODS} for f in METRIC_FEATURES}
    selections = []
    skipped: list[dict[str, Any]] = []
    for k, split in enumerate(splits):
        try:
            if not split.probe.size:
                raise NoCrossCameraMatch("no test person is seen by two cameras")
            distances, selection, subspace = _split_scores(features, labels, cameras, split.train, grid, folds,
                                                           inner_rng)
        except NoCrossCameraMatch as exc:
            skipped.append({"split": k + 1, "reason": str(exc)})
        else:
            selections.append({**selection.to_dict(), "xqda_subspace_dims": subspace})
            valid = ~same_camera(pseudo, split.probe, split.gallery)
            for f, by_method in distances.items():
                for method, distance in by_method.items():
                    scores[f][method].append(rank_scores(distance(split.probe, split.gallery), labels[split.probe],
                                                         labels[split.gallery], valid))
        if progress:
            progress(k + 1)
    if not selections:
        reasons = "; ".join(f"split {s['split']}: {s['reason']}" for s in skipped)
        raise ValueError(f"every split was left out: {reasons}")
    left_out = {
        "identities_not_seen_by_two_cameras": len(cams_of) - matchable,
        "splits_evaluated": len(selections),
        "splits_skipped": skipped,
        "cv_folds_skipped": sum(len(s["folds_skipped"]) for s in selections),
        "cv_probes_without_match": sum(s["cv_probes_without_match"] for s in selections),
        "test_probes_without_match": sum(r.probes_without_match for r in scores[METRIC_FEATURES[0]][METHODS[0]]),
    }
    return ({f: {m: _summary(runs) for m, runs in by_method.items()} for f, by_method in scores.items()},
            selections, left_out)


def _chosen_summary(selections: list[dict[str, Any]]) -> dict[str, Any]:
    """How often each value was chosen over the splits."""

    def counts(values: list[Any]) -> dict[str, int]:
        out: dict[str, int] = {}
        for v in values:
            out[str(v)] = out.get(str(v), 0) + 1
        return dict(sorted(out.items(), key=lambda kv: -kv[1]))

    return {
        "pca_dims": counts(["_".join(f"{b}{s['pca_dims'][b]}" for b in FEATURES) for s in selections]),
        **{f"{method}_{f}": counts([(s[method][f]["regularisation"], s[method][f]["max_dims"]) for s in selections])
           for method in ("xqda", "kissme") for f in METRIC_FEATURES},
        "xqda_subspace_dims_mean": {f: round(float(np.mean([s["xqda_subspace_dims"][f] for s in selections])), 1)
                                    for f in METRIC_FEATURES},
    }


def _plot(results: dict[str, dict[str, dict[str, Any]]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(4.5 * len(results), 4), squeeze=False)
    for ax, (name, by_method) in zip(axes[0], results.items(), strict=True):
        for method, r in by_method.items():
            ax.plot(np.arange(1, len(r["cmc"]) + 1), r["cmc"], label=f"{method} (rank-1 {r['rank1']:.3f})")
        ax.set_title(name)
        ax.set_xlabel("rank")
        ax.set_ylabel("matching rate")
        ax.set_ylim(0, 1)
        ax.legend(loc="lower right", fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="face-reid-eval-body", description=__doc__.splitlines()[0])
    p.add_argument("crops", type=Path, metavar="CROPS_DIR", help="one sub-folder of person crops per identity")
    p.add_argument("--include", action="append", default=[], metavar="PATTERN",
                   help="only identities whose folder name matches this glob (repeatable), e.g. 'pkureid_*'")
    p.add_argument("--exclude", action="append", default=[], metavar="PATTERN",
                   help="leave out identities whose folder name matches this glob (repeatable)")
    p.add_argument("--splits", type=int, default=10, help="random train / test splits averaged (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the splits and folds (default 0)")
    p.add_argument("--pca-dims", metavar="hsv=N,siltp=N",
                   help="fixed PCA components per block (default: chosen per split by cross-validation)")
    p.add_argument("--max-length", type=int, default=DEFAULT_MAX_LENGTH,
                   help=f"most projected values per person (all blocks) when the components are chosen "
                   f"(default {DEFAULT_MAX_LENGTH})")
    p.add_argument("--folds", type=int, default=3,
                   help="cross-validation folds over each split's training identities (default 3)")
    p.add_argument("--out", type=Path, help="also write the JSON to this file")
    p.add_argument("--plot", type=Path, help="save the CMC curves to this PNG")
    p.add_argument("--silhouette", type=float, default=CROP_SILHOUETTE, metavar="SHARE",
                   help=f"central share of a crop's columns described as the person, in (0, 1] (default "
                        f"{CROP_SILHOUETTE}: the camera cuts the person out by depth; 1 = every pixel)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def _fail(message: str) -> int:
    print(f"face-reid-eval-body: error: {message}", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    """Run the evaluation; returns the exit status (2 on unusable input)."""
    args = _parser().parse_args(list(argv) if argv is not None else None)
    log = None if args.quiet else sys.stderr
    for name in ("splits", "folds", "max_length"):
        low = 2 if name == "folds" else 1
        if getattr(args, name) < low:
            return _fail(f"--{name.replace('_', '-')} must be >= {low}, got {getattr(args, name)}")
    t0 = time.perf_counter()
    try:
        grid = SearchGrid((tuple(parse_pca_dims(args.pca_dims)[b] for b in FEATURES),) if args.pca_dims
                          else dims_candidates(max_length=args.max_length))
        crops = filter_crops(list_crops(args.crops), args.include, args.exclude)
        described = describe_crops(crops, log=log, silhouette=args.silhouette)
        labels, cameras = described.labels, described.cameras
        bar = None
        if log:
            from face_reid_camera.faces.photos import progress_bar

            bar = progress_bar(args.splits, "splits", log)
        results, selections, left_out = evaluate(described.features, labels, cameras, args.splits, args.seed,
                                                 grid, args.folds, bar)
    except ValueError as exc:
        return _fail(str(exc))
    out: dict[str, Any] = {
        "crops_dir": str(args.crops),
        "include": args.include,
        "exclude": args.exclude,
        "crops": len(described.crops),
        "skipped_unreadable": len(described.skipped),
        "identities": len(set(labels.tolist())),
        "crops_with_camera": int(sum(bool(c) for c in cameras)),
        "splits": args.splits,
        "seed": args.seed,
        "protocol": "per split: half of the identities are the training people (PCA projection per block, "
                    "then KISSME / XQDA on the projected vectors); each other identity gives one random probe "
                    "crop, compared with the gallery of every other test crop seen by another camera (cameras "
                    "unknown: every other crop); euclidean_raw on the descriptors, the others on the projected "
                    "vectors",
        "hyperparameters": {
            "chosen_on": f"{args.folds}-fold cross-validation over each split's training identities (every crop "
                         "a probe against the fold's crops of other cameras; rank-1, then mAP); components by "
                         "the fused XQDA" + (" (fixed by --pca-dims)" if args.pca_dims else
                                             f" within {args.max_length} values per person"),
            "grid": grid.to_dict(),
            "chosen_counts": _chosen_summary(selections),
            "per_split": selections,
        },
        "silhouette": args.silhouette,
        "descriptor_ms_per_crop": round(described.ms_per_crop, 3),
        "feature_dims": {f: int(raw_feature(described.features, f).shape[1]) for f in METRIC_FEATURES},
        "left_out": {**left_out, "why": "a split without a test person seen by two cameras, a cross-validation fold "
                                        "without a training person seen by two cameras and a crop whose person no "
                                        "other camera saw cannot be scored: left out, counted; results average the "
                                        "rest"},
        "results": results,
        "run_time_s": round(time.perf_counter() - t0, 1),
    }
    if args.plot:
        _plot(results, args.plot, f"{args.crops.name}: {out['identities']} identities, {args.splits} splits")
        out["plot"] = str(args.plot)
    if log and (left_out["splits_skipped"] or left_out["cv_folds_skipped"]):
        print(f"face-reid-eval-body: left out {len(left_out['splits_skipped'])} of {args.splits} splits and "
              f"{left_out['cv_folds_skipped']} cross-validation folds (no person seen by two cameras in them); see "
              f"'left_out'", file=log)
    text = json.dumps(out, indent=1)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n", encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
