"""``python -m simulator``: the simulator process (see simulator/app.py)."""

import sys

from .app import main

sys.exit(main())
