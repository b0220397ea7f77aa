"""``python -m autopilot``: the flight-controller process (autopilot/app.py), its command line."""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import time

from quadcommon import bus
from quadcommon.build_info import this_build
from quadcommon.schema import ConfigError
from quadcommon.udp import PortInUse

from .app import Autopilot
from .logger.logger import LogOptions
from .mavlink.signing import SigningOptions
from .setup import AutopilotSetup


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m autopilot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N (ports +N, sysid 1+N)")
    parser.add_argument("--controller", default="intbs_nlhinf", help="cascade (config/controllers)")
    parser.add_argument("--vehicle", default="paper_quad", help="vehicle (config/vehicle)")
    parser.add_argument("--sitl-config", default=None, help="path of an alternative sitl.toml")
    parser.add_argument(
        "--autostart",
        metavar="SCENARIO",
        default=None,
        help="arm at t=0 and fly the scenario's trajectory (the paper's experiment)",
    )
    parser.add_argument("--state-source", choices=("odometry", "hil_state_quaternion"), default="odometry",
                        help="where the truth comes from (with --estimator truth)")  # fmt: skip
    parser.add_argument("--estimator", choices=("truth", "ekf"), default="truth",
                        help="fly on the simulator's truth (the paper's assumption) or on the EKF's estimate "
                        "of the sensors (EKF2_EN; default: truth)")  # fmt: skip
    parser.add_argument("--estimator-profile", default="default", metavar="NAME",
                        help="config/estimator/NAME.toml: the EKF2_* values to start from (default: PX4's)")
    parser.add_argument("--no-zenoh", action="store_true", help="do not publish controller internals")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--params", metavar="FILE", default=None,
                        help="parameter file (params.toml, NAME = value): loaded at start if it exists, "
                        "saved on every change and on MAV_CMD_PREFLIGHT_STORAGE")  # fmt: skip
    parser.add_argument("--signing-key", metavar="FILE", default=None,
                        help="MAVLink 2 signing on the GCS links with this key: one line, 64 hex digits "
                        "or a passphrase (hashed as MAVProxy's 'signing setup PASSPHRASE')")  # fmt: skip
    parser.add_argument("--signing-state", metavar="FILE", default=None,
                        help="where the signing key and timestamps persist (default: signing-N.json "
                        "beside --params, else beside --signing-key, else in memory)")  # fmt: skip
    parser.add_argument("--log-dir", metavar="DIR", default="log",
                        help="flight logs (ULog) go to DIR/YYYY-MM-DD/HH_MM_SS.ulg as PX4's, when SDLOG_MODE "
                        "says (default 0: from arming to disarming), and the MAVLink log download serves "
                        "them (default: log under the working directory)")  # fmt: skip
    parser.add_argument("--no-log", action="store_true",
                        help="no flight log at all (the log download lists none)")  # fmt: skip
    parser.add_argument("--spacing", type=float, default=0.0, metavar="M",
                        help="this instance's home N x M metres north of sitl.toml's (quadsitl up --spacing; "
                        "the simulator takes the same)")  # fmt: skip
    parser.add_argument("--impair", action="append", default=[], metavar="LINK:SPEC",
                        help="impair a link, e.g. gcs:loss=5%%,delay=50ms (repeatable; replaces that link's "
                        "[impair] entry of sitl.toml; docs/links.md)")  # fmt: skip
    args = parser.parse_args(argv)
    try:
        setup = AutopilotSetup.load(args.instance, args.controller, args.vehicle, args.sitl_config,
                                    args.autostart, args.state_source, args.params, args.estimator,
                                    args.estimator_profile)  # fmt: skip
        signing = SigningOptions(args.signing_key, args.signing_state, epoch_clock=time.time)
        build = this_build()  # AUTOPILOT_VERSION and the flight log's version
        log = LogOptions(None if args.no_log else args.log_dir, utc_clock=time.time, version=build.version)
        setup = dataclasses.replace(setup, signing=signing, log=log, build=build,
                                    sitl=setup.sitl.spaced(args.instance, args.spacing))
        if args.impair:
            impair = setup.sitl.impair.with_specs(args.impair)
            setup = dataclasses.replace(setup, sitl=dataclasses.replace(setup.sitl, impair=impair))
        app = Autopilot(setup, zenoh=not args.no_zenoh, quiet=args.quiet)
        app.open()
    except (ConfigError, ValueError) as exc:
        print(f"autopilot: {exc}", file=sys.stderr)
        return 2
    except (PortInUse, bus.BusError) as exc:
        print(f"autopilot: {exc}; is another vehicle running with --instance {args.instance}? "
              "(pick another --instance)", file=sys.stderr)  # fmt: skip
        return 2
    signal.signal(signal.SIGTERM, app.stop)
    signal.signal(signal.SIGINT, app.stop)
    try:
        return app.run()
    finally:
        app.close()
        print("autopilot: stopped", flush=True)


if __name__ == "__main__":
    from quadcommon.shell import exit_process

    exit_process(main())
