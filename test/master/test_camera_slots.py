"""Camera topic slots (pure): on a secured master a stranger's keyless topics cannot fill max_camera_topics, are
released when they do not authenticate, and do not hold back a camera that comes after them."""

from __future__ import annotations

import pytest

from face_reid_master import camera_slots as cs
from face_reid_master.camera_slots import CameraSlots, camera_of_topic

PROBATION_MESSAGES, PROBATION_S, PROBATION_TOPICS, RETRY_S = (cs.PROBATION_MESSAGES, cs.PROBATION_S,
                                                              cs.PROBATION_TOPICS, cs.RETRY_S)

EVIL, CAM = frozenset({"evil"}), frozenset({"cam"})


def _fake(k: int) -> str:
    return f"/cam_k/e{k:03d}/face_reid/frames_sealed"


def test_keyless_topics_never_take_a_slot_and_a_later_camera_gets_one() -> None:
    slots = CameraSlots(64, authenticate=True)
    for k in range(64):
        slots.offer(_fake(k), EVIL, 0.0)
    first = slots.step(0.0)
    assert len(first.subscribe) == PROBATION_TOPICS and not slots.slots  # probation, no slot
    for topic in first.subscribe:
        for _ in range(PROBATION_MESSAGES):
            slots.heard(topic, False, 0.5)  # garbage
    slots.offer("/cam_k/face_reid/frames_sealed", CAM, 0.6)  # the real camera starts
    second = slots.step(1.0)
    assert sorted(second.unsubscribe) == sorted(first.subscribe) and slots.released == PROBATION_TOPICS
    # the stranger's participant is suspected now: the camera goes first, ahead of 48 older keyless topics
    assert second.subscribe[0] == "/cam_k/face_reid/frames_sealed" and len(slots.probation) == PROBATION_TOPICS
    slots.heard("/cam_k/face_reid/frames_sealed", True, 1.1)
    assert list(slots.slots) == ["/cam_k/face_reid/frames_sealed"]
    # silent keyless topics are released after PROBATION_S; none ever holds a slot
    changes = slots.step(1.0 + PROBATION_S)
    assert len(changes.unsubscribe) == PROBATION_TOPICS - 1 and list(slots.slots) == ["/cam_k/face_reid/frames_sealed"]
    assert len(slots.probation) <= PROBATION_TOPICS


def test_a_released_topic_is_offered_again_after_a_doubling_cool_down() -> None:
    slots = CameraSlots(4, authenticate=True)
    topic = "/cam1/face_reid/frames_sealed"
    slots.offer(topic, EVIL, 0.0)
    assert slots.step(0.0).subscribe == [topic]
    assert slots.step(PROBATION_S).unsubscribe == [topic]  # silent for PROBATION_S
    assert slots.step(PROBATION_S + RETRY_S - 0.1).subscribe == []
    t = PROBATION_S + RETRY_S
    assert slots.step(t).subscribe == [topic]  # its turn again (the real camera may have come meanwhile)
    assert slots.step(t + PROBATION_S).unsubscribe == [topic]
    assert slots.step(t + PROBATION_S + RETRY_S).subscribe == []  # twice as long now
    t += PROBATION_S + 2 * RETRY_S
    assert slots.step(t).subscribe == [topic]
    slots.heard(topic, True, t + 0.1)  # the camera, at last
    assert topic in slots.slots and not slots.step(t + 100.0).unsubscribe


def test_a_slot_on_which_nothing_opens_is_given_back_and_gone_topics_are_forgotten() -> None:
    """A replayed frame that once got a stranger's topic a slot (or a stopped camera) does not hold it for good;
    the names a stranger made and dropped do not pile up."""
    slots = CameraSlots(4, authenticate=True)
    assert slots.fixed("/fixed/face_reid/frames_sealed")
    slots.offer("/a/face_reid/frames_sealed", EVIL, 0.0)
    slots.offer("/b/face_reid/frames_sealed", CAM, 0.0)
    slots.step(0.0)
    slots.heard("/a/face_reid/frames_sealed", True, 1.0)  # e.g. a replay that won the race
    slots.heard("/b/face_reid/frames_sealed", True, 1.0)
    for t in range(2, 61):
        slots.heard("/b/face_reid/frames_sealed", True, float(t))  # a live camera: every frame opens
    changes = slots.step(1.0 + cs.SLOT_IDLE_S)
    assert changes.idle == ["/a/face_reid/frames_sealed"] and not slots.known("/a/face_reid/frames_sealed")
    assert set(slots.slots) == {"/fixed/face_reid/frames_sealed", "/b/face_reid/frames_sealed"}  # fixed: kept
    for k in range(3):
        slots.offer(f"/gone{k}/face_reid/frames_sealed", EVIL, 100.0)
    slots.prune({"/gone0/face_reid/frames_sealed"})
    assert set(slots.waiting) == {"/gone0/face_reid/frames_sealed"}


def test_garbage_on_a_cameras_own_topic_does_not_cut_its_probation_short() -> None:
    """A stranger flooding the real camera's topic (two participants publish it) cannot get it released before the
    camera's frames had probation_s to open; on a topic of its own, the garbage ends the probation early."""
    slots = CameraSlots(4, authenticate=True)
    shared, own = "/cam1/face_reid/frames_sealed", "/cam2/face_reid/frames_sealed"
    slots.offer(shared, EVIL | CAM, 0.0)
    slots.offer(own, EVIL, 0.0)
    slots.step(0.0)
    for _ in range(10 * PROBATION_MESSAGES):
        slots.heard(shared, False, 0.5)
        slots.heard(own, False, 0.5)
    assert slots.step(1.0).unsubscribe == [own]
    slots.heard(shared, True, 2.0)  # the camera's frame, among the garbage
    assert shared in slots.slots


def test_a_release_says_how_many_messages_did_not_open() -> None:
    slots = CameraSlots(4, authenticate=True)
    slots.offer("/noisy/face_reid/frames_sealed", EVIL, 0.0)
    slots.offer("/silent/face_reid/frames_sealed", EVIL, 0.0)
    slots.step(0.0)
    for _ in range(3):
        slots.heard("/noisy/face_reid/frames_sealed", False, 1.0)
    changes = slots.step(PROBATION_S)
    assert changes.unopened == {"/noisy/face_reid/frames_sealed": 3, "/silent/face_reid/frames_sealed": 0}


def test_at_most_max_slots_authenticated_topics_and_fixed_ones_count() -> None:
    slots = CameraSlots(2, authenticate=True)
    assert slots.fixed("/fixed/face_reid/frames_sealed")
    for name in ("/a/face_reid/frames_sealed", "/b/face_reid/frames_sealed"):
        slots.offer(name, frozenset({name}), 0.0)
    assert len(slots.step(0.0).subscribe) == 2
    slots.heard("/a/face_reid/frames_sealed", True, 0.1)
    slots.heard("/b/face_reid/frames_sealed", True, 0.1)  # a key holder, but no slot left
    assert set(slots.slots) == {"/fixed/face_reid/frames_sealed", "/a/face_reid/frames_sealed"}
    assert slots.refused == {"/b/face_reid/frames_sealed"}
    assert not slots.fixed("/more/face_reid/frames_sealed")


def test_unsecured_first_come_until_the_cap() -> None:
    slots = CameraSlots(2, authenticate=False)
    for k in range(3):
        slots.offer(f"/c{k}/face_reid/frames", frozenset({"x"}), 0.0)
    changes = slots.step(0.0)
    assert changes.subscribe == ["/c0/face_reid/frames", "/c1/face_reid/frames"]
    assert changes.refused == ["/c2/face_reid/frames"] and slots.released == 0


def test_the_camera_of_a_topic_is_its_innermost_namespace() -> None:
    assert camera_of_topic("/cam_k/face_reid/frames_sealed") == "cam_k"
    assert camera_of_topic("/site/cam1/face_reid/frames") == "cam1"
    assert camera_of_topic("/cam_k/e001/face_reid/frames_sealed") == "e001"  # merely contains the id: not cam_k's
    assert camera_of_topic("/face_reid/frames_sealed") == ""


def test_bad_bounds_are_refused() -> None:
    with pytest.raises(ValueError):
        CameraSlots(0, authenticate=True)


def test_two_cameras_under_one_camera_id_are_named() -> None:
    """Frames naming one camera id on two topics, or a camera topic of two publishing nodes: one warning each,
    naming both (before: nothing anywhere)."""
    from face_reid_master.camera_slots import CameraIdWatch

    watch = CameraIdWatch(window_s=10.0)
    watch.frame("cam1", "/cam1/face_reid/frames", 0.0)
    watch.frame("cam2", "/cam2/face_reid/frames", 1.0)
    watch.frame("cam1", "", 1.0)  # a topic not known: not counted
    assert watch.warnings(2.0) == []
    watch.frame("cam1", "/cam3/face_reid/frames", 5.0)  # a third camera started with camera_id cam1
    said = watch.warnings(6.0)
    assert len(said) == 1 and "camera id 'cam1' is used by 2 cameras" in said[0]
    assert "/cam1/face_reid/frames" in said[0] and "/cam3/face_reid/frames" in said[0]
    assert watch.warnings(12.0) == []  # cam1's old topic has been silent for 12 s: no longer two cameras
    two = {"/cam1/face_reid/frames": ["/cam1/face_reid_camera (participant 01)",
                                      "/cam1/face_reid_camera (participant 02)"],
           "/cam2/face_reid/frames": ["/cam2/face_reid_camera (participant 03)"]}
    said = watch.warnings(12.0, two)
    assert len(said) == 1 and "camera topic '/cam1/face_reid/frames' is published by 2 nodes" in said[0]
    assert "(participant 01)" in said[0] and "(participant 02)" in said[0]
    many = CameraIdWatch(max_ids=3)
    for k in range(10):
        many.frame(f"cam{k}", f"/cam{k}/face_reid/frames", 0.0)
    assert len(many._topics) == 3  # bounded: a flood of camera ids does not grow it
