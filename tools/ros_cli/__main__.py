"""`python -m ros_cli ARGS` (tools/ on the path; launchless_scripts/ros does that)."""

import sys

from .cli import main

sys.exit(main())
