"""TracksVerifier and check_network: who may put tracks in front of a consumer on a secured network."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from face_reid_camera.common.sealing import Sealed, Sealer, SealError, load_network_key, write_network_key
from face_reid_master.tracks_auth import TRACKS_PURPOSE, TracksVerifier, check_network, sealed_topic

PAYLOAD = b"\x00\x01\x00\x00 serialized tracks"


@pytest.fixture
def key(tmp_path: Path) -> bytes:
    return load_network_key(write_network_key(tmp_path / "network.key"))


def test_the_masters_sealed_tracks_open_once(key: bytes) -> None:
    master = Sealer(key, "/face_reid_master", TRACKS_PURPOSE)
    verifier = TracksVerifier(key)
    sealed = master.seal(PAYLOAD)
    assert verifier.open(sealed) == PAYLOAD
    with pytest.raises(SealError) as replay:
        verifier.open(sealed)  # the same message again (a replay)
    assert replay.value.code == "replayed"
    assert verifier.open(master.seal(PAYLOAD)) == PAYLOAD
    assert verifier.refused == {"replayed": 1}


def test_tracks_from_another_key_or_sealed_for_another_purpose_are_forged(key: bytes, tmp_path: Path) -> None:
    stranger = load_network_key(write_network_key(tmp_path / "stranger.key"))
    verifier = TracksVerifier(key)
    with pytest.raises(SealError) as other_key:
        verifier.open(Sealer(stranger, "/face_reid_master", TRACKS_PURPOSE).seal(PAYLOAD))
    camera_frame = Sealer(key, "cam_a").seal(PAYLOAD)  # a camera's sealed frame passed off as tracks
    with pytest.raises(SealError) as frame:
        verifier.open(camera_frame)
    good = Sealer(key, "/face_reid_master", TRACKS_PURPOSE).seal(PAYLOAD)
    tampered = Sealed(good.sender_id, good.counter, good.nonce, good.ciphertext[:-1] + bytes([good.ciphertext[-1] ^ 1]))
    with pytest.raises(SealError) as altered:
        verifier.open(tampered)
    renamed = Sealed("/other_master", good.counter, good.nonce, good.ciphertext)  # the sender is authenticated
    with pytest.raises(SealError) as sender:
        verifier.open(renamed)
    assert {other_key.value.code, frame.value.code, altered.value.code, sender.value.code} == {"forged"}
    assert verifier.refused == {"forged": 4}


def test_old_and_pre_start_tracks_are_refused(key: bytes) -> None:
    master = Sealer(key, "/face_reid_master", TRACKS_PURPOSE)
    captured = master.seal(PAYLOAD)  # sealed before the consumer started
    time.sleep(0.01)
    verifier = TracksVerifier(key, max_age_s=5.0)
    with pytest.raises(SealError) as before_start:
        verifier.open(captured)
    with pytest.raises(SealError) as stale:
        verifier.open(master.seal(PAYLOAD), now_s=time.time() + 60.0)  # this host's clock a minute later
    assert (before_start.value.code, stale.value.code) == ("replayed", "stale")


def test_check_network_tells_a_keyless_consumer_the_tracks_are_sealed() -> None:
    sealed = [("/tracks_named_sealed", ["face_reid_msgs/msg/Sealed"]), ("/rosout", ["rcl_interfaces/msg/Log"])]
    keyless = check_network(sealed, "/tracks_named", have_key=False, plain_publishers=0)
    assert keyless.secured_network and "set network_key_path" in keyless.problem
    assert "/tracks_named_sealed" in keyless.problem
    tool = check_network(sealed, "/tracks_named", False, 0, key_hint="give KEYFILE")  # a tool's own way
    assert "; give KEYFILE to read them" in tool.problem and "network_key_path" not in tool.problem
    assert check_network(sealed, "/tracks_named", have_key=True, plain_publishers=0).problem == ""
    spoof = check_network(sealed, "/tracks_named", have_key=True, plain_publishers=1)
    assert "ignored" in spoof.problem and "spoof" in spoof.problem
    unsecured = check_network([("/tracks_named", ["face_reid_msgs/msg/NamedTrackArray"])], "/tracks_named",
                              have_key=False, plain_publishers=1)
    assert not unsecured.secured_network and unsecured.problem == ""
    wrong_type = check_network([("/tracks_named_sealed", ["std_msgs/msg/String"])], "/tracks_named", False, 0)
    assert not wrong_type.secured_network
    assert sealed_topic("/robot/tracks_named") == "/robot/tracks_named_sealed"
