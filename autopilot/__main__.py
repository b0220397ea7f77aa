"""``python -m autopilot``: the flight-controller process (see autopilot/app.py)."""

import sys

from .app import main

sys.exit(main())
