"""Run a MAVSDK-Python example unchanged, its waits paced to a vehicle flying faster than real time.

usage: .venv-mavsdk3/bin/python tests/compat/paced.py FACTOR EXAMPLE.py

The examples wait with ``asyncio.sleep(seconds)``, seconds of the wall clock, as against PX4 SITL
at real time. Against a vehicle at ``quadsitl up --speed FACTOR`` this runs the example's file as it
is (``runpy``, as ``__main__``) with ``asyncio.sleep`` dividing each wait by FACTOR, so the example
waits the same simulated seconds as it does against a vehicle at real time, in 1/FACTOR of the wall
time. Nothing else of the example changes: its calls, their order and their arguments are its own.
Runs under MAVSDK-Python 3 (``.venv-mavsdk3``); no quadsitl import.
"""

from __future__ import annotations

import asyncio
import runpy
import sys


def main() -> None:
    factor, example = float(sys.argv[1]), sys.argv[2]
    assert factor >= 1.0, "FACTOR is the vehicle's --speed, at least 1"
    wall_sleep = asyncio.sleep

    async def paced_sleep(delay: float, result=None):
        return await wall_sleep(delay / factor, result)

    asyncio.sleep = paced_sleep
    sys.argv = [example]
    runpy.run_path(example, run_name="__main__")


if __name__ == "__main__":
    main()
