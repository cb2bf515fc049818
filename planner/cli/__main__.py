"""``python -m planner.cli``: the ``lrauv`` command."""

import sys

from planner.cli import main

sys.exit(main())
