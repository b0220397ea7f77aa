"""``quadsitl up``: simulator + autopilot per vehicle as two OS processes, linked, in the foreground.

Every port is checked first (a port in use is an error naming the port and ``--instance``); the
processes start through the one launcher (:mod:`sitl.launcher`), which waits until each simulator
reports its autopilot linked; the endpoints a ground station connects to are printed; Ctrl-C or
SIGTERM stops everything (SIGTERM, then SIGKILL after a grace period). Children die with the
launcher in any case (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Sequence

from quadcommon import wire

from .launcher import Launcher, LaunchError, VehicleSpec

__all__ = ["LaunchError", "VehicleSpec", "endpoints_banner", "run_up"]


def endpoints_banner(spec: VehicleSpec, ports: wire.Ports) -> str:
    n = spec.instance
    speed = f"{spec.speed}{'x' if spec.speed != 'max' else ''}"
    return "\n".join(
        [
            f"quadsitl: vehicle {n} is up (MAVLink sysid {wire.system_id(n)}, controller {spec.controller}, "
            f"scenario {spec.scenario}, speed {speed})",
            f"  QGroundControl / MAVProxy : udp {ports.gcs_remote}   "
            f"(mavproxy.py --master=udpin:127.0.0.1:{ports.gcs_remote})",
            f"  MAVSDK / API scripts      : udpin://0.0.0.0:{ports.api_remote}   "
            f"(pymavlink: udpin:127.0.0.1:{ports.api_remote})",
            f"  zenoh (truth, internals)  : tcp/127.0.0.1:{ports.zenoh}   "
            f"keys quadsitl/{n}/truth, quadsitl/{n}/controller",
        ]
    )


def _echo(name: str, line: str) -> None:
    print(f"[{name}] {line}", flush=True)


def run_up(specs: Sequence[VehicleSpec]) -> int:
    """Foreground ``quadsitl up``: until Ctrl-C / SIGTERM or a process exits."""
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    launcher = Launcher(echo=_echo)
    try:
        launcher.start_vehicles(specs)
    except LaunchError as exc:
        print(f"quadsitl: {exc}", file=sys.stderr)
        return 2
    for spec in specs:
        print(endpoints_banner(spec, launcher.ports[spec.instance]), flush=True)
    print("  Ctrl-C stops every process.", flush=True)
    code = 0
    try:
        while not stop.wait(0.2):
            exited = launcher.first_exited()
            if exited is not None:
                rc = exited.returncode
                if not (rc == 0 and exited.name.startswith("simulator")):  # --duration reached
                    print(f"quadsitl: {exited.name} exited with code {rc}; stopping", file=sys.stderr)
                    code = 1
                break
    finally:
        print("quadsitl: stopping ...", flush=True)
        launcher.stop()
        print("quadsitl: stopped", flush=True)
    return code
