"""What the process mains share at their edge: how they end."""

from __future__ import annotations

import os
import sys
from typing import NoReturn


def exit_process(code: int | None) -> NoReturn:
    """End the process now, with ``code``, after flushing stdout and stderr.

    For the simulator's and the autopilot's mains once ``main()`` has returned: by then they have
    closed their sockets and zenoh sessions and written what they persist. The interpreter's own
    teardown after that costs 0.3-0.5 s of CPU (measured: a process that has loaded the compiled
    plant exits 0.34 s after its last line, one that has only imported numpy 0.01 s; numba's and
    LLVM's finalisers), which every run and every test that starts a process would wait for.
    """
    if sys.getprofile() is not None:  # under cProfile (benchmarks/sitl_rtf.py --profile): let it
        sys.exit(code or 0)  # write its statistics as the interpreter ends
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can reach it
            pass
    os._exit(code or 0)
