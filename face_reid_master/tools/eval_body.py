"""face-reid-eval-body: body re-identification on labelled crops, CMC and mAP per feature and metric.

The camera's body descriptor code (:mod:`face_reid_camera.body.descriptor`) describes every crop; per
random split half of the identities train KISSME and XQDA, the other half are probes (one camera) against
a gallery (the other cameras), as in the second seed. Prints one JSON object; ``--plot`` saves the CMC
curves.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_master.body.cmc import rank_scores
from face_reid_master.body.crops import Crop, list_crops, reid_splits, same_camera
from face_reid_master.body.kissme import fit_kissme
from face_reid_master.body.linear_metric import LinearMetric, euclidean_metric
from face_reid_master.body.xqda import fit_xqda

__all__ = ["describe_crops", "evaluate", "main"]

RANKS = (1, 5, 10, 20)
KISSME_PCA_DIMS = 100  # KISSME's usual PCA before the metric (fewer when there are fewer training crops)


def describe_crops(crops: Sequence[Crop], log: Any = None) -> tuple[dict[str, np.ndarray], list[int], float]:
    """Per feature ("hsv", "siltp", "fused") the descriptors (n, d) of the readable crops, their indices in
    ``crops``, and the mean time per crop (ms)."""
    from face_reid_camera.body.descriptor import BodyDescriptorConfig, body_descriptor
    from face_reid_camera.faces.photos import PhotoError, progress_bar, read_photo

    config = BodyDescriptorConfig()
    bar = progress_bar(len(crops), "describing crops", log) if log else None
    hsv, siltp, kept = [], [], []
    spent = 0.0
    for k, crop in enumerate(crops):
        try:
            image = read_photo(crop.path)
        except PhotoError as exc:
            if log:
                print(f"skipped: {exc}", file=log)
            continue
        t0 = time.perf_counter()
        d = body_descriptor(image, None, config)
        spent += time.perf_counter() - t0
        hsv.append(d.hsv)
        siltp.append(d.siltp)
        kept.append(k)
        if bar:
            bar(k + 1)
    if not kept:
        raise ValueError("no crop could be read")
    h, s = np.asarray(hsv, dtype=np.float64), np.asarray(siltp, dtype=np.float64)
    fused = np.hstack([h, s]) / np.sqrt(2.0)  # each part unit-length: the fused vector too
    return {"hsv": h, "siltp": s, "fused": fused}, kept, 1e3 * spent / len(kept)


def _metrics(x: np.ndarray, labels: np.ndarray) -> dict[str, LinearMetric]:
    pca = min(KISSME_PCA_DIMS, x.shape[1], max(1, x.shape[0] - len(set(labels.tolist()))))
    return {"euclidean": euclidean_metric(x.shape[1]), "kissme": fit_kissme(x, labels, pca_dims=pca),
            "xqda": fit_xqda(x, labels)}


def evaluate(features: dict[str, np.ndarray], labels: np.ndarray, cameras: list[str], n_splits: int, seed: int,
             progress: Callable[[int], None] | None = None) -> dict[str, dict[str, dict[str, Any]]]:
    """Rank-k and mAP per feature and metric, mean (and std of rank-1) over ``n_splits`` random splits."""
    rng = np.random.default_rng(seed)
    pseudo = [Crop(str(lab), Path(""), cam) for lab, cam in zip(labels.tolist(), cameras, strict=True)]
    splits = reid_splits(pseudo, n_splits, rng)
    scores: dict[str, dict[str, list[Any]]] = {}
    for k, split in enumerate(splits):
        valid = ~same_camera(pseudo, split.probe, split.gallery)
        for name, x in features.items():
            for method, metric in _metrics(x[split.train], labels[split.train]).items():
                s = rank_scores(metric.distances(x[split.probe], x[split.gallery]), labels[split.probe],
                                labels[split.gallery], valid)
                scores.setdefault(name, {}).setdefault(method, []).append(s)
        if progress:
            progress(k + 1)
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for name, by_method in scores.items():
        for method, runs in by_method.items():
            r1 = np.array([s.rank(1) for s in runs])
            longest = max(s.cmc.size for s in runs)
            curve = np.mean([np.pad(s.cmc, (0, longest - s.cmc.size), mode="edge") for s in runs], axis=0)
            out.setdefault(name, {})[method] = {
                **{f"rank{k}": round(float(np.mean([s.rank(k) for s in runs])), 4) for k in RANKS},
                "rank1_std": round(float(r1.std()), 4),
                "map": round(float(np.mean([s.mean_average_precision for s in runs])), 4),
                "probes_per_split": round(float(np.mean([s.probes for s in runs])), 1),
                "cmc": [round(float(v), 4) for v in curve[:50]],
            }
    return out


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
    p.add_argument("--splits", type=int, default=10, help="random train / test splits averaged (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the splits (default 0)")
    p.add_argument("--out", type=Path, help="also write the JSON to this file")
    p.add_argument("--plot", type=Path, help="save the CMC curves to this PNG")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the evaluation; returns the exit status (2 on unusable input)."""
    args = _parser().parse_args(list(argv) if argv is not None else None)
    log = None if args.quiet else sys.stderr
    if args.splits < 1:
        print(f"face-reid-eval-body: error: --splits must be >= 1, got {args.splits}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    try:
        crops = list_crops(args.crops)
        features, kept, ms_per_crop = describe_crops(crops, log)
        labels = np.array([crops[k].identity for k in kept])
        cameras = [crops[k].camera for k in kept]
        bar = None
        if log:
            from face_reid_camera.faces.photos import progress_bar

            bar = progress_bar(args.splits, "splits", log)
        results = evaluate(features, labels, cameras, args.splits, args.seed, bar)
    except ValueError as exc:
        print(f"face-reid-eval-body: error: {exc}", file=sys.stderr)
        return 2
    out: dict[str, Any] = {
        "crops_dir": str(args.crops),
        "crops": len(kept),
        "skipped_unreadable": len(crops) - len(kept),
        "identities": len(set(labels.tolist())),
        "crops_with_camera": int(sum(bool(c) for c in cameras)),
        "splits": args.splits,
        "seed": args.seed,
        "protocol": "per split: half of the identities train the metrics; each other identity gives one "
                    "random probe crop, compared with the gallery of every other test crop seen by another "
                    "camera (cameras unknown: every other crop)",
        "descriptor_ms_per_crop": round(ms_per_crop, 3),
        "feature_dims": {k: int(v.shape[1]) for k, v in features.items()},
        "results": results,
        "run_time_s": round(time.perf_counter() - t0, 1),
    }
    if args.plot:
        _plot(results, args.plot, f"{args.crops.name}: {out['identities']} identities, {args.splits} splits")
        out["plot"] = str(args.plot)
    text = json.dumps(out, indent=1)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n", encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
