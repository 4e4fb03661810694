"""``face-reid-fit-body``: fit the body projection (what cameras send) and the body metric (what the master
compares with) on a folder of labelled person crops.

CROPS_DIR holds one sub-folder of crops per identity (cameras from the file names, see
:mod:`face_reid_master.training.body.crops`). The camera's descriptor code describes every crop; a PCA per
descriptor block gives the projection (``--projection FILE`` keeps an existing one: cameras already send
it, so the metric can be refitted alone); XQDA per feature (hsv, siltp, both fused) on the projected
vectors gives the metric; skew-normal N_p / N_n fitted to held-out same / different-person distances give
the likelihoods and the decision distance (N_p = N_n). The components kept, the regularisation and XQDA's
subspace cap are chosen by cross-validation over the identities (:mod:`face_reid_master.training.body.model_selection`).
Writes ``body_projection.npz``, ``body_metric.json`` and ``body_metric_fit.png`` into ``--out-dir``.
``SOURCE_DATE_EPOCH`` (seconds) fixes the recorded date: same inputs, same bytes.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import os
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from face_reid_camera.body.projection import (
    BODY_PROJECTION_FILE,
    FEATURES,
    BodyProjection,
    load_body_projection,
    save_body_projection,
)
from face_reid_camera.common.errors import ModelLoadError
from face_reid_master.body.features import METRIC_FEATURES, fit_projection, parse_pca_dims
from face_reid_master.body.metric_file import BODY_METRIC_FILE, BodyMetricModel, load_body_metric, save_body_metric
from face_reid_master.training.body.crop_descriptors import CROP_SILHOUETTE, CropDescriptors, describe_crops
from face_reid_master.training.body.crops import Crop, filter_crops, list_crops
from face_reid_master.training.body.metric_fit import FeatureFit, fit_feature_metrics
from face_reid_master.training.body.model_selection import (
    DEFAULT_MAX_LENGTH,
    SearchGrid,
    dims_candidates,
    identity_folds,
    select_parameters,
)

__all__ = ["PLOT_FILE", "main", "plot_fit", "scenario_clothes"]

PLOT_FILE = "body_metric_fit.png"


def scenario_clothes(directories: Iterable[Path]) -> set[str]:
    """The crop identities worn in these face-reid-sim scenarios (each identity's ``clothes``: {day: crop
    folder}); a scenario without bodies adds none. ValueError on an unreadable scenario."""
    from face_reid_master.sim.scenario_files import ScenarioFormatError, load_scenario_document

    names: set[str] = set()
    for directory in directories:
        try:
            doc = load_scenario_document(directory)
        except ScenarioFormatError as exc:
            raise ValueError(f"--exclude-scenario: {exc}") from None
        for ident in doc["identities"]:
            clothes = ident.get("clothes") if isinstance(ident, dict) else None
            if clothes is None:
                continue
            worn = clothes.values() if isinstance(clothes, dict) else clothes
            if not isinstance(worn, Iterable) or isinstance(worn, str) or any(not isinstance(c, str) for c in worn):
                raise ValueError(f"--exclude-scenario: {directory}/scenario.json: clothes must map days to crop "
                                 f"folder names, got {clothes!r}")
            names.update(worn)
    return names


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="face-reid-fit-body", description=__doc__.splitlines()[0].strip("`: "))
    p.add_argument("crops", type=Path, metavar="CROPS_DIR", help="one sub-folder of person crops per identity")
    p.add_argument("--include", action="append", default=[], metavar="PATTERN",
                   help="only identities whose folder name matches this glob (repeatable)")
    p.add_argument("--exclude", action="append", default=[], metavar="PATTERN",
                   help="leave out identities whose folder name matches this glob (repeatable)")
    p.add_argument("--exclude-scenario", action="append", default=[], type=Path, metavar="DIR",
                   help="leave out the crop identities worn in this face-reid-sim scenario (repeatable): keeps "
                   "the fit independent of the scenarios used to report results")
    p.add_argument("--projection", type=Path, metavar="FILE",
                   help="keep this body projection (what the cameras send) and fit only the metric")
    p.add_argument("--pca-dims", metavar="hsv=N,siltp=N",
                   help="fixed components per block (default: chosen by cross-validation)")
    p.add_argument("--max-length", type=int, default=DEFAULT_MAX_LENGTH,
                   help=f"most projected values per person when the components are chosen (default "
                   f"{DEFAULT_MAX_LENGTH}: {4 * DEFAULT_MAX_LENGTH} bytes of float32)")
    p.add_argument("--folds", type=int, default=3, help="cross-validation folds over the identities (default 3)")
    p.add_argument("--max-negative-pairs", type=int, default=20000, metavar="N",
                   help="at most N different-person pairs per fold for the likelihoods (default 20000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the folds and pair samples (default 0)")
    p.add_argument("--out-dir", type=Path, default=None,
                   help="where the files go (default: the models directory)")
    p.add_argument("--silhouette", type=float, default=CROP_SILHOUETTE, metavar="SHARE",
                   help=f"central share of a crop's columns described as the person, in (0, 1] (default "
                        f"{CROP_SILHOUETTE}: the camera cuts the person out by depth; 1 = every pixel)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = p.parse_args(argv)
    for name, low in (("max_length", 2), ("folds", 2), ("max_negative_pairs", 10), ("seed", 0)):
        if getattr(args, name) < low:
            p.error(f"--{name.replace('_', '-')} must be >= {low}, got {getattr(args, name)}")
    if args.projection is not None and args.pca_dims is not None:
        p.error("--pca-dims and --projection exclude each other (the projection fixes the components)")
    if args.pca_dims is not None:
        try:
            args.pca_dims = parse_pca_dims(args.pca_dims)
        except ValueError as exc:
            p.error(f"--pca-dims: {exc}")
    if args.out_dir is None:
        from face_reid_camera.common.resources import models_dir

        args.out_dir = models_dir()
    return args


def _fail(message: str) -> int:
    print(f"face-reid-fit-body: error: {message}", file=sys.stderr)
    return 2


def _command(args: argparse.Namespace) -> str:
    parts = [args.crops.as_posix()]
    parts += [f"--include '{p}'" for p in args.include]
    parts += [f"--exclude '{p}'" for p in args.exclude]
    parts += [f"--exclude-scenario {d.as_posix()}" for d in args.exclude_scenario]
    if args.projection is not None:
        parts.append(f"--projection {args.projection.as_posix()}")
    if args.pca_dims is not None:
        parts.append("--pca-dims " + ",".join(f"{b}={args.pca_dims[b]}" for b in FEATURES))
    elif args.projection is None and args.max_length != DEFAULT_MAX_LENGTH:
        parts.append(f"--max-length {args.max_length}")
    if args.silhouette != CROP_SILHOUETTE:
        parts.append(f"--silhouette {args.silhouette}")
    parts += [f"--folds {args.folds}", f"--max-negative-pairs {args.max_negative_pairs}", f"--seed {args.seed}"]
    return "face-reid-fit-body " + " ".join(parts)


def _fitted_utc() -> str:
    """SOURCE_DATE_EPOCH (reproducible builds) if set, else now."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    when = _dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc) if epoch else _dt.datetime.now(_dt.timezone.utc)
    return when.isoformat(timespec="seconds")


def _crops_digest(crops: Sequence[Crop], root: Path) -> str:
    """sha256 over the used crops' relative paths and contents, in order."""
    h = hashlib.sha256()
    for c in crops:
        h.update(c.path.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(c.path.read_bytes()).digest())
    return h.hexdigest()


def _data_metadata(args: argparse.Namespace, described: CropDescriptors, excluded: set[str]) -> dict[str, Any]:
    from face_reid_master.tools.fit_likelihood import identity_source

    labels = described.labels
    identities = sorted(set(labels.tolist()))
    by_source: dict[str, list[int]] = {}
    for name in identities:
        by_source.setdefault(identity_source(name), []).append(int(np.count_nonzero(labels == name)))
    return {
        "tool": "face-reid-fit-body",
        "command": _command(args),
        "crops_dir": args.crops.as_posix(),
        "crops_sha256": _crops_digest(described.crops, args.crops),
        "n_identities": len(identities),
        "n_crops": int(labels.size),
        "by_source": {s: {"identities": len(n), "crops": sum(n)} for s, n in sorted(by_source.items())},
        "n_skipped_unreadable": len(described.skipped),
        "excluded": {"patterns": list(args.exclude), "included_patterns": list(args.include),
                     "scenario_crop_identities": sorted(excluded)},
        "identities": identities,
        "descriptor": "face_reid_camera.body.descriptor.body_descriptor, default row-band parts, the central "
                      f"{args.silhouette} of each crop's columns (face_reid_master.training.body.crop_descriptors)",
        "silhouette": args.silhouette,
        "fitted_utc": _fitted_utc(),
    }


def _explained(projection: BodyProjection, described: CropDescriptors) -> dict[str, float]:
    """Share of each block's descriptor variance its kept components hold."""
    out = {}
    for b in projection.blocks:
        x = described.features[b.name].astype(np.float64)
        total = float(((x - x.mean(axis=0)) ** 2).sum())
        kept = float((((x - b.mean) @ b.components.astype(np.float64)) ** 2).sum())
        out[b.name] = round(kept / total, 4) if total > 0 else 0.0
    return out


def plot_fit(fits: dict[str, FeatureFit], path: Path, title: str) -> None:
    """Per feature: histograms of the held-out pair distances, the fitted skew-normals and the N_p = N_n crossing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(fits), 1, figsize=(8, 3.6 * len(fits)), dpi=100, squeeze=False)
    try:
        for ax, (name, fit) in zip(axes[:, 0], fits.items(), strict=True):
            lik, crossing = fit.metric.likelihood, fit.metric.decision_distance
            hi = float(np.quantile(np.concatenate([fit.positive, fit.negative]), 0.995)) * 1.05
            bins = np.linspace(0.0, hi, 71)
            grid = np.linspace(0.0, hi, 600)
            ax.hist(fit.positive, bins=bins, density=True, alpha=0.45, color="tab:blue",
                    label=f"same person (n={fit.positive.size})")
            ax.hist(fit.negative, bins=bins, density=True, alpha=0.45, color="tab:red",
                    label=f"different people (n={fit.negative.size})")
            for sn, colour, label in ((lik.positive, "tab:blue", "$N_p$"), (lik.negative, "tab:red", "$N_n$")):
                ax.plot(grid, sn.pdf(grid), color=colour, lw=2, label=f"{label} skew-normal ($\\alpha$={sn.alpha:.2f}, "
                        f"$\\xi$={sn.xi:.3f}, $\\omega$={sn.omega:.3f})")
            ax.axvline(crossing, color="k", ls="--", lw=1.2, label=f"$N_p = N_n$ at d = {crossing:.3f}")
            r = fit.metric.metric.projection.shape[1]
            ax.set_title(f"{name}: XQDA (r = {r}) on {fit.metric.columns.size} projected values; held-out pairs",
                         fontsize=9)
            ax.set_xlabel("XQDA distance (1 = median different-person distance on the training crops)")
            ax.set_ylabel("density")
            ax.set_xlim(0.0, hi)
            ax.legend(loc="upper right", fontsize=7)
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(str(path), metadata={"Software": None})
    finally:
        plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    """Describe, select, fit and write; 0 on success, 2 on unusable input."""
    args = _parse_args(argv)
    log = None if args.quiet else sys.stderr
    t0 = time.perf_counter()
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(args.seed).spawn(3)]
    try:
        excluded = scenario_clothes(args.exclude_scenario)
        kept_projection = load_body_projection(args.projection) if args.projection is not None else None
        crops = filter_crops(list_crops(args.crops), args.include, args.exclude, excluded)
        described = describe_crops(crops, kept_projection.descriptor_config if kept_projection else None, log,
                                   args.silhouette)
    except (ValueError, FileNotFoundError, ModelLoadError) as exc:
        return _fail(str(exc))
    labels, cameras = described.labels, described.cameras
    n_ids = len(set(labels.tolist()))
    if n_ids < 2 * args.folds:
        return _fail(f"{n_ids} identities: {args.folds} folds need >= {2 * args.folds}")
    print(f"described {labels.size} crops of {n_ids} identities in {time.perf_counter() - t0:.1f} s "
          f"({len(described.skipped)} unreadable skipped, {len(excluded)} scenario crop identities excluded)")
    from face_reid_master.tools.fit_likelihood import file_sha256, identity_source

    groups = np.array([identity_source(n) for n in labels.tolist()])
    try:
        if kept_projection is not None:
            grid = SearchGrid((tuple(b.output_dim for b in kept_projection.blocks),))
            widest = kept_projection
        else:
            pairs = ((tuple(args.pca_dims[b] for b in FEATURES),) if args.pca_dims
                     else dims_candidates(max_length=args.max_length))
            grid = SearchGrid(pairs).capped(labels.size)
            widest = fit_projection(described.features, grid.max_dims(), described.config)
        if tuple(b.name for b in widest.blocks) != FEATURES:
            raise ValueError(f"the projection must have the blocks {FEATURES}, got {[b.name for b in widest.blocks]}")
        scores = widest.project_many(described.features)
        bar = None
        if log:
            from face_reid_camera.faces.photos import progress_bar

            bar = progress_bar(args.folds, "choosing the parameters (folds)", log)
        selection = select_parameters({b: scores[:, s] for b, s in widest.slices().items()}, labels, cameras, grid,
                                      args.folds, streams[0], bar)
        data = _data_metadata(args, described, excluded)
        if kept_projection is not None:
            projection = kept_projection
            projection_info = {"file": args.projection.as_posix(), "sha256": file_sha256(args.projection),
                               "kept": "given by --projection, not refitted"}
        else:
            projection = fit_projection(described.features, selection.pca_dims, described.config)
            projection = BodyProjection(projection.blocks, projection.descriptor_config, {
                **data, "method": "PCA per descriptor block (fit_pca_block) on every crop used",
                "pca_dims": selection.pca_dims,
                "pca_dims_chosen_by": (
                    "--pca-dims" if args.pca_dims else
                    f"{args.folds}-fold cross-validation over the identities: the fused XQDA's rank-1 (every crop a "
                    f"probe against its fold's crops of other cameras), within {args.max_length} values per person"),
                "explained_variance": _explained(projection, described),
                "fused_xqda_cv_rank1_by_pca_dims": {k: round(v, 4) for k, v in selection.fused_by_dims.items()},
            })
            projection_info = {"file": BODY_PROJECTION_FILE, "kept": "fitted in the same run"}
        wire = projection.project_many(described.features)
        folds = identity_folds(labels, args.folds, streams[1])
        fits = fit_feature_metrics(wire, labels, groups, projection.slices(), selection.xqda, folds,
                                   args.max_negative_pairs, streams[2])
        metadata = {
            **data,
            "projection": {**projection_info, "space": projection.space, "length": projection.length},
            "metric": "XQDA per feature on the projected vectors (face_reid_master.training.body.xqda), distances "
                      "divided by the median different-person distance on the training crops",
            "likelihoods": f"skew-normal MLE (face_reid_master.identity.likelihood.fit_skewnormal) on held-out "
                           f"distances: {args.folds} folds of the identities, each measured by XQDA fitted on the "
                           f"other folds; every same-person pair, different-person pairs within one source "
                           f"(folder-name prefix) sampled up to {args.max_negative_pairs} per fold (numpy "
                           f"SeedSequence({args.seed}) stream 2)",
            "selection": {
                "method": f"{args.folds}-fold cross-validation over the identities (numpy SeedSequence({args.seed}) "
                          "stream 0): every crop a probe against its fold's crops of other cameras, rank-1 then "
                          "mAP; components by the fused XQDA, then per feature the regularisation and subspace cap",
                "grid": grid.to_dict(), **selection.to_dict()},
        }
        model = BodyMetricModel(projection.space, projection.length,
                                tuple((n, s.start, s.stop) for n, s in projection.slices().items()),
                                {n: f.metric for n, f in fits.items()}, metadata)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return _fail(f"cannot fit on {args.crops}: {exc}")
    out_dir: Path = args.out_dir
    if kept_projection is None:
        print(f"wrote {save_body_projection(projection, out_dir / BODY_PROJECTION_FILE)}")
    metric_path = save_body_metric(model, out_dir / BODY_METRIC_FILE)
    print(f"wrote {metric_path}")
    shipped = load_body_metric(metric_path)  # what the master will read: report and plot that
    for name in METRIC_FEATURES:
        f = shipped.features[name]
        pos, neg = fits[name].positive, fits[name].negative
        d = f.decision_distance
        print(f"{name}: {f.columns.size} values -> XQDA r={f.metric.projection.shape[1]} (regularisation "
              f"{f.parameters['regularisation']}, cap {f.parameters['max_dims']}); N_p = N_n at d = {d:.4f}: "
              f"{np.mean(pos < d):.3f} of {pos.size} held-out same-person pairs below, {np.mean(neg >= d):.3f} of "
              f"{neg.size} different-person pairs above")
    print(f"projection {projection.space}: {projection.length} float32 values per person "
          f"({', '.join(f'{b.name} {b.output_dim}' for b in projection.blocks)})")
    plot_path = out_dir / PLOT_FILE
    plot_fit({n: FeatureFit(shipped.features[n], fits[n].positive, fits[n].negative) for n in METRIC_FEATURES},
             plot_path, f"{args.crops.resolve().name}: {labels.size} crops of {n_ids} identities")
    print(f"wrote {plot_path} ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
