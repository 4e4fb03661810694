#!/usr/bin/env python3
"""Print who is where, from the face-reid master's /tracks_named (a robot's view of the camera network).

Usage: who_is_where.py [COUNT [KEYFILE]]: stop after COUNT messages (0, the default: never; Ctrl-C ends it);
KEYFILE: a secured network's key file (then only sealed tracks are taken). A message that says what the one
before it said (nobody there, or the same people at the same places) is not printed again."""

import os
import signal
import sys

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

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


def main() -> int:
    args = remove_ros_args(sys.argv)[1:]
    if len(args) > 2 or not (args[:1] or ["0"])[0].isdigit():
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    count = int(args[0]) if args else 0  # stop after this many messages (0: never)
    key = args[1] if len(args) > 1 else ""  # a secured network's key file: only sealed tracks are taken
    seen, said = [0], [""]

    def on_tracks(msg: NamedTrackArray) -> None:
        lines = [line for line in map(describe, msg.tracks) if line]
        text = "\n  ".join([f"{len(lines)} people in '{msg.header.frame_id}':", *lines])
        if text != said[0]:  # tracks come many times a second: what has not changed is said once
            print(text, flush=True)  # one write per message: a Ctrl-C while printing cuts no message in half
            said[0] = text
        seen[0] += 1

    stop = []  # Ctrl-C only asks the loop to end (a KeyboardInterrupt inside rclpy could surface as another error)
    signal.signal(signal.SIGINT, lambda *_: stop.append(True))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("who_is_where")
    executor = SingleThreadedExecutor()  # made before the waiting line: a Ctrl-C then never meets a half-made one
    executor.add_node(node)
    try:
        # checks sealed tracks; says when a key is needed, and how to give it
        tracks = subscribe_tracks(node, on_tracks, "/tracks_named", key,
                                  key_hint="give the network's key file as KEYFILE (who_is_where.py 0 KEYFILE)")
        print(f"who_is_where: waiting for {'sealed ' if key else ''}tracks on {tracks.listening} "
              f"(ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}); Ctrl-C ends", file=sys.stderr, flush=True)
        while not stop and (count == 0 or seen[0] < count):
            executor.spin_once(timeout_sec=0.5)
    except ValueError as exc:  # an unusable key file: one line
        print(f"who_is_where: {exc}", file=sys.stderr)
        return 2
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
