"""``face-reid-fit-likelihood``: fit the face-distance likelihoods N_p / N_n on a folder of face photos.

Koide et al. 2017, Sec. III-E / Fig. 6: skew-normals fitted by maximum likelihood to L2 distances of
positive (same identity) and negative (different identity) face pairs, here of the embedder actually
used.  ``--camera-views`` fits on what a camera sees (the simulator's degraded views of each photo);
``--fit-min-of-k`` also fits the min-of-K exponents of :class:`~face_reid_master.identity.likelihood.LikelihoodModel`
(off by default: they assume a face's stored features are independent photos).  The command that made
the shipped ``models/face_likelihood.json`` is in its metadata and in the README.

FACES_DIR holds one sub-folder per identity (name = identity).  With ``--same-source-negatives`` the
negative pairs are drawn only between identities of the same source dataset (:func:`identity_source`):
cross-dataset pairs differ also in camera / resolution and are easier, which would bias N_n towards large
distances.  ``--exclude`` / ``--exclude-scenario`` leave identities out (:func:`excluded_from_fit`).
"""

from __future__ import annotations

import argparse
import dataclasses
import fnmatch
import hashlib
import math
import os
import sys
import time
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from face_reid_master.identity.likelihood import (
    LikelihoodModel,
    fit_likelihood_model,
    fit_min_of_k_exponent,
)
from face_reid_master.identity.size_likelihood import FaceLikelihood, save_face_likelihood

__all__ = [
    "MIN_OF_K_VALUES",
    "MinOfKSamples",
    "PairDistances",
    "build_pair_distances",
    "camera_view_draws",
    "excluded_from_fit",
    "file_sha256",
    "identity_source",
    "main",
    "plot_fit",
    "sample_min_of_k_distances",
]

IntArray = npt.NDArray[np.intp]
MIN_OF_K_VALUES: tuple[int, ...] = (1, 2, 3, 5, 7)
MIN_OF_K_QUERIES_PER_K = 3000
NAME_FAR = 1e-3  # naming threshold: this share of the negative pairs (--camera-views: learned faces) is closer
NAME_SPLITS = 5  # random gallery / scene splits of every identity for the face-level naming threshold
NAME_MAX_FEATURES = 50  # a learned face's features in that derivation (the master's max_features_per_face)
_MAX_LISTED_SKIPPED = 100  # skipped file names written into the JSON metadata


def identity_source(identity: str) -> str:
    """Source dataset of an identity folder name: the prefix before the first ``_``; without ``_`` the name
    without its trailing digits (``yaleB10`` -> ``yaleB``), or the whole name if that leaves nothing."""
    if "_" in identity:
        return identity.split("_", 1)[0]
    return identity.rstrip("0123456789") or identity


def excluded_from_fit(identity: str, patterns: Sequence[str], names: Collection[str]) -> bool:
    """True when ``identity`` is one of ``names`` (e.g. a reported scenario's people) or matches a glob."""
    return identity in names or any(fnmatch.fnmatchcase(identity, p) for p in patterns)


def _stack(identities: Mapping[str, npt.ArrayLike]) -> tuple[list[str], npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    names = sorted(identities)
    if len(names) < 2:
        raise ValueError(f"need at least 2 identities with usable photos, got {len(names)}")
    blocks = []
    for name in names:
        arr = np.asarray(identities[name], dtype=np.float64)
        if arr.ndim != 2 or arr.shape[0] < 1 or (blocks and arr.shape[1] != blocks[0].shape[1]):
            raise ValueError(f"embeddings of {name!r} must be (k >= 1, dim) like the others, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"embeddings of {name!r} contain NaN or Inf")
        blocks.append(arr)
    labels = np.concatenate([np.full(len(b), i, dtype=np.intp) for i, b in enumerate(blocks)])
    return names, np.concatenate(blocks), labels


def _distance_matrix(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    sq = np.einsum("ij,ij->i", x, x)
    return np.sqrt(np.maximum(sq[:, None] + sq[None, :] - 2.0 * (x @ x.T), 0.0))


@dataclass(frozen=True)
class PairDistances:
    """L2 distances of all positive pairs and of a sample of negative pairs (of ``n_negative_available``)."""

    positive: npt.NDArray[np.float64]
    negative: npt.NDArray[np.float64]
    n_negative_available: int


def build_pair_distances(
    identities: Mapping[str, npt.ArrayLike],
    max_negative_pairs: int,
    rng: np.random.Generator,
    same_source_negatives: bool = False,
) -> PairDistances:
    """All same-identity pair distances, and a uniform sample without replacement of at most
    ``max_negative_pairs`` different-identity pairs (only same-source ones if ``same_source_negatives``)."""
    if isinstance(max_negative_pairs, bool) or not isinstance(max_negative_pairs, int) or max_negative_pairs < 1:
        raise ValueError(f"max_negative_pairs must be an int >= 1, got {max_negative_pairs!r}")
    names, x, labels = _stack(identities)
    dist = _distance_matrix(x)
    iu, ju, pos_idx, neg_idx, n_available = _sampled_pairs(names, labels, max_negative_pairs, rng,
                                                           same_source_negatives)
    return PairDistances(
        positive=dist[iu[pos_idx], ju[pos_idx]],
        negative=dist[iu[neg_idx], ju[neg_idx]],
        n_negative_available=n_available,
    )


def _sampled_pairs(names: Sequence[str], labels: npt.NDArray[np.intp], max_negative_pairs: int,
                   rng: np.random.Generator, same_source_negatives: bool,
                   ) -> tuple[IntArray, IntArray, IntArray, IntArray, int]:
    """Pairs (i < j) of the stacked photos: (iu, ju, positive pair indices, sampled negative pair indices,
    negatives available); negatives uniformly without replacement, at most ``max_negative_pairs``."""
    iu, ju = np.triu_indices(len(labels), k=1)
    same = labels[iu] == labels[ju]
    negative_ok = ~same
    if same_source_negatives:
        sources = np.array([identity_source(n) for n in names])
        negative_ok &= sources[labels[iu]] == sources[labels[ju]]
    neg_idx = np.flatnonzero(negative_ok)
    n_available = int(neg_idx.size)
    if n_available > max_negative_pairs:
        neg_idx = np.sort(rng.choice(neg_idx, size=max_negative_pairs, replace=False))
    return iu, ju, np.flatnonzero(same), neg_idx, n_available


@dataclass(frozen=True)
class NamingDistances:
    """The naming rule's distance (min over learned x gallery features) for a person's own gallery
    (positive) and for other people's (negative), over random splits of each identity's photos."""

    positive: npt.NDArray[np.float64]
    negative: npt.NDArray[np.float64]

    def threshold(self, far: float) -> float:
        """Distance below which a ``far`` share of the learned faces would take another person's name."""
        return float(np.quantile(self.negative, far))


def naming_distances(views: Mapping[str, npt.NDArray[np.float64]], rng: np.random.Generator,
                     splits: int = NAME_SPLITS, max_features: int = NAME_MAX_FEATURES,
                     same_source_negatives: bool = False) -> NamingDistances:
    """Per identity with >= 3 photos and per split: a third of its photos (at least one) as the gallery (the
    photos themselves, view 0), the camera views of the others as a learned face (at most ``max_features``
    of them); the paper's naming distance of every learned face to every gallery (others: same source only if
    ``same_source_negatives``). ``views[name]``: (photos, views, dim), NaN rows for views without a face."""
    names = sorted(n for n, v in views.items() if v.shape[0] >= 3)
    if len(names) < 2:
        raise ValueError(f"need >= 2 identities with >= 3 photos to derive the naming threshold, got {len(names)}")
    sources = [identity_source(n) for n in names]
    pos: list[float] = []
    neg: list[float] = []
    for _ in range(splits):
        learned, gallery = [], []
        for n in names:
            v = views[n]
            order = rng.permutation(v.shape[0])
            n_gal = max(1, v.shape[0] // 3)
            g = v[order[:n_gal], 0]
            rest = v[order[n_gal:]].reshape(-1, v.shape[2])
            g, rest = g[np.isfinite(g).all(axis=1)], rest[np.isfinite(rest).all(axis=1)]
            if len(rest) > max_features:
                rest = rest[rng.choice(len(rest), max_features, replace=False)]
            learned.append(rest)
            gallery.append(g)
        sq_g = [np.einsum("ij,ij->i", g, g) for g in gallery]
        for i, face in enumerate(learned):
            if not len(face):
                continue
            sq = np.einsum("ij,ij->i", face, face)
            for j, g in enumerate(gallery):
                if not len(g) or (i != j and same_source_negatives and sources[i] != sources[j]):
                    continue
                d2 = sq[:, None] + sq_g[j][None, :] - 2.0 * face @ g.T
                (pos if i == j else neg).append(float(np.sqrt(max(float(d2.min()), 0.0))))
    if len(neg) < 10 or not pos:
        raise ValueError(f"too few learned faces to derive the naming threshold ({len(pos)} own, {len(neg)} other)")
    return NamingDistances(np.array(pos), np.array(neg))


@dataclass(frozen=True)
class MinOfKSamples:
    """min_k distances of queries to K features of the same identity (positive) / another one (negative)."""

    positive: dict[int, npt.NDArray[np.float64]]
    negative: dict[int, npt.NDArray[np.float64]]
    identities: list[str]


def sample_min_of_k_distances(
    identities: Mapping[str, npt.ArrayLike],
    rng: np.random.Generator,
    ks: Sequence[int] = MIN_OF_K_VALUES,
    queries_per_k: int = MIN_OF_K_QUERIES_PER_K,
    same_source_negatives: bool = False,
) -> MinOfKSamples | None:
    """Queries for the min-of-K fit, on the identities with >= max(ks) + 1 photos (the same set for every K).

    Positive: a random photo of identity A vs K other random photos of A.  Negative: a random photo of A
    vs K random photos of another eligible identity B (same source if ``same_source_negatives``).
    None when fewer than two identities are eligible (no exponent can be fitted).
    """
    ks = sorted({int(k) for k in ks})
    if len(ks) < 2 or ks[0] < 1:
        raise ValueError(f"need at least two K values >= 1, got {ks}")
    need = ks[-1] + 1
    eligible = sorted(n for n, e in identities.items() if len(np.asarray(e)) >= need)
    if len(eligible) < 2:
        return None
    names, x, labels = _stack({n: identities[n] for n in eligible})
    dist = _distance_matrix(x)
    n_ids = len(names)
    counts = np.bincount(labels, minlength=n_ids)
    members = np.full((n_ids, int(counts.max())), -1, dtype=np.intp)  # photo indices, -1 padded
    for i in range(n_ids):
        members[i, : counts[i]] = np.flatnonzero(labels == i)
    sources = np.array([identity_source(n) for n in names])
    partner_ok = ~np.eye(n_ids, dtype=bool)
    if same_source_negatives:
        partner_ok &= sources[:, None] == sources[None, :]
    with_partner = np.flatnonzero(partner_ok.any(axis=1))
    if with_partner.size == 0:
        return None
    q = int(queries_per_k)

    def random_members(ids: npt.NDArray[np.intp], n: int) -> npt.NDArray[np.intp]:
        """n distinct random photos of each identity in ``ids`` (random keys, non-members sort last)."""
        keys = rng.random((ids.size, members.shape[1]))
        keys[members[ids] < 0] = np.inf
        return np.take_along_axis(members[ids], np.argsort(keys, axis=1)[:, :n], axis=1)

    def random_partners(ids: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
        keys = rng.random((ids.size, n_ids))
        keys[~partner_ok[ids]] = np.inf
        return np.argmin(keys, axis=1)

    pos: dict[int, npt.NDArray[np.float64]] = {}
    neg: dict[int, npt.NDArray[np.float64]] = {}
    for k in ks:
        chosen = random_members(rng.integers(n_ids, size=q), k + 1)  # query + K others of the same identity
        pos[k] = dist[chosen[:, :1], chosen[:, 1:]].min(axis=1)
        ia = with_partner[rng.integers(with_partner.size, size=q)]
        query = random_members(ia, 1)
        others = random_members(random_partners(ia), k)
        neg[k] = dist[query, others].min(axis=1)
    return MinOfKSamples(pos, neg, list(names))


def camera_view_draws(
    views: Mapping[str, npt.ArrayLike], draws: int, rng: np.random.Generator,
    chosen: list[dict[str, npt.NDArray[np.intp]]] | None = None,
) -> list[dict[str, npt.NDArray[np.float64]]]:
    """``draws`` data sets of one random usable view per photo: ``views[name]`` is (photos, views, dim) with
    NaN rows for views without a detectable face (each photo needs at least one usable view).

    One view per photo per draw keeps same-photo pairs out of the positives: two frames of one photo are
    not two occasions of a person, and would make N_p far too tight. ``chosen`` (a list) receives, per draw,
    the view index taken for every photo.
    """
    if isinstance(draws, bool) or not isinstance(draws, int) or draws < 1:
        raise ValueError(f"draws must be an int >= 1, got {draws!r}")
    arrays = {name: np.asarray(v, dtype=np.float64) for name, v in views.items()}
    usable = {}
    for name, arr in arrays.items():
        if arr.ndim != 3 or arr.shape[0] < 1:
            raise ValueError(f"views of {name!r} must be (photos >= 1, views, dim), got {arr.shape}")
        ok = np.all(np.isfinite(arr), axis=2)
        if not ok.any(axis=1).all():
            raise ValueError(f"every photo of {name!r} needs at least one usable view")
        usable[name] = ok
    out = []
    for _ in range(draws):
        draw = {}
        pick: dict[str, npt.NDArray[np.intp]] = {}
        for name in sorted(arrays):
            keys = np.where(usable[name], rng.random(usable[name].shape), -1.0)  # unusable views never win
            pick[name] = np.argmax(keys, axis=1)
            draw[name] = arrays[name][np.arange(len(keys)), pick[name]]
        out.append(draw)
        if chosen is not None:
            chosen.append(pick)
    return out


def _draw_fit(ax: Any, model: LikelihoodModel, pos: npt.NDArray[np.float64], neg: npt.NDArray[np.float64],
              title: str, hi: float) -> None:
    """Histograms of the pair distances, the fitted skew-normals and the N_p = N_n crossing on ``ax``."""
    crossing = model.decision_distance
    bins = np.linspace(0.0, hi, 71)
    grid = np.linspace(0.0, hi, 600)
    ax.hist(pos, bins=bins, density=True, alpha=0.45, color="tab:blue", label=f"positive pairs (n={pos.size})")
    ax.hist(neg, bins=bins, density=True, alpha=0.45, color="tab:red", label=f"negative pairs (n={neg.size})")
    p, n = model.positive, model.negative
    ax.plot(grid, p.pdf(grid), color="tab:blue", lw=2,
            label=f"$N_p$ skew-normal ($\\alpha$={p.alpha:.2f}, $\\xi$={p.xi:.3f}, $\\omega$={p.omega:.3f})")
    ax.plot(grid, n.pdf(grid), color="tab:red", lw=2,
            label=f"$N_n$ skew-normal ($\\alpha$={n.alpha:.2f}, $\\xi$={n.xi:.3f}, $\\omega$={n.omega:.3f})")
    ax.axvline(crossing, color="k", ls="--", lw=1.2, label=f"$N_p = N_n$ at d = {crossing:.3f}")
    ax.set_xlabel("L2 distance between face embeddings")
    ax.set_ylabel("density")
    ax.set_xlim(0.0, hi)
    ax.set_title(title or "Face-pair distance likelihoods", fontsize=9)
    ax.legend(loc="upper right", fontsize=7)


def size_bucket_distances(
    draw: Mapping[str, npt.ArrayLike], eye_px: Mapping[str, npt.ArrayLike], edges: Sequence[float],
    max_negative_pairs: int, rng: np.random.Generator, same_source_negatives: bool = False,
) -> list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
    """(positive, negative) pair distances per eye-distance bucket of the *query*: every pair counts once for
    the bucket of each of its two faces (the face a camera just saw is compared with whatever a face has
    stored). ``eye_px[name]``: the size of each photo's face in this draw; at most ``max_negative_pairs``
    negatives are sampled (only same-source ones if ``same_source_negatives``)."""
    names, x, labels = _stack(draw)
    size = np.concatenate([np.asarray(eye_px[n], dtype=np.float64).reshape(-1) for n in names])
    if size.shape != (len(x),):
        raise ValueError("eye_px needs one size per photo of every identity")
    bucket = np.searchsorted(np.asarray(edges, dtype=np.float64), size, side="right")
    dist = _distance_matrix(x)
    iu, ju, pos_idx, neg_idx, _ = _sampled_pairs(names, labels, max_negative_pairs, rng, same_source_negatives)
    out = []
    for b in range(len(edges) + 1):
        parts = []
        for idx in (pos_idx, neg_idx):
            d = dist[iu[idx], ju[idx]]
            parts.append(np.concatenate([d[bucket[iu[idx]] == b], d[bucket[ju[idx]] == b]]))
        out.append((parts[0], parts[1]))
    return out


def plot_fit(
    model: LikelihoodModel,
    positive: npt.ArrayLike,
    negative: npt.ArrayLike,
    path: str | Path,
    title: str = "",
    by_size: Sequence[tuple[str, LikelihoodModel, npt.ArrayLike, npt.ArrayLike]] = (),
) -> None:
    """Fig. 6 of the paper: histograms of pair distances, fitted skew-normals and the N_p = N_n crossing;
    with ``by_size`` (label, model, positive, negative) one more panel per face-size bucket.

    matplotlib (Agg backend) is imported here only.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [(title, model, np.asarray(positive, dtype=np.float64), np.asarray(negative, dtype=np.float64))]
    panels += [(label, m, np.asarray(p, dtype=np.float64), np.asarray(n, dtype=np.float64))
               for label, m, p, n in by_size]
    hi = max(1.4, *(float(max(np.max(p), np.max(n))) + 0.05 for _, _, p, n in panels))
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 5.0 * len(panels)), dpi=100, squeeze=False)
    try:
        for ax, (label, m, pos, neg) in zip(axes[:, 0], panels, strict=True):
            _draw_fit(ax, m, pos, neg, label, hi)
        fig.tight_layout()
        fig.savefig(str(path))
    finally:
        plt.close(fig)


def file_sha256(path: Path) -> str:
    """sha256 (hex) of a file, read in chunks."""
    h = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _relative_names(paths: Sequence[Path], root: Path) -> list[str]:
    out = []
    for p in paths:
        try:
            out.append(p.relative_to(root).as_posix())
        except ValueError:
            out.append(p.name)
    return out


def _describe_data(faces_dir: Path, identities: Mapping[str, npt.NDArray[np.float32]]) -> str:
    by_source: dict[str, list[int]] = {}
    for name, emb in identities.items():
        by_source.setdefault(identity_source(name), []).append(len(emb))
    parts = ", ".join(f"{src} {len(n)} ids / {sum(n)} photos" for src, n in sorted(by_source.items()))
    return f"{faces_dir.resolve().name} (by folder-name prefix: {parts}); one (largest) face per photo"


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="face-reid-fit-likelihood",
        description="Fit the skew-normal face-distance likelihoods on a folder of face photos with one "
        "sub-folder per identity, and write them as JSON.",
    )
    parser.add_argument("faces_dir", type=Path, metavar="FACES_DIR", help="folder with one sub-folder per identity")
    parser.add_argument("--out", type=Path, default=None,
                        help="output JSON (default: models/face_likelihood_<space>.json)")
    parser.add_argument("--embedder", choices=("dlib", "sface", "both"), default="dlib",
                        help="the network(s) the photos are embedded with (default dlib)")
    parser.add_argument("--space", default=None,
                        help="the space fitted (default: the embedder's; with --embedder both also dlib_resnet_v1 "
                        "or sface_2021dec, i.e. one half of the joint embeddings)")
    parser.add_argument("--size-buckets", type=str, default="", metavar="PX,PX",
                        help="with --camera-views: also fit N_p / N_n per eye-distance bucket of the query face, "
                        "edges in pixels, e.g. 12,20 (default: the pooled fit only)")
    parser.add_argument("--plot", type=Path, default=None, metavar="PATH.png",
                        help="also save a plot of the distance histograms and fitted densities")
    parser.add_argument("--max-negative-pairs", type=int, default=20000, metavar="N",
                        help="at most N negative pairs per draw, sampled at random (default: 20000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the pair / query sampling (default: 0)")
    parser.add_argument("--same-source-negatives", action="store_true",
                        help="negative pairs only between identities of the same source (folder-name prefix "
                        "before the first '_', or the name without trailing digits)")
    parser.add_argument("--camera-views", type=int, default=0, metavar="DRAWS",
                        help="fit on what a camera sees: each photo also embedded under the simulator's camera "
                        "degradations (lighting, roll, JPEG, 14 / 10 / 9 px eye distance), DRAWS data sets of one "
                        "random view per photo (default 0: the photos as they are)")
    parser.add_argument("--cache", type=Path, default=None, metavar="NPZ",
                        help="with --camera-views: embedding cache shared with face-reid-sim --cache")
    parser.add_argument("--exclude", action="append", default=[], metavar="PATTERN",
                        help="leave out identities whose folder name matches this glob (repeatable), "
                        "e.g. 'celeba_*'")
    parser.add_argument("--exclude-scenario", action="append", default=[], type=Path, metavar="DIR",
                        help="leave out the identities of this face-reid-sim scenario (repeatable): keeps the "
                        "fit independent of the scenarios used to report results")
    parser.add_argument("--fit-min-of-k", action="store_true",
                        help="also fit the min-of-K exponents (assumes the stored features of a face are "
                        "independent photos; default: 0, the paper's pair likelihoods)")
    args = parser.parse_args(argv)
    if args.max_negative_pairs < 1:
        parser.error("--max-negative-pairs must be >= 1")
    if args.seed < 0:
        parser.error("--seed must be >= 0")
    if args.camera_views < 0:
        parser.error("--camera-views must be >= 0")
    if args.cache is not None and not args.camera_views:
        parser.error("--cache needs --camera-views")
    from face_reid_camera.common.embedding_spaces import embedder_space, parse_space

    have = embedder_space(args.embedder)
    args.space = args.space or have
    try:
        wanted = {c.space_id for c in parse_space(args.space)}
    except ValueError as exc:
        parser.error(f"--space: {exc}")
    if not wanted <= {c.space_id for c in parse_space(have)}:
        parser.error(f"--space {args.space} is not part of the {args.embedder} embedder's space {have}")
    try:
        args.size_edges = tuple(float(v) for v in args.size_buckets.split(",") if v.strip())
    except ValueError:
        parser.error(f"--size-buckets must be pixel edges like 12,20, got {args.size_buckets!r}")
    if args.size_edges and not args.camera_views:
        parser.error("--size-buckets needs --camera-views (the sizes come from the camera views)")
    if any(b <= a for a, b in zip((0.0, *args.size_edges), args.size_edges, strict=False)):
        parser.error(f"--size-buckets edges must be positive and increasing, got {args.size_buckets!r}")
    if args.out is None:
        from face_reid_master.identity.size_likelihood import default_likelihood_file

        args.out = Path("models") / default_likelihood_file(args.space)
    return args


def _fail(message: str) -> int:
    print(f"face-reid-fit-likelihood: error: {message}", file=sys.stderr)
    return 2


def _scenario_identities(args: argparse.Namespace) -> set[str]:
    """Names of the identities of the ``--exclude-scenario`` scenarios; ValueError on an unreadable one."""
    from face_reid_master.sim.scenario_files import ScenarioFormatError, load_scenario_document

    names: set[str] = set()
    for directory in args.exclude_scenario:
        try:
            doc = load_scenario_document(directory)
        except ScenarioFormatError as exc:
            raise ValueError(f"--exclude-scenario: {exc}") from None
        names.update(str(i["name"]) for i in doc["identities"])
    return names


@dataclass
class _Embedded:
    """Embeddings of the usable photos, (photos, views, dim) per identity (1 view without --camera-views)."""

    views: dict[str, npt.NDArray[np.float64]]
    skipped_unreadable: list[str]
    skipped_no_face: list[str]
    n_ignored_non_image: int
    embedder_desc: str
    eye_px: dict[str, npt.NDArray[np.float64]] = dataclasses.field(default_factory=dict)  # (photos, views) px

    @property
    def n_photos(self) -> int:
        return sum(len(v) for v in self.views.values())


def _embed(args: argparse.Namespace, keep: Any) -> _Embedded:
    """Embed FACES_DIR (identities for which ``keep(name)`` holds); ValueError on an unusable folder."""
    from face_reid_camera.faces.photos import PhotoEmbedder, progress_bar

    faces_dir: Path = args.faces_dir
    if args.camera_views:
        from face_reid_master.sim.photos import InsufficientFacesError, PhotoBank

        try:
            bank = PhotoBank(faces_dir, args.cache, min_photos_per_identity=1, embedder=args.embedder)
        except InsufficientFacesError as exc:
            raise ValueError(str(exc)) from None
        from face_reid_master.sim.photos import NUM_VARIANTS, variant_eye_px

        names = [n for n in sorted(bank.identity_files) if keep(n)]
        views = {}
        eye_px = {}
        progress = progress_bar(len(names), "embedding identities (camera views)")
        for k, name in enumerate(names):
            ident = bank.load_identity(name)
            if ident is not None:
                views[name] = _in_space(np.stack([p.embeddings for p in ident.photos]).astype(np.float64),
                                        bank.space, args.space)
                eye_px[name] = np.stack([variant_eye_px(p, np.arange(NUM_VARIANTS)) for p in ident.photos])
            progress(k + 1, len(names))
        bank.save_cache()
        return _Embedded(views, list(bank.skipped_unreadable),
                         list(bank.skipped_no_face), bank.ignored_non_image,
                         _embedder_text(bank.photo_embedder, args.space)
                         + "; camera views: face_reid_master.sim.photos PhotoBank variants", eye_px)
    from face_reid_camera.faces.embedder import load_embedder

    embedder = PhotoEmbedder(embedder=load_embedder(args.embedder))
    folder = embedder.embed_folder_tree(faces_dir, progress_bar(0, "embedding photos"))
    views = {name: _in_space(np.stack([e.embedding for e in embs])[:, None, :].astype(np.float64),
                             embedder.embedder.space, args.space)
             for name, embs in folder.identities.items() if keep(name)}

    def kept(paths: list[Path]) -> list[Path]:  # skipped files of excluded identities are not reported
        return [p for p in paths if keep(p.parent.name)]

    return _Embedded(views, _relative_names(kept(folder.skipped_unreadable), faces_dir),
                     _relative_names(kept(folder.skipped_no_face), faces_dir), len(folder.ignored_non_image),
                     _embedder_text(embedder, args.space))


def _components(space: str) -> tuple[Any, ...]:
    from face_reid_camera.common.embedding_spaces import parse_space

    return parse_space(space)


def _component_weights(draw: Mapping[str, npt.NDArray[np.float64]], space: str, max_negative_pairs: int,
                       rng: np.random.Generator, same_source: bool) -> tuple[float, ...]:
    """Joint spaces: 1 / median negative-pair distance of each component, so both networks count alike
    (empty for a single network)."""
    parts = _components(space)
    if len(parts) < 2:
        return ()
    out, start = [], 0
    for part in parts:
        sub = {n: v[:, start: start + part.dim] for n, v in draw.items()}
        start += part.dim
        neg = build_pair_distances(sub, max_negative_pairs, rng, same_source).negative
        out.append(round(1.0 / float(np.median(neg)), 4))
    return tuple(out)


def _in_space(views: npt.NDArray[np.float64], have: str, want: str) -> npt.NDArray[np.float64]:
    """The ``want`` part of embeddings of space ``have`` (last axis)."""
    from face_reid_camera.common.embedding_spaces import extract_space

    part = extract_space(views, have, want)
    if part is None:  # checked by the argument parser
        raise ValueError(f"space {want!r} is not part of {have!r}")
    return np.ascontiguousarray(part)


def _embedder_text(photo_embedder: Any, space: str) -> str:
    from face_reid_camera.common.embedding_spaces import SPACES, parse_space

    parts = photo_embedder.embedder.embedders if hasattr(photo_embedder.embedder, "embedders") \
        else (photo_embedder.embedder,)
    nets = "; ".join(f"{SPACES[e.space].description} run as models/{e.model_path.name} (sha256 "
                     f"{file_sha256(e.model_path)}), aligned to its {e.spec.chip_size_px}x{e.spec.chip_size_px} chip "
                     "template" for e in parts if e.space in {c.space_id for c in parse_space(space)})
    return (
        f"space {space}: {nets}; face detection: YuNet 2023mar (face_reid_camera.faces.detector, on photos shrunk "
        f"to <= {photo_embedder.max_side_px} px), 5 landmarks of the largest face -> similarity transform "
        "(face_reid_camera.faces.photos.PhotoEmbedder)"
    )


def _command(args: argparse.Namespace) -> str:
    parts = [args.faces_dir.as_posix(), f"--max-negative-pairs {args.max_negative_pairs}", f"--seed {args.seed}"]
    if args.same_source_negatives:
        parts.append("--same-source-negatives")
    if args.camera_views:
        parts.append(f"--camera-views {args.camera_views}")
    parts += [f"--exclude '{p}'" for p in args.exclude]
    parts += [f"--exclude-scenario {d.as_posix()}" for d in args.exclude_scenario]
    if args.fit_min_of_k:
        parts.append("--fit-min-of-k")
    if args.embedder != "dlib":
        parts.append(f"--embedder {args.embedder}")
    from face_reid_camera.common.embedding_spaces import embedder_space

    if args.space != embedder_space(args.embedder):
        parts.append(f"--space {args.space}")
    if args.size_edges:
        parts.append(f"--size-buckets {','.join(f'{e:g}' for e in args.size_edges)}")
    return "face-reid-fit-likelihood " + " ".join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """Embed FACES_DIR, fit, write the JSON (and plot); 0 on success, 2 on an unusable folder / fit."""
    args = _parse_args(argv)
    faces_dir: Path = args.faces_dir
    patterns: list[str] = list(args.exclude)
    try:
        scenario_names = _scenario_identities(args)
    except ValueError as exc:
        return _fail(str(exc))

    def keep(name: str) -> bool:
        return not excluded_from_fit(name, patterns, scenario_names)

    t0 = time.perf_counter()
    try:
        emb = _embed(args, keep)
    except ValueError as exc:
        return _fail(str(exc))
    n_unread, n_noface = len(emb.skipped_unreadable), len(emb.skipped_no_face)
    print(
        f"embedded {emb.n_photos} photos of {len(emb.views)} identities in {time.perf_counter() - t0:.1f} s "
        f"({len(scenario_names)} scenario identities and {len(patterns)} patterns excluded); skipped {n_unread} "
        f"unreadable, {n_noface} without a detectable face; ignored {emb.n_ignored_non_image} non-image files"
    )
    for p in emb.skipped_unreadable:
        print(f"  unreadable: {p}", file=sys.stderr)
    for p in emb.skipped_no_face:
        print(f"  no face: {p}", file=sys.stderr)

    pair_rng, k_rng, size_rng, name_rng = (np.random.default_rng(s)
                                           for s in np.random.SeedSequence(args.seed).spawn(4))
    same_source = bool(args.same_source_negatives)
    try:
        chosen: list[dict[str, npt.NDArray[np.intp]]] = []
        draws = (camera_view_draws(emb.views, args.camera_views, pair_rng, chosen) if args.camera_views
                 else [{n: v[:, 0] for n, v in emb.views.items()}])
        weights = _component_weights(draws[0], args.space, args.max_negative_pairs, size_rng, same_source)
        if weights:
            scale = np.concatenate([np.full(c.dim, w) for c, w in zip(_components(args.space), weights, strict=True)])
            draws = [{n: v * scale for n, v in d.items()} for d in draws]
        pair_sets = [build_pair_distances(d, args.max_negative_pairs, pair_rng, same_source) for d in draws]
        positive = np.concatenate([p.positive for p in pair_sets])
        negative = np.concatenate([p.negative for p in pair_sets])
        if positive.size < 10 or negative.size < 10:
            raise ValueError(
                f"too few pairs to fit ({positive.size} positive, {negative.size} negative; need "
                ">= 10 each): add identities with several photos each"
            )
        neg_desc = "different-identity pairs" + (
            " within the same source dataset (folder-name prefix before '_' or the name without trailing digits; "
            "cross-dataset pairs are easier and would bias N_n to larger distances)" if same_source else ""
        )
        view_desc = (
            f"; {args.camera_views} draws of one random camera view per photo (the photo or a simulated camera "
            "degradation of it: darker / brighter, +-8 deg roll, JPEG 35, 14 / 10 / 9 px eye distance)"
            if args.camera_views else ""
        )
        metadata: dict[str, Any] = {
            "embedder": emb.embedder_desc,
            "distance": (f"L2 between the {args.space} embeddings" + (
                f", each component scaled by its weight {list(weights)} (1 / its median negative-pair distance)"
                if weights else "")),
            "data": _describe_data(faces_dir, emb.views) + view_desc,
            "n_identities": len(emb.views),
            "identities": sorted(emb.views),
            "n_images": emb.n_photos,
            "n_skipped_unreadable": n_unread,
            "n_skipped_no_face": n_noface,
            "skipped_unreadable": emb.skipped_unreadable[:_MAX_LISTED_SKIPPED],
            "skipped_no_face": emb.skipped_no_face[:_MAX_LISTED_SKIPPED],
            "excluded": {"patterns": patterns, "scenario_identities": sorted(scenario_names)},
            "positive_pairs": "all same-identity pairs of different photos" + (" in every draw" if args.camera_views
                                                                               else ""),
            "negative_pairs": (
                f"{neg_desc}; seeded random sample (numpy SeedSequence({args.seed}), stream 0) of at most "
                f"{args.max_negative_pairs} of {pair_sets[0].n_negative_available} available"
                + (" per draw" if args.camera_views else "")
            ),
            "command": _command(args),
        }
        model = fit_likelihood_model(positive, negative, metadata=metadata)
    except ValueError as exc:
        return _fail(f"cannot fit the likelihoods on {faces_dir}: {exc}")

    e_pos = e_neg = 0.0
    k_desc = ("not fitted: 0 = the paper's plain pair likelihoods (the stored features of a face are frames of a "
              "few glances, far from independent; see README)")
    if args.fit_min_of_k:
        samples = [sample_min_of_k_distances(d, k_rng, same_source_negatives=same_source) for d in draws]
        usable = [x for x in samples if x is not None]
        if not usable:
            k_desc = (f"not fitted: fewer than 2 identities with >= {max(MIN_OF_K_VALUES) + 1} photos; 0 = the "
                      "paper's plain pair likelihoods")
            print(f"warning: min-of-K exponents set to 0 ({k_desc})", file=sys.stderr)
        else:
            pos_k = {k: np.concatenate([x.positive[k] for x in usable]) for k in usable[0].positive}
            neg_k = {k: np.concatenate([x.negative[k] for x in usable]) for k in usable[0].negative}
            e_pos = round(fit_min_of_k_exponent(pos_k, model.positive), 3)
            e_neg = round(fit_min_of_k_exponent(neg_k, model.negative), 3)
            k_desc = (
                f"K_eff = K**e for eq. 4's minimum over K stored features: e fitted (scipy L-BFGS-B MLE of s*K**e) "
                f"on {MIN_OF_K_QUERIES_PER_K} queries per K in {tuple(MIN_OF_K_VALUES)} per draw, "
                f"{len(usable[0].identities)} identities with >= {max(MIN_OF_K_VALUES) + 1} photos, negatives "
                f"{'from the same source' if same_source else 'from any other identity'}, numpy SeedSequence("
                f"{args.seed}) stream 1. Set both to 0 for the paper's plain pair likelihoods."
            )
    try:
        model = dataclasses.replace(
            model,
            k_exponent_positive=e_pos,
            k_exponent_negative=e_neg,
            metadata={**model.metadata, "min_of_k_exponents": k_desc},
        )
    except ValueError as exc:
        return _fail(f"fitted model is unusable: {exc}")

    by_size: list[tuple[str, LikelihoodModel, npt.NDArray[np.float64], npt.NDArray[np.float64]]] = []
    edges: tuple[float, ...] = args.size_edges
    try:
        if edges:
            per_draw = [size_bucket_distances(d, {n: emb.eye_px[n][np.arange(len(c[n])), c[n]] for n in d}, edges,
                                              args.max_negative_pairs, size_rng, same_source)
                        for d, c in zip(draws, chosen, strict=True)]
            bounds = (0.0, *edges, math.inf)
            for b in range(len(edges) + 1):
                pos_b = np.concatenate([x[b][0] for x in per_draw])
                neg_b = np.concatenate([x[b][1] for x in per_draw])
                if pos_b.size < 10 or neg_b.size < 10:
                    raise ValueError(f"eye-distance bucket [{bounds[b]:g}, {bounds[b + 1]:g}) px has only "
                                     f"{pos_b.size} positive / {neg_b.size} negative pairs: choose other edges")
                fit_b = fit_likelihood_model(pos_b, neg_b)
                by_size.append((f"query face eye distance [{bounds[b]:g}, {bounds[b + 1]:g}) px", fit_b, pos_b, neg_b))
    except ValueError as exc:
        return _fail(f"cannot fit the size buckets: {exc}")
    # derived on the same data: the threshold method's distance (N_p = N_n) and the naming distance at a false
    # name rate of 1e-3: of learned faces (camera views) against galleries, or else of photo pairs
    naming = None
    if args.camera_views:
        scaled = {n: v * scale for n, v in emb.views.items()} if weights else emb.views
        try:
            naming = naming_distances(scaled, name_rng, same_source_negatives=same_source)
        except ValueError as exc:
            return _fail(f"cannot derive the naming threshold: {exc}")
    name_threshold = round(naming.threshold(NAME_FAR) if naming else float(np.quantile(negative, NAME_FAR)), 4)
    threshold_distance = round(model.decision_distance, 4)
    metadata = {**model.metadata, "size_buckets": (
        f"N_p / N_n per eye-distance bucket of the query face, edges {list(edges)} px: every pair of a draw counts "
        "for the bucket of each of its two faces; negatives sampled per draw like the pooled fit (numpy "
        f"SeedSequence({args.seed}) stream 2)") if edges else "none (pooled fit only)",
        "thresholds": "threshold_distance = pooled N_p = N_n distance; name_threshold = " + (
            f"the {NAME_FAR:g} quantile of the naming rule's distance (min over feature pairs) from learned faces "
            f"(<= {NAME_MAX_FEATURES} camera views of two thirds of an identity's photos) to other identities' "
            f"galleries (the other third, as photos){', same source' if same_source else ''}: {NAME_SPLITS} random "
            f"splits, numpy SeedSequence({args.seed}) stream 3, {naming.negative.size} other / {naming.positive.size} "
            "own learned-face-gallery pairs" if naming else
            f"the {NAME_FAR:g} quantile of the pooled negative pair distances (pair false-accept rate {NAME_FAR:g})")}
    face_model = FaceLikelihood(
        dataclasses.replace(model, metadata=metadata), args.space, edges, tuple(m for _, m, _, _ in by_size),
        weights, name_threshold, threshold_distance, metadata)

    out: Path = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")  # written whole, then renamed over the old file
    try:
        save_face_likelihood(face_model, tmp)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)

    crossing = model.decision_distance
    p, n = model.positive, model.negative
    print(f"positive pairs {positive.size}, negative pairs {negative.size} "
          f"(of {pair_sets[0].n_negative_available} available{' per draw' if args.camera_views else ''})")
    print(f"N_p: alpha={p.alpha:.4f} xi={p.xi:.4f} omega={p.omega:.4f}; "
          f"N_n: alpha={n.alpha:.4f} xi={n.xi:.4f} omega={n.omega:.4f}")
    print(f"min-of-K exponents: positive {e_pos}, negative {e_neg}")
    for label, m, pos_b, neg_b in by_size:
        print(f"  {label}: {pos_b.size} positive / {neg_b.size} negative pairs, N_p = N_n at d = "
              f"{m.decision_distance:.4f}, positive median {np.median(pos_b):.4f}")
    if naming:
        print(f"naming: {naming.negative.size} other / {naming.positive.size} own learned-face-gallery pairs; at "
              f"name_threshold {name_threshold} {np.mean(naming.positive < name_threshold):.3f} of own galleries "
              "are within reach")
    print(f"derived: threshold_distance {threshold_distance}, name_threshold {name_threshold}"
          + (f", component weights {list(weights)}" if weights else ""))
    pos_ok = float(np.mean(positive < crossing))
    neg_ok = float(np.mean(negative >= crossing))
    print(f"N_p = N_n at d = {crossing:.4f}: {pos_ok:.3f} of positive pairs below, {neg_ok:.3f} of negative "
          "pairs above")
    print(f"wrote {out}")
    if args.plot is not None:
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        title = (f"{faces_dir.resolve().name}: {emb.n_photos} photos, {len(emb.views)} identities"
                 f"{', camera views' if args.camera_views else ''} (balanced pair accuracy "
                 f"{0.5 * (pos_ok + neg_ok):.3f})")
        plot_fit(model, positive, negative, args.plot, title=title, by_size=by_size)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
