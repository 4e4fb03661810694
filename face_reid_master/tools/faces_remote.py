"""``face-reid-faces --master NODE``: the same list / forget, plus add, on a running master through its
services (~/list_faces, ~/forget_face, ~/add_person; the last two need ``admin_services: true`` on the master).
With ``--key`` the requests are sealed with the network key for that master (a secured master takes nothing else:
a keyless listing gets nothing), and only the master's reply sealed for the request is believed (a reply from a
server without the key is reported as unauthenticated and passed over). Photos given to ``add`` are turned into
embeddings here (the images never leave this process).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from face_reid_camera.common.checks import shown
from face_reid_camera.common.ros.service_call import SealedCaller, call_service
from face_reid_master.tools.faces_cli import TIME_HEADER, local_time, name_cell

EXIT_OK, EXIT_NOT_FOUND, EXIT_USAGE, EXIT_UNREACHABLE = 0, 1, 2, 5


_HINT = "is the master running, with admin_services: true for add / forget, on this ROS_DOMAIN_ID?"


class _Client:
    """Calls the master's services: plain without a key; with one, through :class:`SealedCaller` (requests sealed
    for the master, only its reply sealed for the request taken)."""

    def __init__(self, node: Any, master: str, key: bytes | None, prog: str, timeout_s: float) -> None:
        self.node, self.master, self.timeout_s = node, master, timeout_s
        self.sealed = SealedCaller(node, key, prog, _HINT) if key is not None else None

    def call(self, srv_type: Any, service: str, request: Any) -> Any:
        if self.sealed is None:
            return call_service(self.node, srv_type, f"{self.master}/{service}", request, self.timeout_s, _HINT)
        return self.sealed.call(srv_type, self.master, service, request, self.timeout_s)


def format_remote_list(rows: list[tuple[int, str, int, float]], master: str) -> str:
    """The ~/list_faces answer as a table: face id, name, stored features, last seen (names and times shown as
    face-reid-faces shows the store's); its rows of face id 0 are the master's predefined people (gallery folder
    or named at run time), listed after the faces with their number of embeddings."""
    faces = [r for r in rows if r[0]]
    people = [r for r in rows if not r[0]]
    lines = [f"{'id':>6}  {'name':<24} {'features':>8}  last seen {TIME_HEADER}"]
    lines += [f"{fid:>6}  {name_cell(name):<24} {n:>8}  {local_time(seen)}"
              for fid, name, n, seen in faces]
    lines.append(f"{len(faces)} face(s) on {master}")
    if people:
        lines.append(f"{'person':<32} {'photos':>8}")
        lines += [f"{name_cell(name):<32} {n:>8}" for _, name, n, _ in people]
        lines.append(f"{len(people)} predefined person(s) on {master} (gallery folder and named at run time)")
    return "\n".join(lines)


def refusal_line(prog: str, message: str, keyed: bool) -> str:
    """The one line for a request the master refused: its reason once (a sealing refusal already starts with
    'refused:'), and, when no --key was given and the master wants sealed requests, how to seal them."""
    line = f"{prog}: refused: {message.removeprefix('refused: ')}"
    if not keyed and "network key" in message:
        line += " (give --key with the network's key file)"
    return line


def photo_embeddings(photos: list[str], space: str) -> tuple[list[float], list[str]]:
    """The embeddings (of embedder space ``space``, flattened) of the largest face of each photo, and a note per
    photo left out (unreadable, no face); the photos are read here and go nowhere else."""
    from face_reid_camera.common.embedding_spaces import embedder_for_space
    from face_reid_camera.faces.embedder import load_embedder
    from face_reid_camera.faces.photos import PhotoEmbedder

    embedder = PhotoEmbedder(embedder=load_embedder(embedder_for_space(space)))
    values: list[float] = []
    notes: list[str] = []
    for path in photos:
        try:
            found = embedder.embed_photo(path)
        except (OSError, ValueError) as exc:
            notes.append(f"skipped {shown(path)}: {exc}")
            continue
        if found is None:
            notes.append(f"skipped {shown(path)}: no face found")
        else:
            values.extend(float(v) for v in found.embedding)
    return values, notes


def run_remote(args: argparse.Namespace, prog: str) -> int:
    """One command against the master node ``args.master``; exit codes as face-reid-faces (5: no master)."""
    import rclpy

    from face_reid_msgs.srv import AddPerson, ForgetFace, ListFaces

    if args.command == "rename":
        print(f"{prog}: rename needs the store itself (the master offers no rename service): stop the master "
              "and run without --master", file=sys.stderr)
        return EXIT_USAGE
    key = None
    if args.key:
        from face_reid_camera.common.sealing import load_network_key

        key = load_network_key(args.key)
    master = "/" + args.master.strip("/")
    rclpy.init()
    node = rclpy.create_node("face_reid_faces_client")
    client = _Client(node, master, key, prog, args.timeout_s)
    try:
        if args.command == "list":
            reply = client.call(ListFaces, "list_faces", ListFaces.Request())
            rows = list(zip(reply.face_ids, reply.names, reply.num_features, reply.last_seen_s, strict=False))
            print(format_remote_list(rows, master))
            if not rows and key is None:
                print(f"{prog}: a master with a network key answers a listing without --key with nothing",
                      file=sys.stderr)
            return EXIT_OK
        if args.command == "forget":
            request = ForgetFace.Request(face_id=args.face_id or 0, name=args.name or "")
            reply = client.call(ForgetFace, "forget_face", request)
        else:  # add
            values, notes = photo_embeddings(args.photos, args.space)
            for note in notes:
                print(f"{prog}: {note}", file=sys.stderr)
            if not values:
                print(f"{prog}: no usable face in the photos", file=sys.stderr)
                return EXIT_NOT_FOUND
            request = AddPerson.Request(name=args.name, embeddings=values)
            reply = client.call(AddPerson, "add_person", request)
    except TimeoutError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return EXIT_UNREACHABLE
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    print(reply.message if reply.success else refusal_line(prog, reply.message, key is not None),
          file=sys.stdout if reply.success else sys.stderr)
    return EXIT_OK if reply.success else EXIT_NOT_FOUND
