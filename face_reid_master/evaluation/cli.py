"""``face-reid-eval``: run the master core on a recorded scenario and print the paper's metrics as JSON.

Example: ``face-reid-eval S --method bayes --plot S/bayes`` after ``face-reid-sim ... --out S``.
The metrics are defined in ``docs/evaluation.md, "What is counted"`` (computed by
:mod:`face_reid_master.evaluation.metrics` from a run of :mod:`face_reid_master.evaluation.runner`).
One JSON object goes to stdout (and to ``--out``); progress to stderr. ``--live`` replays the scenario
through the real master node over DDS instead (:mod:`face_reid_master.evaluation.live`). Exit status: 0 done,
2 bad arguments / unreadable scenario, 1 other errors (e.g. missing models, the master node failed),
130 interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from face_reid_camera.common.errors import ModelLoadError
from face_reid_master.body.metric_file import BodyMetricModel, default_body_metric, load_body_metric
from face_reid_master.core import MasterConfig
from face_reid_master.evaluation.body_rank import scenario_bodies, scenario_rank1
from face_reid_master.evaluation.gallery import GalleryInfo, default_gallery_people, scenario_gallery
from face_reid_master.evaluation.metrics import evaluate_run, paired_reid_times
from face_reid_master.evaluation.oracle_check import body_separation, oracle_check
from face_reid_master.evaluation.plots import save_plots
from face_reid_master.evaluation.protocol import ProtocolCheck, check_protocol
from face_reid_master.evaluation.runner import DEFAULT_TICK_PERIOD_S, RunLog, progress_to, run_master
from face_reid_master.identity.confidence_map import ConfidenceMap, default_confidence_map, load_confidence_map
from face_reid_master.identity.size_likelihood import FaceLikelihood, default_face_likelihood, load_face_likelihood

_IDENTITY_FIELDS = {
    "bayes": ("posterior_threshold", "prior_probability", "min_observations", "new_person_scale_c",
              "max_features_per_face", "learn_only_consistent_features",
              "release_after_inconsistent"),
    "threshold": ("threshold_distance", "threshold_votes", "max_features_per_face", "learn_only_consistent_features",
                  "release_after_inconsistent"),
}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="face-reid-eval",
        description="Evaluate people re-identification on a scenario written by face-reid-sim: tracks "
                    "re-identified successfully / wrongly, re-identification time, recover rate, names of "
                    "predefined people, IDF1 / MOTA (definitions: docs/evaluation.md, 'What is counted').",
    )
    p.add_argument("scenario", type=Path, metavar="SCENARIO_DIR", help="directory written by face-reid-sim")
    p.add_argument("--method", choices=("bayes", "threshold", "both"), default="bayes",
                   help="face classification: the paper's Bayesian inference (default) or the threshold baseline; "
                        "both: run each (offline) and compare their re-identification times on the same tracks")
    p.add_argument("--gallery-people", type=int, default=None, metavar="K",
                   help="predefined people: K day-1 identities (default: half of them; 0 = no gallery), each "
                        "with the photos of their folder the scenario did not use")
    p.add_argument("--faces", type=Path, default=None,
                   help="faces folder for the gallery photos (default: the one recorded in scenario.json)")
    p.add_argument("--tick-period", type=float, default=DEFAULT_TICK_PERIOD_S, metavar="S",
                   help=f"core.tick period between frames, scenario seconds (default {DEFAULT_TICK_PERIOD_S})")
    p.add_argument("--plot", type=str, default=None, metavar="PREFIX",
                   help="save PREFIX_timeline.png, PREFIX_map.png and PREFIX_reliability.png")
    p.add_argument("--out", type=Path, default=None, metavar="JSON", help="also write the JSON to this file")
    p.add_argument("--likelihood", type=Path, default=None, metavar="JSON",
                   help="the fitted likelihoods to use (default: models/face_likelihood_<space>.json); "
                   "see face-reid-fit-likelihood")
    p.add_argument("--body-metric", type=Path, default=None, metavar="JSON",
                   help="the body metric to use (default: the shipped models/body_metric.json); see face-reid-fit-body")
    p.add_argument("--confidence-map", type=str, default=None, metavar="JSON",
                   help="the map from decision posteriors to identity_confidence (default: the shipped "
                        "models/identity_confidence.json; 'raw': the posteriors themselves, what a map is fitted on)")
    p.add_argument("--allow-fitted", action="store_true",
                   help="evaluate although a loaded model was fitted on the scenario's people (or does not say what "
                        "it saw): the result is marked \"honest\": false (default: refused, exit status 3)")
    p.add_argument("--space", default=None, metavar="SPACE",
                   help="embedder space the master compares (default: the scenario's); a scenario simulated with "
                        "both embedders serves dlib_resnet_v1, sface_2021dec and dlib_resnet_v1+sface_2021dec")
    p.add_argument("--pooled-likelihood", action="store_true",
                   help="judge every face by the pooled likelihood, ignoring the face-size buckets")
    p.add_argument("--evidence", choices=("face", "body", "fused"), default="fused",
                   help="fused (default): bodies (where the scenario has them) steer the tracker's association "
                        "(body_appearance_tracking) and name tracks that show no face (body_identity); body: "
                        "bodies for the tracker only; face: positions and faces only, as before bodies")
    p.add_argument("--no-mot", action="store_true", help="skip the motmetrics IDF1 / MOTA (saves time)")
    p.add_argument("--live", action="store_true",
                   help="run the whole DDS pipeline instead of the core: a master node process (temporary face "
                        "database, the same gallery, --method) gets the recorded camera frames as CameraFrame "
                        "messages in real time (takes the scenario's duration); metrics from what it publishes "
                        "on /tracks_named (each track attributed to the nearest true person; no MOT metrics). "
                        "Later days are replayed after a 5 s pause with the master kept running")
    p.add_argument("--domain-id", type=int, default=None,
                   help="--live: ROS_DOMAIN_ID of the run, 0..232 (default: the environment's ROS_DOMAIN_ID, else "
                        "random in 1..100; discovery on localhost only)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return p


def _protocol(args: argparse.Namespace, document: dict[str, Any], model: FaceLikelihood,
              body_metric: BodyMetricModel | None, cmap: ConfidenceMap) -> ProtocolCheck:
    """Which loaded model saw the scenario's people (the body metric only when bodies are evaluated)."""
    face_source = str(args.likelihood) if args.likelihood is not None else f"shipped likelihoods of {model.space}"
    map_source = str(args.confidence_map) if args.confidence_map is not None else "shipped confidence map"
    metric_meta, metric_source = None, ""
    if args.evidence != "face" and document.get("body_space") is not None:
        metric_meta = (body_metric or default_body_metric()).metadata
        metric_source = str(args.body_metric) if args.body_metric is not None else "shipped models/body_metric.json"
    return check_protocol(document, model.metadata, face_source, metric_meta, metric_source, cmap.metadata,
                          map_source)


def _scenario_json(scenario: Any) -> dict[str, Any]:
    doc = scenario.document
    summary = scenario.summary
    return {
        "directory": str(scenario.directory),
        "level": scenario.level,
        "seed": scenario.seed,
        "days": len(scenario.days),
        "people_per_day": summary.get("people_per_day"),
        "identities": len(scenario.identities),
        "cameras": len(scenario.cameras),
        "duration_s": summary.get("duration_s"),
        "frames": summary.get("frames"),
        "detections": summary.get("detections"),
        "face_detections": summary.get("face_detections"),
        "gt_losses": summary.get("losses"),
        "gt_visible_segments": summary.get("visible_segments"),
        "faces_dir": doc.get("faces_dir"),
        "embedding_space": doc.get("embedding_space", "dlib_resnet_v1"),
        "bodies": doc.get("body_space") is not None,
        "body_space": doc.get("body_space"),
        **({"oracle": True, "oracle_noise_std": (doc.get("oracle_evidence") or {}).get("noise_std")}
           if doc.get("oracle") else {}),
    }


def _parameters(config: MasterConfig, likelihood: FaceLikelihood, tick_period_s: float) -> dict[str, Any]:
    out: dict[str, Any] = {k: getattr(config, k) for k in _IDENTITY_FIELDS[config.method]}
    out["embedding_space"] = config.embedding_space
    out["name_threshold"] = config.name_threshold or likelihood.name_threshold
    if config.method == "threshold":
        out["threshold_distance"] = config.threshold_distance or likelihood.threshold_distance
    out["likelihood_size_buckets"] = list(likelihood.eye_px_edges) if likelihood.conditioned else "pooled"
    out["tick_period_s"] = tick_period_s
    out["evidence"] = ("fused" if config.body_identity else "body") if config.body_appearance_tracking else "face"
    out["body_appearance_tracking"] = config.body_appearance_tracking
    out["body"] = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name.startswith("body_")}
    out["tracker"] = dataclasses.asdict(config.tracker)
    if config.method == "bayes":
        out["likelihood_data"] = likelihood.metadata.get("data", "")
        out["likelihood_command"] = likelihood.metadata.get("command", "")
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Run the evaluation; returns the exit status."""
    parser = _parser()
    args = parser.parse_args(list(argv) if argv is not None else None)
    log = None if args.quiet else sys.stderr
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        print(f"face-reid-eval: error: --domain-id must be in 0..232, got {args.domain_id}", file=sys.stderr)
        return 2
    if args.live and args.confidence_map == "raw":
        print("face-reid-eval: error: --confidence-map raw is offline only (the live master publishes through a map "
              "file)", file=sys.stderr)
        return 2
    if args.live and args.method != "bayes":
        print("face-reid-eval: error: --live runs the master node, which uses the Bayesian table: the threshold "
              "baseline runs offline (without --live)", file=sys.stderr)
        return 2
    if not (math.isfinite(args.tick_period) and args.tick_period > 0):
        print(f"face-reid-eval: error: --tick-period must be > 0 s, got {args.tick_period}", file=sys.stderr)
        return 2
    from face_reid_master.sim.scenario_files import ScenarioFormatError, load_scenario, load_scenario_document

    try:
        space = args.space or str(load_scenario_document(args.scenario).get("embedding_space", "dlib_resnet_v1"))
    except ScenarioFormatError as exc:
        print(f"face-reid-eval: error: {exc}", file=sys.stderr)
        return 2
    try:
        model = default_face_likelihood(space) if args.likelihood is None else load_face_likelihood(args.likelihood)
        if model.space != space:
            raise ValueError(f"{args.likelihood} is fitted for space {model.space!r}, the master compares {space!r}")
    except (OSError, ValueError) as exc:
        print(f"face-reid-eval: error: --likelihood: {exc}", file=sys.stderr)
        return 2
    if args.pooled_likelihood:
        model = model.pooled_only()
    missing = [name for name, needed in (("name_threshold", args.gallery_people != 0),
                                         ("threshold_distance", args.method in ("threshold", "both")))
               if needed and getattr(model, name) is None]
    if missing:
        print(f"face-reid-eval: error: --likelihood: {args.likelihood or 'the shipped fit'} derives no "
              f"{' / '.join(missing)} (a version-1 file?): refit with face-reid-fit-likelihood", file=sys.stderr)
        return 2

    try:
        body_metric = None if args.body_metric is None else load_body_metric(args.body_metric)
    except (OSError, ValueError, ModelLoadError) as exc:
        print(f"face-reid-eval: error: --body-metric: {exc}", file=sys.stderr)
        return 2
    try:
        cmap = (default_confidence_map() if args.confidence_map is None else ConfidenceMap.identity()
                if args.confidence_map == "raw" else load_confidence_map(args.confidence_map))
    except (OSError, ValueError, ModelLoadError) as exc:
        print(f"face-reid-eval: error: --confidence-map: {exc}", file=sys.stderr)
        return 2

    t0 = time.perf_counter()
    try:
        scenario = load_scenario(args.scenario)
    except ScenarioFormatError as exc:
        print(f"face-reid-eval: error: {exc}", file=sys.stderr)
        return 2
    protocol = _protocol(args, scenario.document, model, body_metric, cmap)
    if not protocol.honest:
        lines = "\n".join(f"  - {p}" for p in protocol.problems())
        if not args.allow_fitted:
            print(f"face-reid-eval: error: {args.scenario} is not an honest test of the loaded models:\n{lines}\n"
                  "evaluate people no fitted model has seen (docs/evaluation.md, 'Honest evaluation'), or pass "
                  "--allow-fitted to evaluate anyway (the result is marked \"honest\": false)", file=sys.stderr)
            return 3
        print(f"face-reid-eval: WARNING: NOT AN HONEST TEST: the loaded models saw this scenario's people:\n{lines}",
              file=sys.stderr)
    if log:
        print(f"loaded {args.scenario}: {len(scenario.frames)} frames in {time.perf_counter() - t0:.1f} s", file=log)
    try:
        gallery_ids = default_gallery_people(scenario.document, args.gallery_people)
    except ValueError as exc:
        print(f"face-reid-eval: error: --gallery-people: {exc}", file=sys.stderr)
        return 2
    t1 = time.perf_counter()
    gallery = scenario_gallery(scenario.document, scenario.directory, gallery_ids, faces_dir=args.faces, log=log,
                               space=space) \
        if gallery_ids else GalleryInfo({}, {}, {}, [], skipped="--gallery-people 0")
    if gallery.skipped and gallery_ids and log:
        print(f"gallery skipped: {gallery.skipped}", file=log)
    if log and gallery.people:
        print(f"gallery of {len(gallery.people)} people built in {time.perf_counter() - t1:.1f} s", file=log)

    days = scenario.day_spans
    if args.method == "both":
        runs = {m: _run_offline(args, m, scenario, gallery, days, log, model, body_metric, cmap)
                for m in ("bayes", "threshold")}
        result = {"scenario": runs["bayes"][0].pop("scenario"), "method": "both"}
        for m, (res, _) in runs.items():
            res.pop("scenario", None)
            result[m] = res
        result["paired"] = paired_reid_times(runs["bayes"][1], runs["threshold"][1], ("bayes", "threshold"))
    else:
        config = _config(args, args.method, space)
        if args.live:
            return _main_live(args, scenario, gallery, config, model, days, t0, log, protocol)
        result = _run_offline(args, args.method, scenario, gallery, days, log, model, body_metric, cmap)[0]
    result["protocol"] = protocol.as_json()
    result["total_time_s"] = round(time.perf_counter() - t0, 2)
    _emit(result, args.out)
    return 0


def _config(args: argparse.Namespace, method: str, space: str) -> MasterConfig:
    """The master configuration the evaluation's options ask for."""
    return MasterConfig(method=method, embedding_space=space, body_appearance_tracking=args.evidence != "face",
                        body_identity=args.evidence == "fused")


def _body_metric_json(run: RunLog, scenario: Any, days: list[tuple[int, float, float, list[int]]],
                      loaded: BodyMetricModel | None) -> dict[str, Any] | None:
    """Rank-1 of the body metric in use (``loaded``, else the shipped one) on the scenario's bodies."""
    if run.body_metric is None:  # bodies were not used
        return None
    base = loaded or default_body_metric()
    bodies = scenario_bodies(scenario.frames, scenario.frame_gt_ids, base.space, days)
    if not bodies.labels.size:
        return None
    return {"bodies": int(bodies.labels.size), "rank1": scenario_rank1(bodies, base.features["fused"])}


def _oracle_bodies(run: RunLog, scenario: Any, days: list[tuple[int, float, float, list[int]]],
                   loaded: BodyMetricModel | None) -> dict[str, Any] | None:
    """How far apart an oracle scenario's bodies are in the fused body metric in use (None: bodies not used)."""
    if run.body_metric is None:
        return None
    base = loaded or default_body_metric()
    return body_separation(scenario_bodies(scenario.frames, scenario.frame_gt_ids, base.space, days),
                           base.features["fused"])


def _run_offline(args: argparse.Namespace, method: str, scenario: Any, gallery: GalleryInfo,
                 days: list[tuple[int, float, float, list[int]]], log: Any,
                 model: FaceLikelihood, body_metric: BodyMetricModel | None = None,
                 cmap: ConfidenceMap | None = None) -> tuple[dict[str, Any], RunLog]:
    """The master core with ``method`` (and ``model``: likelihoods, weights, thresholds) over the scenario;
    (the JSON-ready metrics, the run's log)."""
    config = _config(args, method, model.space)
    likelihood = model
    if log:
        print(f"running the master core ({method}) over {len(scenario.frames)} frames", file=log)
    run = run_master(scenario.frames, scenario.frame_gt_ids, config, likelihood=likelihood, body_metric=body_metric,
                     confidence_map=cmap,
                     gallery=gallery.people or None, tick_period_s=args.tick_period, days=days,
                     progress=progress_to(log) if log else None)
    if log:
        print(f"core done in {run.runtime_s:.1f} s; computing metrics", file=log)
    metrics = evaluate_run(run, gallery_people=gallery.gt_of_name or None, scenario_summary=scenario.summary,
                           with_mot=not args.no_mot)
    result: dict[str, Any] = {
        "scenario": _scenario_json(scenario),
        "method": method,
        "parameters": _parameters(config, likelihood, args.tick_period),
        "gallery": gallery.as_json(),
        "confidence_map": "raw" if cmap is not None and cmap.raw else str(args.confidence_map or "shipped"),
        **{k: v for k, v in metrics.items() if k != "method"},
    }
    body_json = _body_metric_json(run, scenario, days, body_metric)
    if body_json is not None:
        result["body_metric"] = body_json
    oracle = oracle_check(scenario.document, scenario.frames, scenario.frame_gt_ids, likelihood,
                          config.name_threshold or likelihood.name_threshold,
                          _oracle_bodies(run, scenario, days, body_metric) if scenario.document.get("oracle") else None)
    if oracle is not None:  # an oracle-evidence scenario: how far apart its people are against the decisions
        result["oracle"] = oracle
    if args.plot:
        t2 = time.perf_counter()
        prefix = args.plot if args.method != "both" else f"{args.plot}_{method}"
        paths = save_plots(run, scenario, prefix, title=f"{args.scenario.name} / {method}")
        result["plots"] = [str(p) for p in paths]
        if log:
            print(f"plots saved in {time.perf_counter() - t2:.1f} s: {', '.join(map(str, paths))}", file=log)
    return result, run


def _emit(result: dict[str, Any], out: Path | None) -> None:
    text = json.dumps(result, indent=1, sort_keys=False)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text + "\n", encoding="utf-8")
    print(text)


def _main_live(args: argparse.Namespace, scenario: Any, gallery: GalleryInfo, config: MasterConfig,
               model: FaceLikelihood, days: list[tuple[int, float, float, list[int]]], t0: float,
               log: Any, protocol: ProtocolCheck) -> int:
    """``--live``: the scenario through the master node over DDS; the metrics of what it published."""
    likelihood = model
    import os
    import signal
    import uuid

    from face_reid_master.demo.children import domain_id_for_run
    from face_reid_master.evaluation.live import LiveError, run_live, scenario_truth
    from face_reid_master.evaluation.published_tracks import MATCH_RADIUS_M, run_log_from_messages

    try:
        domain_id = domain_id_for_run(args.domain_id)
    except ValueError as exc:
        print(f"face-reid-eval: error: {exc}", file=sys.stderr)
        return 2
    # this process joins the same private, loopback-only domain before rclpy is imported
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    day_of = {int(d["day"]): (float(d["start_s"]), float(d["end_s"])) for d in scenario.days}
    day_of_frame = [next((d for d, (a, b) in day_of.items() if a - 1e-6 <= f.stamp_s <= b + 1e-6), 0)
                    for f in scenario.frames]
    if log:
        print(f"live run on ROS_DOMAIN_ID={domain_id} (localhost only): {len(scenario.frames)} frames over "
              f"{len(days)} day(s), method {args.method}", file=log)

    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, signal.default_int_handler)
    previous = signal.signal(signal.SIGTERM, on_term)
    t1 = time.perf_counter()
    try:
        live = run_live(scenario.frames, day_of_frame, gallery.people, domain_id, uuid.uuid4().hex[:12],
                        log=log, likelihood_path=args.likelihood, embedding_space=model.space,
                        body_appearance_tracking=config.body_appearance_tracking,
                        body_metric_path=args.body_metric,
                        confidence_map_path=None if args.confidence_map is None else Path(args.confidence_map))
    except LiveError as exc:
        print(f"face-reid-eval: error: live run failed: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("face-reid-eval: interrupted; every process stopped", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    play_s = time.perf_counter() - t1
    run = run_log_from_messages(live.messages, scenario_truth(scenario.ground_truth, days),
                                len(scenario.identities), days, args.method)
    metrics = evaluate_run(run, gallery_people=gallery.gt_of_name or None, scenario_summary=scenario.summary,
                           with_mot=False)
    for key in ("method", "master_stats", "frames", "frames_rejected", "detections", "run_time_s"):
        metrics.pop(key, None)
    transport = live.transport
    result: dict[str, Any] = {
        "mode": "live",
        "scenario": _scenario_json(scenario),
        "method": args.method,
        "parameters": {**_parameters(config, likelihood, 1.0 / 5.0), "master": "face_reid_master.ros.node, default "
                       "parameters but method, db_path (temporary) and gallery_path (the gallery below, .npz)"},
        "gallery": gallery.as_json(),
        **metrics,
        "frames": transport["frames_sent"],
        "frames_rejected": transport["master_frames_not_applied"],
        "detections": transport["detections_sent"],
        "attribution": {"match_radius_m": MATCH_RADIUS_M, "published_track_samples": int(run.det_gt.size),
                        "samples_near_nobody": int((run.det_gt < 0).sum())},
        "transport": {"domain_id": domain_id, **transport},
        "run_time_s": round(play_s, 2),
    }
    if args.plot:
        paths = save_plots(run, scenario, args.plot, title=f"{args.scenario.name} / {args.method} (live)")
        result["plots"] = [str(p) for p in paths]
    result["protocol"] = protocol.as_json()
    result["total_time_s"] = round(time.perf_counter() - t0, 2)
    _emit(result, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
