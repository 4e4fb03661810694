"""``face-reid-faces``: inspect and edit the master's persistent face memory (list, forget, rename).

The data never leaves the store: there is no export of vectors, ``list --json`` prints summaries only. The
store holds the learned faces and the people named at run time (``add``). ``list`` reads it beside a running
master (read-only, through SQLite's own locks); ``forget`` / ``rename`` / ``add`` need the master stopped (it
would overwrite them), or ``--master NODE`` to list / forget / add through the running master's services
(faces_remote.py). ``add`` embeds the photos here: only their embeddings are kept. Options (``--db``,
``--master``, ...) go before or after the command.

Exit codes: 0 done, 1 nothing matched (unknown face id / name) or the master refused, 2 usage error, 3 store
in use by another process, 4 store unusable (missing file, I/O or configuration error), 5 no master answered.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from face_reid_camera.common.checks import shown
from face_reid_master.identity.predefined_people import check_person_name
from face_reid_master.storage.face_store import (
    FaceStore,
    FaceStoreError,
    FaceStoreLockedError,
    FaceSummary,
    PersonSummary,
    default_db_path,
)

__all__ = ["EXIT_BUSY", "EXIT_NOT_FOUND", "EXIT_OK", "EXIT_STORE_ERROR", "EXIT_USAGE", "build_parser", "main"]

PROG = "face-reid-faces"
EXIT_OK = 0
EXIT_NOT_FOUND = 1
EXIT_USAGE = 2
EXIT_BUSY = 3
EXIT_STORE_ERROR = 4


def _common_options(parser: argparse.ArgumentParser, suppress: bool) -> None:
    """--db, --master, --key, --timeout-s: taken before the command or after it (``suppress``: on a command, so
    that an option not given there keeps what was given before it)."""
    def default(value: object) -> object:
        return argparse.SUPPRESS if suppress else value

    parser.add_argument(
        "--db",
        type=Path,
        default=default(None),
        help="face store file (default: $FACE_REID_DB or ~/.local/share/face_reid/faces.db)",
    )
    parser.add_argument("--master", default=default(""), metavar="NODE",
                        help="work on a running master through its services instead of the store, e.g. "
                             "/face_reid_master (add and forget need its admin_services: true)")
    parser.add_argument("--key", default=default(""),
                        help="with --master: seal the requests with this network key file")
    parser.add_argument("--timeout-s", type=float, default=default(20.0),
                        help="with --master: how long to wait for it (s; default 20)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="List, forget or rename the faces learned by the face-reid master and the people named at run "
                    "time (biometric data).",
    )
    _common_options(parser, suppress=False)
    common = argparse.ArgumentParser(add_help=False)
    _common_options(common, suppress=True)
    sub = parser.add_subparsers(dest="command", required=True)
    p_list = sub.add_parser("list", parents=[common],
                            help="list stored faces and named people (no feature vectors); works beside a running "
                                 "master (read-only)")
    p_list.add_argument("--json", action="store_true",
                        help="one JSON array of summaries (faces; then people named at run time, with 'person')")
    p_forget = sub.add_parser("forget", parents=[common],
                              help="delete a face (or all faces with a name, and the person of that name) for good")
    target = p_forget.add_mutually_exclusive_group(required=True)
    target.add_argument("face_id", nargs="?", type=int, help="face id to delete")
    target.add_argument("--name", help="delete every face with exactly this name and the person named so")
    p_rename = sub.add_parser("rename", parents=[common], help="set or clear the name of a face")
    p_rename.add_argument("face_id", type=int)
    name = p_rename.add_mutually_exclusive_group(required=True)
    name.add_argument("name", nargs="?", help="new name")
    name.add_argument("--clear", action="store_true", help="remove the name")
    p_add = sub.add_parser("add", parents=[common],
                           help="name a person from photos (embedded here, no photo is kept): with --master on the "
                                "running master, else in the store (the master stopped); kept across restarts")
    p_add.add_argument("name")
    p_add.add_argument("photos", nargs="+", help="face photos (JPEG/PNG) of that person")
    p_add.add_argument("--space", default="", help="with --master: the master's embedding space (default: the "
                                                   "master's default; on the store: the store's)")
    return parser


TIME_HEADER = "(local time)"  # list: how the times are shown (by face-reid-faces --master too)


def local_time(stamp_s: float) -> str:
    """Seconds since the epoch as this machine's local time, ISO 8601 to the second with its UTC offset (how
    both the store and a running master's list show times); the number itself when no date has it."""
    try:
        return _dt.datetime.fromtimestamp(stamp_s).astimezone().isoformat(timespec="seconds")
    except (OverflowError, OSError, ValueError):
        return f"{stamp_s:.3f}"


def name_cell(name: str | None) -> str:
    """A face's name as the lists show it: "-" for none, quoted and cut when it is long or not printable."""
    if not name:
        return "-"
    return name if name.isprintable() and len(name) <= 24 else shown(name, 20)


def _print_list(faces: list[FaceSummary], people: list[PersonSummary], as_json: bool) -> None:
    if as_json:
        rows: list[dict[str, object]] = [
            {
                "face_id": f.face_id,
                "name": f.name,
                "n_features": f.n_features,
                "n_observations": f.n_observations,
                "created_s": f.created_s,
                "last_seen_s": f.last_seen_s,
            }
            for f in faces
        ]
        rows += [{"person": p.name, "n_embeddings": p.n_embeddings, "added_s": p.added_s} for p in people]
        print(json.dumps(rows))
        return
    created = f"created {TIME_HEADER}"
    print(f"{'id':>6}  {'name':<24} {'features':>8} {'observ.':>8}  {created:<25}  last seen {TIME_HEADER}")
    for f in faces:
        name = name_cell(f.name)
        print(
            f"{f.face_id:>6}  {name:<24} {f.n_features:>8} {f.n_observations:>8}  "
            f"{local_time(f.created_s):<25}  {local_time(f.last_seen_s)}"
        )
    print(f"{len(faces)} face(s)")
    if people:  # the gallery folder's people are not in the store: a running master lists them (--master)
        print(f"{'person':<32} {'photos':>8}  added {TIME_HEADER}")
        for p in people:
            print(f"{name_cell(p.name):<32} {p.n_embeddings:>8}  {local_time(p.added_s)}")
        print(f"{len(people)} person(s) named at run time")


def _add(store: FaceStore, args: argparse.Namespace) -> int:
    """``add`` on the store (the master stopped): the photos' embeddings in the store's space, kept as a person named
    at run time (the master names them from its next start)."""
    import numpy as np

    from face_reid_master.tools.faces_remote import photo_embeddings

    try:
        name = check_person_name(args.name)
    except ValueError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    values, notes = photo_embeddings(args.photos, store.embedding_space)
    for note in notes:
        print(f"{PROG}: {note}", file=sys.stderr)
    if not values:
        print(f"{PROG}: no usable face in the photos", file=sys.stderr)
        return EXIT_NOT_FOUND
    n = store.save_person(name, np.asarray(values, dtype=np.float32).reshape(-1, store.embedding_dim))
    print(f"added {shown(name)} with {n} embeddings to {store.path} (the master names them from its next start)")
    return EXIT_OK


def _run(store: FaceStore, args: argparse.Namespace) -> int:
    if args.command == "list":
        _print_list(store.list_faces(), store.list_people(), args.json)
        return EXIT_OK
    if args.command == "forget":
        if args.name is not None:
            ids = store.forget_name(args.name)
            person = store.forget_person(args.name)
            if not ids and not person:
                print(f"{PROG}: no face or person named {shown(args.name)}", file=sys.stderr)
                return EXIT_NOT_FOUND
            said = ([f"forgot face(s) {', '.join(str(i) for i in ids)} named {shown(args.name)}"] if ids else []) + (
                [f"removed the person {shown(args.name)} named at run time"] if person else [])
            print("; ".join(said))
            return EXIT_OK
        if not store.forget(args.face_id):
            print(f"{PROG}: no face {args.face_id}", file=sys.stderr)
            return EXIT_NOT_FOUND
        print(f"forgot face {args.face_id}")
        return EXIT_OK
    if args.command == "add":
        return _add(store, args)
    # rename
    new_name = None if args.clear else args.name
    if new_name is not None:
        try:
            check_person_name(new_name)
        except ValueError as exc:
            hint = " (use --clear to remove a name)" if not new_name.strip() else ""
            print(f"{PROG}: error: {exc}{hint}", file=sys.stderr)
            return EXIT_USAGE
    if not store.set_name(args.face_id, new_name):
        print(f"{PROG}: no face {args.face_id}", file=sys.stderr)
        return EXIT_NOT_FOUND
    print(f"face {args.face_id} " + (f"renamed {shown(new_name)}" if new_name is not None else "name cleared"))
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits 2 on usage errors, 0 on --help
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.WARNING, format=f"{PROG}: %(levelname)s: %(message)s")
    if args.master:
        from face_reid_master.tools.faces_remote import run_remote

        if args.command == "add" and not args.space:
            from face_reid_master.core import MasterConfig

            args.space = MasterConfig().embedding_space
        try:
            return run_remote(args, PROG)
        except ValueError as exc:  # e.g. an unusable key file
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    path = args.db if args.db is not None else default_db_path()
    try:
        with FaceStore(path, create=False, embedding_dim=None, embedding_space=None,
                       read_only=args.command == "list") as store:
            if store.recovered_from is not None:
                print(
                    f"{PROG}: warning: the store was corrupt and has been moved to {store.recovered_from}; "
                    "this is a new, empty store",
                    file=sys.stderr,
                )
            return _run(store, args)
    except FaceStoreLockedError as exc:
        print(f"{PROG}: error: {exc}: stop the master node first, or give --master NODE to work through it",
              file=sys.stderr)
        return EXIT_BUSY
    except ValueError as exc:  # e.g. a face id out of range
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (FaceStoreError, OSError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_STORE_ERROR


if __name__ == "__main__":
    sys.exit(main())
