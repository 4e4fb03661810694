"""Sealing (AES-256-GCM with the network key): what a stranger cannot do, replays, clocks, key files."""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path

import pytest

from face_reid_camera.common.sealing import (
    KEY_BYTES,
    Opener,
    Sealer,
    SealError,
    load_network_key,
    write_network_key,
)

KEY = bytes(range(KEY_BYTES))
OTHER = bytes(reversed(range(KEY_BYTES)))
PAYLOAD = b"embedding \x00\x01\x02 of a person" * 10


def _code(opener: Opener, sealed, now_s: float | None = None) -> str:
    with pytest.raises(SealError) as info:
        opener.open(sealed, now_s)
    return info.value.code


def test_a_holder_of_the_key_opens_what_another_holder_sealed_and_nobody_reads_it_on_the_way() -> None:
    sealed = Sealer(KEY, "cam_a").seal(PAYLOAD)
    assert b"embedding" not in sealed.ciphertext and PAYLOAD[:16] not in sealed.ciphertext
    assert Opener(KEY).open(sealed) == PAYLOAD


def test_a_stranger_can_neither_open_nor_forge_nor_alter() -> None:
    sealed = Sealer(KEY, "cam_a").seal(PAYLOAD)
    assert _code(Opener(OTHER), sealed) == "forged"  # another key cannot read it
    assert _code(Opener(KEY), Sealer(OTHER, "cam_a").seal(PAYLOAD)) == "forged"  # nor write one
    flipped = bytearray(sealed.ciphertext)
    flipped[3] ^= 1
    assert _code(Opener(KEY), dataclasses.replace(sealed, ciphertext=bytes(flipped))) == "forged"
    assert _code(Opener(KEY), dataclasses.replace(sealed, sender_id="cam_b")) == "forged"  # the sender is sealed too
    assert _code(Opener(KEY), dataclasses.replace(sealed, counter=sealed.counter + 1)) == "forged"
    # a seal made for frames is not an admin request
    assert _code(Opener(KEY, purpose="forget_face"), sealed) == "forged"


def test_replays_are_refused_per_sender_and_a_reordered_message_still_opens_once() -> None:
    a, b = Sealer(KEY, "cam_a"), Sealer(KEY, "cam_b")
    first, second, other = a.seal(b"1"), a.seal(b"2"), b.seal(b"3")
    assert second.counter != first.counter
    opener = Opener(KEY)
    assert opener.open(second) == b"2"
    assert _code(opener, second) == "replayed"
    assert opener.open(first) == b"1"  # reordered on the way: not seen yet (freshness is the clock's check)
    assert _code(opener, first) == "replayed"
    assert opener.open(other) == b"3"  # another sender has its own counters
    assert opener.open(a.seal(b"4")) == b"4"


def test_seals_far_from_the_receivers_clock_are_refused() -> None:
    sealed = Sealer(KEY, "cam_a").seal(PAYLOAD)
    opener = Opener(KEY, max_age_s=30.0)
    assert _code(opener, sealed, time.time() + 60.0) == "stale"  # an old recording replayed to a fresh master
    assert _code(opener, sealed, time.time() - 60.0) == "stale"  # a sender whose clock runs a minute ahead
    assert opener.open(sealed, time.time() + 10.0) == PAYLOAD


def test_malformed_seals_are_refused_with_a_reason() -> None:
    sealed = Sealer(KEY, "cam_a").seal(PAYLOAD)
    opener = Opener(KEY)
    assert _code(opener, dataclasses.replace(sealed, nonce=b"short")) == "malformed"
    assert _code(opener, dataclasses.replace(sealed, ciphertext=b"")) == "malformed"
    assert _code(opener, dataclasses.replace(sealed, sender_id="")) == "malformed"
    assert _code(opener, dataclasses.replace(sealed, sender_id="x" * 100_000)) == "malformed"
    assert _code(opener, dataclasses.replace(sealed, counter=0)) == "malformed"


def test_arguments_are_checked_by_name() -> None:
    with pytest.raises(ValueError, match="32 bytes"):
        Sealer(b"short", "cam_a")
    with pytest.raises(ValueError, match="sender_id"):
        Sealer(KEY, "")
    with pytest.raises(ValueError, match="max_age_s"):
        Opener(KEY, max_age_s=0.0)


def test_key_files_are_private_and_checked(tmp_path: Path) -> None:
    path = write_network_key(tmp_path / "keys" / "network.key")
    assert path.stat().st_mode & 0o777 == 0o600
    key = load_network_key(path)
    assert len(key) == KEY_BYTES and key != load_network_key(write_network_key(tmp_path / "second.key"))
    with pytest.raises(ValueError, match="not overwritten"):
        write_network_key(path)
    os.chmod(path, 0o644)
    with pytest.raises(ValueError, match="readable by others"):
        load_network_key(path)
    os.chmod(path, 0o600)
    link = tmp_path / "link.key"
    link.symlink_to(path)
    with pytest.raises(ValueError, match="is a symlink: refused"):
        load_network_key(link)
    bad = tmp_path / "bad.key"
    bad.write_text("not hex")
    bad.chmod(0o600)
    with pytest.raises(ValueError, match="hex digits"):
        load_network_key(bad)
    with pytest.raises(ValueError, match="face-reid-keys new"):
        load_network_key(tmp_path / "missing.key")


def test_face_reid_keys_makes_and_checks_a_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from face_reid_camera.tools.keys import main

    path = tmp_path / "network.key"
    assert main(["new", str(path)]) == 0 and path.stat().st_mode & 0o777 == 0o600
    assert main(["check", str(path)]) == 0
    assert main(["new", str(path)]) == 2 and "not overwritten" in capsys.readouterr().err
    path.chmod(0o640)
    assert main(["check", str(path)]) == 2 and "chmod 600" in capsys.readouterr().err


def test_face_reid_keys_says_what_to_do(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: '(remove it first)' though --force exists; 'is not a regular file (symlinks are refused)' for a
    folder; a traceback for --force onto a folder."""
    from face_reid_camera.tools.keys import main

    path = tmp_path / "network.key"
    assert main(["new", str(path)]) == 0
    capsys.readouterr()
    assert main(["new", str(path)]) == 2
    assert capsys.readouterr().err == (f"face-reid-keys: {path} exists: a network key is not overwritten "
                                       "(face-reid-keys new --force replaces it; every host then needs the new key)\n")
    assert main(["check", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"face-reid-keys: network key {tmp_path} is a folder: give the key file in it\n"
    assert main(["new", "--force", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"face-reid-keys: {tmp_path}: Is a directory\n"


def test_a_receiver_refuses_what_was_sealed_before_it_started_so_a_restart_reopens_no_replay() -> None:
    captured = Sealer(KEY, "admin").seal(PAYLOAD)  # overheard before the receiver (re)started
    restarted = Opener(KEY, not_before_s=time.time())
    assert _code(restarted, captured) == "replayed"  # within max_age_s, but older than the receiver
    assert restarted.open(Sealer(KEY, "admin").seal(PAYLOAD)) == PAYLOAD  # what is sealed now still opens
    assert Opener(KEY).open(captured) == PAYLOAD  # without not_before_s only the counters in memory protect


def test_a_counter_far_ahead_from_a_key_holder_does_not_make_the_real_frames_replayed() -> None:
    """8d: one frame sealed 25 s ahead (a key holder, or a clock glitch) must not cost the camera 25 s."""
    now = time.time()
    opener = Opener(KEY, max_age_s=30.0)
    ahead = Sealer(KEY, "cam_a")
    with _clock_at(now + 25.0):
        future = ahead.seal(b"ahead")
    assert opener.open(future, now) == b"ahead"
    real = Sealer(KEY, "cam_a")
    for k in range(250):  # the next 25 s of a 10 Hz camera
        with _clock_at(now + k * 0.1):
            sealed = real.seal(b"%d" % k)
        assert opener.open(sealed, now + k * 0.1) == b"%d" % k
    assert _code(opener, future, now + 1.0) == "replayed"  # and the one ahead is still not opened twice


def test_a_sender_whose_clock_stepped_back_is_heard_at_once_and_replays_stay_refused() -> None:
    """A camera's clock +120 s for 5 s, then corrected: its counters follow the corrected clock (no clamp)."""
    now = time.time()
    sealer, opener = Sealer(KEY, "cam_a"), Opener(KEY, max_age_s=30.0)
    with _clock_at(now):
        before = sealer.seal(b"before")
    with _clock_at(now + 120.0):
        sealer.seal(b"glitch")  # stale at the receiver (refused, counted by the caller)
    with _clock_at(now + 5.0):
        after = sealer.seal(b"after")
    assert opener.open(before, now) == b"before"
    assert opener.open(after, now + 5.0) == b"after"
    assert _code(opener, before, now + 5.0) == "replayed"
    assert _code(opener, after, now + 6.0) == "replayed"


def test_the_replay_cache_is_pruned_by_age_and_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    import face_reid_camera.common.sealing as sealing

    now = time.time()
    opener, sealer = Opener(KEY, max_age_s=1.0), Sealer(KEY, "cam_a")
    old = []
    for k in range(100):
        with _clock_at(now + k * 0.1):
            sealed = sealer.seal(b"x")
        opener.open(sealed, now + k * 0.1)
        old.append(sealed)
    assert opener._seen_total <= 11  # only the last max_age_s of counters are kept
    assert _code(opener, old[-1], now + 9.95) == "replayed"  # still in the window: remembered
    assert _code(opener, old[0], now + 9.95) == "stale"
    monkeypatch.setattr(sealing, "_MAX_SEEN", 50)
    flood = Opener(KEY, max_age_s=30.0)
    senders = [Sealer(KEY, f"holder{k}") for k in range(20)]
    for k in range(200):
        flood.open(senders[k % 20].seal(b"x"))
    assert flood._seen_total <= 50
    first = senders[0].seal(b"y")
    flood.open(first)
    assert _code(flood, first) == "replayed"


def test_the_start_guard_follows_a_corrected_clock() -> None:
    """A receiver started while its clock ran 120 s ahead: once corrected, fresh messages open at once."""
    mono = [100.0]
    now = time.time()
    with _clock_at(now + 120.0):
        opener = Opener(KEY, max_age_s=30.0, not_before_s=now + 120.0, monotonic=lambda: mono[0])
    mono[0] += 6.0
    with _clock_at(now + 6.0):
        fresh = Sealer(KEY, "cam_a").seal(b"fresh")
    assert opener.open(fresh, now + 6.0) == b"fresh"
    with _clock_at(now - 1.0):
        captured = Sealer(KEY, "cam_a").seal(b"captured")  # sealed before the receiver started
    assert _code(opener, captured, now + 6.0) == "replayed"


class _clock_at:
    """time.time_ns / time.time of the sealing module at ``t`` (s) inside the with block (a stepped clock)."""

    def __init__(self, t: float) -> None:
        self.t = t

    def __enter__(self) -> None:
        import face_reid_camera.common.sealing as sealing

        self._patch = pytest.MonkeyPatch()
        fake = type("FakeTime", (), {"time_ns": staticmethod(lambda: int(self.t * 1e9)),
                                     "time": staticmethod(lambda: self.t), "monotonic": staticmethod(time.monotonic)})
        self._patch.setattr(sealing, "time", fake)

    def __exit__(self, *exc: object) -> None:
        self._patch.undo()
