"""The master's pure core: camera frames in, named tracks out (no rclpy); :mod:`.master` tells the frame's way."""

from face_reid_master.core.config import MasterConfig
from face_reid_master.core.master import MasterCore
from face_reid_master.core.records import FrameOutcome, MasterStats

__all__ = ["FrameOutcome", "MasterConfig", "MasterCore", "MasterStats"]
