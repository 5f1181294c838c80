"""``python -m ros_bridge``: the same as ``vgn-ros``."""

import sys

from ros_bridge.cli import main

sys.exit(main())
