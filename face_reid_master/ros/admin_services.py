"""The master's services: ``~/list_faces`` always, ``~/add_person`` and ``~/forget_face`` when
``admin_services`` is on (their own callback group: while a request waits for its photos, frames and timers go
on). On a secured network only a request sealed with the network key for this master is done (a keyless
``list_faces`` gets empty lists: names and last-seen times are personal data), and the reply is sealed for the
request (only its sender can read it, nobody else can forge it); a refused request or any error is reported in the
response, logged (cut) and counted (calls and refusals per service on /diagnostics), never raised into the
executor. Photos are read, decoded and embedded on a worker thread, within a request's pixel budget.

A person added by ``~/add_person`` is kept in the face store (with ``persist_faces``), so that the next start has
them as it has the gallery folder's people (the one added wins over the folder's of the same name); ``~/forget_face``
by name removes them from the store too. ``~/list_faces`` lists the learned faces, then every predefined person
(gallery folder or added) as a row of face id 0 (no face id is 0) with the number of their embeddings and last
seen 0 (the message has no other place for them).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

from face_reid_camera.common.checks import shown
from face_reid_camera.common.embedding_spaces import space_dim
from face_reid_camera.common.ros.sealed import open_request, reply_is_sealed, seal_response
from face_reid_camera.common.sealing import SealError
from face_reid_master.storage.errors import reason_of
from face_reid_msgs.srv import AddPerson, ForgetFace, ListFaces

__all__ = ["AdminServices"]

_MAX_REPLY_CHARS = 1000  # service replies are cut to this
_MAX_LOG_CHARS = 300  # log lines about a request are cut to this
_MAX_PHOTO_PIXELS = 40_000_000  # an add-person photo larger than this (by its header) is refused: 40 MP
_REQUEST_PIXEL_BUDGET = 200_000_000  # pixels one add-person request may decode in all (a few seconds of work)


class AdminServices:
    """The services of a master ``node`` (see the module doc); :attr:`calls` / :attr:`refusals` count them."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.calls: dict[str, int] = {}
        self.refusals: dict[str, int] = {}
        self._services: list[Any] = []
        self._worker: Any = None  # the thread that decodes add-person photos (off the frame path)

    def create(self, admin: bool, secured: bool) -> None:
        """Offer the services (``admin``: also those that change the faces)."""
        node, log = self.node, self.node.get_logger()
        self._services = [node.create_service(ListFaces, "~/list_faces", self.list_faces)]
        if not admin:
            log.info("admin services off (admin_services: false): ~/add_person and ~/forget_face are not offered")
            return
        group = MutuallyExclusiveCallbackGroup()
        self._services += [
            node.create_service(AddPerson, "~/add_person", self.add_person, callback_group=group),
            node.create_service(ForgetFace, "~/forget_face", self.forget_face, callback_group=group)]
        if not secured:
            log.warning("admin services on (admin_services: true) without a network key: any participant of this "
                        "DDS domain can call ~/add_person and ~/forget_face")
        else:
            log.info("admin services on (admin_services: true): ~/add_person and ~/forget_face for requests sealed "
                     "with the network key (face-reid-faces --master NODE --key KEYFILE)")

    def destroy(self) -> None:
        for srv in self._services:
            self.node.destroy_service(srv)
        self._services = []

    async def add_person(self, request: Any, response: Any) -> Any:
        return await self._handle("add_person", self._do_add_person, request, response)

    async def forget_face(self, request: Any, response: Any) -> Any:
        return await self._handle("forget_face", self._do_forget_face, request, response)

    async def _handle(self, what: str, handler: Any, request: Any, response: Any) -> Any:
        """Run a service handler (a coroutine: the executor goes on with frames while it waits): a refused request
        (ValueError) or any other error is reported in the response and logged (cut), never raised into the
        executor."""
        wire, error = request, None
        try:
            request, error = self._opened(request)
            if error is not None:
                raise ValueError(f"refused: {error}")
            await handler(request, response)
        except ValueError as exc:
            response.success, response.message = False, str(exc)[:_MAX_REPLY_CHARS]
        except Exception as exc:  # a request must never take the node down
            response.success = False
            response.message = f"internal error: {type(exc).__name__}: {str(exc)[:200]}"
        self._count(what, not response.success)
        # names, face ids and photo paths: private (local log only on a secured network)
        self.node.log_throttled(what, f"{what}: {response.message[:_MAX_LOG_CHARS]}", level="info", every_s=1.0,
                                private=True)
        return self._reply(wire, response, error)

    def _opened(self, request: Any) -> tuple[Any, SealError | None]:
        """The request to act on, and why it is refused (None: not refused): on a secured master only what a
        holder of the network key sealed for this master is done."""
        if not self.node._openers:
            return request, None
        try:
            return open_request(self.node._openers["requests"], request, self.node.get_fully_qualified_name(),
                                time.time()), None
        except SealError as exc:
            return request, exc

    def _reply(self, wire: Any, response: Any, error: SealError | None) -> Any:
        """``response`` as sent: on a secured master sealed for the request ``wire`` when a key holder's fresh
        request to this master was opened (else plain: why it was refused, nothing else)."""
        if not self.node._openers or not reply_is_sealed(error):
            return response
        # the master's sealer (sender: this node's name); each seal names its own purpose
        return seal_response(self.node._tracks_sealer, response, self.node.get_fully_qualified_name(), wire)

    def _count(self, what: str, refused: bool) -> None:
        self.calls[what] = self.calls.get(what, 0) + 1
        if refused:
            self.refusals[what] = self.refusals.get(what, 0) + 1

    async def _off_the_frame_path(self, work: Any) -> Any:
        """``work()`` on the admin worker thread; the executor serves frames meanwhile (rclpy resumes the awaiting
        service coroutine when the worker's result arrives)."""
        from concurrent.futures import ThreadPoolExecutor

        from rclpy.task import Future

        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="face_reid_admin")
        done: Future[Any] = Future(executor=self.node.executor)
        done.add_done_callback(lambda _: None)  # its completion wakes the executor, which resumes the coroutine

        def finished(job: Any) -> None:
            if job.exception() is not None:
                done.set_exception(job.exception())
            else:
                done.set_result(job.result())

        self._worker.submit(work).add_done_callback(finished)
        return await done

    async def _do_add_person(self, request: Any, response: Any) -> None:
        from face_reid_camera.faces.photos import embed_request_photos
        from face_reid_master.identity.predefined_people import check_person_name

        name = check_person_name(request.name.strip())
        dim = space_dim(str(self.node.values["embedding_space"]))
        max_rows = int(self.node.values["max_embeddings_per_request"])
        max_photos = int(self.node.values["max_photos_per_request"])
        if len(request.embeddings) > max_rows * dim:
            raise ValueError(f"more than {max_rows} embeddings in one request (max_embeddings_per_request)")
        if len(request.embeddings) % dim:
            raise ValueError(f"embeddings must hold k x {dim} values (space {self.node.values['embedding_space']}), "
                             f"got {len(request.embeddings)}")
        if len(request.image_paths) > max_photos:
            raise ValueError(f"more than {max_photos} photos in one request (max_photos_per_request)")
        emb = np.asarray(request.embeddings, dtype=np.float32)
        rows: list[np.ndarray] = list(emb.reshape(-1, dim)) if emb.size else []
        notes: list[str] = []
        if request.image_paths:  # read, decoded and embedded off the frame path, within the request's pixel budget
            paths, root, max_bytes = [str(p) for p in request.image_paths], str(self.node.values["photo_root"]), int(
                self.node.values["max_photo_bytes"])
            photos = await self._off_the_frame_path(lambda: embed_request_photos(
                self.node.photo_embedder(), root, paths, max_bytes, _MAX_PHOTO_PIXELS, _REQUEST_PIXEL_BUDGET))
            rows += photos.embeddings
            notes += photos.notes
        try:
            if not rows:
                raise ValueError("no usable face embedding")
            self.node.finish_frames()  # the request acts on the face table as the frames applied so far left it
            self.node.configured_core().add_person(name, np.stack(rows))
        except ValueError as exc:
            raise ValueError("; ".join([str(exc), *notes])[:_MAX_REPLY_CHARS]) from None
        added = f"added {name} with {len(rows)} embeddings"
        store = self.node.store
        if store is None:
            notes.insert(0, "for this run only: persist_faces is off, the next start will not know them")
        else:
            try:
                store.save_person(name, np.stack(rows))
            except Exception as exc:  # they are named until the master stops: the operator must know they vanish then
                raise ValueError(f"{added} for this run only: the face store could not keep them "
                                 f"({reason_of(exc)[:300]})") from None
        response.success, response.num_embeddings = True, len(rows)
        response.message = "; ".join([added, *notes])[:_MAX_REPLY_CHARS]

    async def _do_forget_face(self, request: Any, response: Any) -> None:
        self.node.finish_frames()  # the request acts on the face table as the frames applied so far left it
        core = self.node.configured_core()
        if not request.face_id and not request.name:
            raise ValueError("give a face_id or a name")
        ids = [int(request.face_id)] if request.face_id else [
            fid for fid in core.identity.face_ids() if core.face_name(fid) == request.name
        ]
        forgotten = [fid for fid in ids if core.forget_face(fid)]
        by_name = bool(request.name) and not request.face_id
        person = by_name and core.forget_person(request.name)
        kept = by_name and self.node.store is not None and self.node.store.forget_person(request.name)
        person = person or kept
        response.forgotten_face_ids = forgotten
        response.success = bool(forgotten) or person
        said = ([f"forgot faces {forgotten}"] if forgotten else []) + (
            [f"removed the predefined person {shown(request.name, 64)}"] if person else [])
        response.message = "; ".join(said) if said else "no such face or person"

    def list_faces(self, request: Any, response: Any) -> Any:
        """The learned faces (ids, names, features, last seen), then the predefined people (face id 0, their number
        of embeddings, last seen 0); on a secured master only for a request sealed with the key for this master
        (others get empty lists, counted as refused)."""
        _, error = self._opened(request)
        if error is not None:
            self._count("list_faces", True)
            self.node.get_logger().warning(f"list_faces: refused: {str(error)[:_MAX_LOG_CHARS]}",
                                           throttle_duration_sec=5.0)
            return self._reply(request, response, error)
        self._count("list_faces", False)
        core = self.node.configured_core()
        for face in core.identity.faces.export_all():
            response.face_ids.append(face.face_id)
            response.names.append(core.face_name(face.face_id))
            response.num_features.append(int(face.features.shape[0]))
            response.last_seen_s.append(float(face.last_seen_s))
        for name in core.people.names():  # the predefined people: face id 0, their embeddings, never seen as a face
            response.face_ids.append(0)
            response.names.append(name)
            response.num_features.append(core.people.n_embeddings(name))
            response.last_seen_s.append(0.0)
        return self._reply(request, response, None)
