"""Print who is where, from the face-reid master's /tracks_named (a robot's view of the camera network)."""

import sys

import rclpy

from face_reid_master.ros.tracks_in import subscribe_tracks
from face_reid_msgs.msg import NamedTrack, NamedTrackArray


def describe(track: NamedTrack) -> str | None:
    """One line per person a robot may act on; None for what it should ignore."""
    if track.state == NamedTrack.STATE_TENTATIVE:
        return None  # not confirmed yet: may be noise
    who = track.name or (f"face {track.face_id}" if track.face_id else "someone unknown")  # face_id 0: undecided
    where = f"({track.position.x:.2f}, {track.position.y:.2f}) m"
    if track.state == NamedTrack.STATE_LOST:
        where += ", predicted (not seen for a while)"  # a lost track's position is a guess
    sure = f"{track.identity_confidence:.2f} by {track.identity_evidence}" if track.face_id else "no identity yet"
    return f"track {track.track_id}: {who} at {where}; identity {sure}"


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("who_is_where")
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 0  # stop after this many messages (0: never)
    key = sys.argv[2] if len(sys.argv) > 2 else ""  # a secured network's key file: only sealed tracks are taken
    seen = [0]

    def on_tracks(msg: NamedTrackArray) -> None:
        lines = [line for line in map(describe, msg.tracks) if line]
        print(f"{len(lines)} people in '{msg.header.frame_id}':", *lines, sep="\n  ", flush=True)
        seen[0] += 1

    subscribe_tracks(node, on_tracks, "/tracks_named", key)  # checks sealed tracks; says when a key is needed
    while rclpy.ok() and (count == 0 or seen[0] < count):
        rclpy.spin_once(node, timeout_sec=0.5)
    rclpy.shutdown()


if __name__ == "__main__":
    main()
