"""The master core against cameras that lie about time or flood it: no camera can move the tracker clock past
the master's own, make the other cameras' frames late or make the tracker start afresh; floods and forged
embeddings are refused and counted. Each scenario here hid, reset or slowed the tracker before (the issue's
probes)."""

from __future__ import annotations

import numpy as np

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.records import CameraFrameRecord, PersonRecord

LATENCY_S = 0.05  # camera capture -> master receive


def _person(t: float, emb: np.ndarray | None = None) -> PersonRecord:
    return PersonRecord(np.array([0.5 * t, 1.0, 0.0]), 0.05, 1.75, emb, 0.9 if emb is not None else 0.0, 0.8)


def _core(**kw) -> MasterCore:
    return MasterCore(MasterConfig(embedding_space="dlib_resnet_v1", body_appearance_tracking=False, **kw))


def _walk_with_liar(core: MasterCore, liar_offset_s: float, seconds: float = 30.0, burst: int = 1) -> set[int]:
    """A person walks in front of cam_a at 10 Hz (stamps true); cam_liar sends ``burst`` empty frames twice a
    second stamped ``liar_offset_s`` off. Returns the track ids the person had (live: now_s = receive time)."""
    tracks: set[int] = set()
    for k in range(int(seconds * 10)):
        t = k / 10
        outcome = core.process_frame(CameraFrameRecord("cam_a", t, (_person(t),)), now_s=t + LATENCY_S)
        assert outcome.accepted, outcome.reason
        tracks.update(outcome.track_of_person.values())
        for _ in range(burst if k % 5 == 0 else 0):
            core.process_frame(CameraFrameRecord("cam_liar", t + liar_offset_s, ()), now_s=t + LATENCY_S)
        core.tick(t + LATENCY_S)
    return tracks


def test_a_camera_stamping_in_the_future_cannot_hide_people_seen_by_the_others() -> None:
    core = _core()
    tracks = _walk_with_liar(core, 1.9)  # within max_stamp_future_s (2 s): before, cam_a's frames were "late"
    assert len(tracks) == 1 and core.stats.frames_applied == 300 + 60
    assert core.stats.frames_future_clamped == 60 and core.stats.frames_rejected_tracker_late == 0
    assert core.tracker.stats.clock_resyncs == 0


def test_a_camera_lagging_behind_never_resets_the_tracker() -> None:
    core = _core()
    tracks = _walk_with_liar(core, -1.5, burst=6)  # late: refused, never taken for a clock jump back (before:
    assert len(tracks) == 1 and core.stats.frames_rejected_tracker_late == 360  # 5 in a row deleted every track)
    assert core.tracker.stats.clock_resyncs == 0


def test_the_masters_own_clock_going_back_starts_the_tracker_afresh() -> None:
    core = _core()
    for k in range(20):
        core.process_frame(CameraFrameRecord("cam_a", k / 10, (_person(k / 10),)), now_s=k / 10 + LATENCY_S)
    assert len(core.tracks()) == 1
    out = core.process_frame(CameraFrameRecord("cam_a", 0.0, (_person(0.0),)), now_s=LATENCY_S)  # bag looped
    assert out.accepted and core.stats.clock_jumps_back == 1


def test_replay_without_a_master_clock_still_follows_a_jump_back() -> None:
    core = _core()
    for k in range(20):
        core.process_frame(CameraFrameRecord("cam_a", 100 + k / 10, (_person(k / 10),)))
    outcomes = [core.process_frame(CameraFrameRecord("cam_a", k / 10, (_person(k / 10),))) for k in range(8)]
    assert [o.accepted for o in outcomes][-3:] == [True, True, True]  # re-based after clock_resync_frames


def test_crowds_floods_and_forged_embeddings_are_refused_and_counted() -> None:
    core = _core(max_people_per_frame=50, max_camera_rate_hz=40.0)
    big = tuple(_person(0.0) for _ in range(5000))
    out = core.process_frame(CameraFrameRecord("cam_a", 0.0, big), now_s=0.0)
    assert not out.accepted and "5000 people" in out.reason and core.stats.frames_rejected_too_many_people == 1
    accepted = [core.process_frame(CameraFrameRecord("cam_b", 1.0 + k / 1000, ()), now_s=1.0 + k / 1000).accepted
                for k in range(100)]  # 1000 frames/s for 0.1 s
    assert sum(accepted) == 40 and core.stats.frames_rejected_camera_rate == 60
    assert core.process_frame(CameraFrameRecord("cam_a", 2.0, ()), now_s=2.0).accepted  # other cameras unaffected
    rng = np.random.default_rng(0)
    real = rng.normal(size=128).astype(np.float32)
    real *= 1.4 / np.linalg.norm(real)  # dlib embeddings of real faces are 1.2-1.65 long
    forged = (real * 1000.0, np.zeros(128, np.float32), real * 0.1)
    for k, emb in enumerate((real, *forged)):
        core.process_frame(CameraFrameRecord("cam_c", 3.0 + k, (_person(0.0, emb),)), now_s=3.0 + k)
    assert core.stats.embeddings_rejected_norm == 3 and core.stats.embeddings_used == 1


def test_a_huge_camera_id_is_cut_and_escaped_in_what_is_logged() -> None:
    core = _core(known_camera_ids=("cam_a",))
    out = core.process_frame(CameraFrameRecord("\x1b[2J" + "x" * 100_000, 0.0, ()), now_s=0.0)
    assert not out.accepted and len(out.reason) < 120 and "\x1b" not in out.reason  # before: 100,000 characters


def test_cameras_with_unusable_spaces_cannot_grow_what_the_master_remembers() -> None:
    """Each new camera id sending an unusable space is noticed once; 5,000 of them (random ids) keep at most
    1,024 remembered, and a camera noticed again after being forgotten is simply noticed again."""
    core = _core()
    emb = np.full(128, 0.1, np.float32)
    notices = 0
    for k in range(5000):
        person = PersonRecord(np.array([0.0, 1.0, 0.0]), 0.05, 1.75, emb, 0.9, 0.8, "some_space_" + "z" * 1000)
        out = core.process_frame(CameraFrameRecord(f"cam_{k}", 0.01 * k, (person,)), now_s=0.01 * k)
        notices += len(out.notices)
    assert notices == 5000 and len(core.reader._space_noticed) == 1024  # before: 5,000 entries, each a 1,000-char space
    assert all(len(space) <= 64 for space in core.reader._space_noticed.values())
    again = core.process_frame(CameraFrameRecord("cam_4999", 50.0, (person,)), now_s=50.0)
    assert not again.notices  # still remembered: not said twice
