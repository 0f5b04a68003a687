"""``python -m skinfit``: the command line (same as the ``skinfit`` script)."""

import sys

from skinfit.apps.cli import main

sys.exit(main())
