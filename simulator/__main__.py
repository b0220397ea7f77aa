"""``python -m simulator``: the plant process (see simulator/app.py), its command line."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import signal
import sys

from quadcommon import wire
from quadcommon.schema import ConfigError

from .app import Simulator, StartupError
from .core import SimulatorSetup
from .pacing import parse_speed


def with_impairments(setup: SimulatorSetup, specs: list[str]) -> SimulatorSetup:
    """``--impair LINK:SPEC`` over the sitl.toml's ``[impair]`` (ImpairmentError names the value)."""
    sitl = setup.sitl
    return dataclasses.replace(setup, sitl=dataclasses.replace(sitl, impair=sitl.impair.with_specs(specs)))


# -- command line -----------------------------------------------------------------------------------
def _speed(text: str) -> float | None:
    try:
        return parse_speed(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _duration(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--duration must be a number of seconds, got {text!r}") from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"--duration must be > 0 s, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simulator",
        description="The quadsitl simulator process (plant side of the SITL, lockstep over MAVLink HIL).",
    )
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N (ports +N, sysid 1+N)")
    parser.add_argument("--vehicle", default=None, help="vehicle (config/vehicle); default: the scenario's")
    parser.add_argument("--scenario", default="hover", help="scenario (config/scenarios); default: hover")
    parser.add_argument(
        "--speed", type=_speed, default=1.0, help="wall-clock pacing: a factor (1 = real time) or 'max'"
    )
    parser.add_argument("--duration", type=_duration, default=None, help="stop after S simulated seconds")
    parser.add_argument("--config-dir", default=None,
                        help="a directory of your own configuration, looked in before the shipped one "
                        "(also QUADSITL_CONFIG_DIR)")  # fmt: skip
    parser.add_argument("--sitl-config", default=None, help="path of an alternative sitl.toml")
    parser.add_argument("--sensors", default=None,
                        help="sensor profile: ideal, mocap, gps (config/sensors; default: the scenario's)")
    parser.add_argument("--spacing", type=float, default=0.0, metavar="M",
                        help="this instance's home N x M metres north of sitl.toml's (quadsitl up --spacing; "
                        "the autopilot takes the same)")  # fmt: skip
    parser.add_argument("--impair", action="append", default=[], metavar="LINK:SPEC",
                        help="impair a link, e.g. hil:loss=1%%,delay=5ms (repeatable; replaces that link's "
                        "[impair] entry of sitl.toml; docs/links.md)")  # fmt: skip
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.config_dir is not None:
        import quadcommon.config as qconfig

        try:  # first in QUADSITL_CONFIG_DIR: names are looked up there, then in the shipped files
            os.environ.update(qconfig.with_config_dir(args.config_dir, os.environ))
        except ConfigError as exc:
            print(f"simulator: {exc}", file=sys.stderr)
            return 2
    try:
        setup = SimulatorSetup.load(
            args.instance, args.scenario, args.vehicle, args.sitl_config, args.sensors
        )
        if args.spacing:
            setup = dataclasses.replace(setup, sitl=setup.sitl.spaced(args.instance, args.spacing))
        if args.impair:
            setup = with_impairments(setup, args.impair)
        app = Simulator(setup, args.speed, args.duration)
    except (ConfigError, ValueError) as exc:
        print(f"simulator: {exc}", file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, app.stop)
    signal.signal(signal.SIGINT, app.stop)
    code = 2
    opened = False
    try:
        app.open()
        opened = True
        speed = "max" if app.speed is None else f"{app.speed:g}x"
        v, core = setup.vehicle, app.core
        app.log(
            f"instance {app.instance}, vehicle {v.name} (actuation {v.actuation.mode}, "
            f"plant {v.plant.model}), scenario {setup.scenario.name}, physics {core.physics_hz:g} Hz, "
            f"control {core.control_hz:g} Hz, "
            f"speed {speed}; truth on zenoh {wire.zenoh_key(app.instance, 'truth')} "
            f"(tcp/{wire.LOOPBACK}:{app.ports.zenoh})"
        )
        code = app.run()
    except StartupError as exc:
        print(f"simulator: {exc}", file=sys.stderr)
        return 2
    finally:
        app.close()
        if opened:
            app.log(app.summary())
    return code


if __name__ == "__main__":
    from quadcommon.shell import exit_process

    exit_process(main())
