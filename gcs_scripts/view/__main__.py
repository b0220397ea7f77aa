"""``python -m gcs_scripts.view``: the same as ``quadsitl view``."""

import sys

from .server import main

sys.exit(main(prog="python -m gcs_scripts.view"))
