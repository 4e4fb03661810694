"""MasterHealthWatch: what the master's /diagnostics says about its store, lost faces, overload and a second
master (pure: counters in, errors and warnings out)."""

from __future__ import annotations

from face_reid_camera.common.diagnostics import DiagnosticLevel, NodeHealth
from face_reid_master.health import MasterHealthWatch


def test_all_well_says_nothing() -> None:
    v = MasterHealthWatch().verdict(1.0, frames_in=100, frames_dropped_overload=1, store_last_write_ok=True)
    assert v.errors == [] and v.warnings == []


def test_a_failing_store_is_an_error_with_its_reason_and_a_recovered_one_a_warning() -> None:
    watch = MasterHealthWatch(recovered_warn_s=60.0)
    v = watch.verdict(10.0, store_write_failures=2, store_last_write_ok=False,
                      store_last_error="FaceStoreError: database or disk is full")
    assert len(v.errors) == 1 and "disk full" in v.errors[0] and "not saved" in v.errors[0]
    v = watch.verdict(20.0, store_write_failures=2, store_last_write_ok=True, store_last_error="FaceStoreError: x")
    assert v.errors == [] and len(v.warnings) == 1 and "2 face store write(s) failed" in v.warnings[0]
    assert watch.verdict(71.0, store_write_failures=2, store_last_write_ok=True).warnings == []  # long recovered


def test_faces_lost_at_open_warn_for_the_whole_run() -> None:
    watch = MasterHealthWatch()
    watch.store_opened(lost_face_ids=[3, 4], recovered_from="/db/faces.db.corrupt-1", salvaged_face_ids=[1])
    for now in (1.0, 5000.0):
        warnings = watch.verdict(now).warnings
        assert any("2 learned face(s) lost at open" in w and "3, 4" in w for w in warnings)
        assert any("corrupt" in w and "1 face(s) salvaged" in w for w in warnings)


def test_overload_warns_with_the_percentage_over_the_window() -> None:
    watch = MasterHealthWatch(overload_fraction=0.05, window_s=30.0)
    assert watch.verdict(0.0, frames_in=0, frames_dropped_overload=0).warnings == []
    assert watch.verdict(10.0, frames_in=1000, frames_dropped_overload=40).warnings == []  # 4 %
    (w,) = watch.verdict(20.0, frames_in=2000, frames_dropped_overload=120).warnings  # 6 % since 0 s
    assert "6.0 %" in w and "120 of 2000" in w
    # 30 s later: the window holds only recent frames, none dropped
    assert watch.verdict(60.0, frames_in=4000, frames_dropped_overload=120).warnings == []


def test_another_publisher_of_the_output_is_named() -> None:
    (w,) = MasterHealthWatch().verdict(1.0, other_publishers=["/site_b/face_reid_master"]).warnings
    assert "/site_b/face_reid_master" in w and "/tracks_named" in w


def test_a_keyless_publisher_of_the_sealed_output_is_not_called_a_second_master() -> None:
    """What another publisher of a secured master's tracks topic sent did not open with the key: a keyless
    participant, not a master (which would hold the key); once a message of another sender opens, a master."""
    others = ["/stranger"]
    (w,) = MasterHealthWatch().verdict(1.0, other_publishers=others, output_topic="/tracks_named_sealed",
                                       others_unopened=5).warnings
    assert "unauthenticated publisher of /tracks_named_sealed" in w and "/stranger" in w
    assert "keyless" in w and "one master per domain" not in w
    (w,) = MasterHealthWatch().verdict(1.0, other_publishers=others, others_unopened=5, others_opened=1).warnings
    assert "one master per domain" in w


def test_node_health_reports_errors_as_error_level() -> None:
    health = NodeHealth("m", "m")
    health.start(0.0)
    health.frame_in(0.5)
    report = health.report(1.0, warnings=["a warning"], errors=["store broken"])
    assert report.level == DiagnosticLevel.ERROR and report.message == "store broken; a warning"
