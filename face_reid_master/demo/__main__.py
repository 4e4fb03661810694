"""``python -m face_reid_master.demo``: the built-in demo (same as the ``face-reid-demo`` console script)."""

import sys

from face_reid_master.demo.run import main

sys.exit(main())
