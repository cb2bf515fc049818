"""``python -m planner``: the same as ``lrauv`` (the executive runs onboard replans this way)."""

import sys

from planner.cli import main

sys.exit(main())
