"""The ``quadsitl`` command line (the composition root's entry point).

quadsitl up [--instance N] [--scenario NAME]       the SITL: simulator + autopilot over MAVLink/UDP
quadsitl paper [--out DIR] [--nominal-plant]      the paper's experiment, in-process
quadsitl run SCENARIO [--controller NAME]          one in-process run
quadsitl campaign SPEC [--runs N] [--out DIR]       Monte Carlo campaign (sitl/campaign/)
quadsitl tune [--rise-time S] [--out FILE]          PX4's attitude autotune in-process (sitl/tune.py)
quadsitl view [--instance N ...] [LOG ...]         live view / replays in the browser
quadsitl fly setpoints|trajectory|paper ...        fly a running SITL (gcs_scripts/fly_*.py)
quadsitl mission upload|download|clear ...         the mission protocol (gcs_scripts/upload_mission.py)
  ... --instance 0-9 (or 0..9, 3,5,8)              the script once per vehicle, side by side
quadsitl gusts upload PROFILE ...                  disturbances (gcs_scripts/upload_gusts.py)
quadsitl record [--out DIR/NAME] ...               record a session (gcs_scripts/record.py)
quadsitl fail UNIT TYPE [--instance N] [--enable]  inject a failure, as PX4's failure command
quadsitl config copy DIR [--force]                 write the shipped configuration out for editing

Configuration names (scenarios, vehicles, gusts, ...) are looked up in --config-dir DIR, then in
the directories of QUADSITL_CONFIG_DIR (joined by ':'), then in the shipped configuration.
"""

from __future__ import annotations

import argparse
import os
import sys
from importlib import metadata
from pathlib import Path

from autopilot.control.config import CONTROLLER_NAMES
from autopilot.control.registry import ControllerFailure
from quadcommon.cli_help import HelpFormatter
from quadcommon.schema import ConfigError

# The ground-station scripts as subcommands: (group, name) -> module of gcs_scripts with
# main(argv, prog) and the arguments put before the user's (the same flags as the script).
DELEGATED: dict[tuple[str, str], tuple[str, tuple[str, ...], str]] = {
    ("fly", "setpoints"): ("fly_setpoints", (), "fly setpoints (default: a square) in OFFBOARD"),
    ("fly", "trajectory"): ("fly_trajectory", (), "fly a scenario's trajectory as streamed setpoints"),
    ("fly", "paper"): ("fly_paper", (), "the paper's curve as a TIMED mission, recorded"),
    ("mission", "upload"): ("upload_mission", (), "upload a mission file or --curve (and --fly it)"),
    ("mission", "download"): ("upload_mission", ("--download",), "print or --save the vehicle's mission"),
    ("mission", "clear"): ("upload_mission", ("--clear",), "clear the vehicle's mission"),
    ("gusts", "upload"): ("upload_gusts", (), "send a gust profile to the simulator (zenoh)"),
}
RECORD_MODULE = "record"
IMPAIR_MODULE = "impair"
FAIL_MODULE = "fail"
GROUP_HELP = {
    "fly": "fly a running SITL: setpoints, trajectory, paper (quadsitl fly NAME --help)",
    "mission": "the vehicle's mission: upload, download, clear (quadsitl mission NAME --help)",
    "gusts": "disturbances: upload a gust profile to the simulator (quadsitl gusts upload --help)",
}


def version() -> str:
    """The installed quadsitl version, or ``unknown (not installed)`` in a bare checkout."""
    try:
        return metadata.version("quadsitl")
    except metadata.PackageNotFoundError:  # a checkout run without installing it
        return "unknown (not installed)"


FAN_OUT_GROUPS = ("fly", "mission")  # --instance takes a range: the script once per vehicle (sitl/fan_out.py)


def _each_instance(argv: list[str]) -> int | None:
    """``quadsitl fly|mission NAME ... --instance 0-9``: the script once per instance, side by side
    (:mod:`sitl.fan_out`); None when ``--instance`` names one vehicle (or none)."""
    from . import fan_out

    prog = f"quadsitl {argv[0]} {argv[1]}"
    try:
        instances = fan_out.several_instances(argv[2:])
        if instances is None:
            return None
        fan_out.check_several(argv[2:])
    except fan_out.InstanceError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    command = [sys.executable, "-m", "sitl.cli", argv[0], argv[1]]  # (--config-dir: in the environment)
    return fan_out.run_each(command, argv[2:], instances, prog)


def _delegate(module: str, argv: list[str], prog: str) -> int:
    main = __import__(f"gcs_scripts.{module}", fromlist=["main"]).main
    return main(argv, prog=prog)


class _Parser(argparse.ArgumentParser):
    """Every subcommand's parser: its help lists the defaults (:class:`HelpFormatter`)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)


def _cmd_config(args: argparse.Namespace) -> int:
    from quadcommon.config import config_dirs, copy_shipped_config

    if args.action == "copy":
        written = copy_shipped_config(args.dir, force=args.force)
        print(f"wrote {len(written)} files to {args.dir}/ (edit them; use them with "
              f"--config-dir {args.dir} or QUADSITL_CONFIG_DIR={args.dir})")  # fmt: skip
        return 0
    for d in config_dirs():  # "where": the directories looked in, first match wins
        print(d)
    return 0


def _cmd_paper(args: argparse.Namespace) -> int:
    from .paper import run_paper

    out = Path(args.out)
    result = run_paper(
        out,
        scenarios=tuple(args.scenarios),
        controllers=tuple(args.controllers),
        nominal_plant=args.nominal_plant,
        workers=args.workers,
        duration_s=args.duration,
        estimator=args.estimator,
        sensors=args.sensors,
    )
    print(f"\nwrote {len(result.outputs)} files to {out}/:")
    print(f"  tables:  {out / 'tables.md'}  (+ table1_final_errors.csv, table2_ise.csv, table3_iadu.csv)")
    print(f"  figures: {out}/<scenario>_{{path3d,position,position_error,orientation,controls}}.png")
    print(f"  runs:    {out / 'runs'}/<scenario>_<controller>.parquet")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from autopilot.control.config import load_controller
    from gcs_scripts.analysis.metrics import indices
    from quadcommon.config import load_scenario

    from .inprocess import RunOptions, run_scenario

    record = run_scenario(
        load_scenario(args.scenario),
        load_controller(args.controller),
        RunOptions(nominal_plant=args.nominal_plant, duration_s=args.duration, estimator=args.estimator,
                   sensors=args.sensors),  # fmt: skip
    )
    ind = indices(record)
    e = ind.final_error_m
    print(f"{record.scenario} / {record.controller}: final error x={e[0]:+.5f} y={e[1]:+.5f} z={e[2]:+.5f} m")
    print("ISE  " + "  ".join(f"{k}={v:.5f}" for k, v in ind.ise.items()))
    print("IADU " + "  ".join(f"{k}={v:.4f}" for k, v in ind.iadu.items()))
    if args.out:
        path = record.write_parquet(args.out)
        print(f"time series written to {path}")
    return 0


def _estimation_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--estimator", choices=("truth", "ekf"), default=None,
                   help="what the autopilot flies on: the simulator's truth (the paper's assumption) or its "
                   "EKF over the sensors (default: the scenario's, truth for the paper's)")  # fmt: skip
    p.add_argument("--sensors", default=None, metavar="PROFILE",
                   help="sensor profile: ideal, mocap, gps (config/sensors; default: the scenario's, ideal)")


def speed_text(text: str) -> str:
    """``--speed`` checked (:func:`simulator.pacing.parse_speed`) and kept as text: the processes
    started get it as typed."""
    from simulator.pacing import parse_speed

    try:
        parse_speed(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _params_file(args: argparse.Namespace, instance: int, controller) -> str | None:
    """Vehicle ``instance``'s parameter file, checked now (a bad one fails before any process
    starts, naming file, key, value and range); a file that does not exist yet is created on the
    first save. Several vehicles need ``{instance}`` in the path: each saves its own."""
    if not args.params:
        return None
    if args.count > 1 and "{instance}" not in args.params:
        raise ConfigError(
            f"--params {args.params}: with --count {args.count} the path must contain {{instance}} "
            "(each vehicle saves its own parameters), e.g. params-{instance}.toml"
        )
    path = args.params.replace("{instance}", str(instance))
    if Path(path).exists():
        from autopilot.params.definitions import default_parameters
        from autopilot.params.storage import read_params_file
        from quadcommon.config import load_sitl

        read_params_file(path, default_parameters(controller, load_sitl(args.sitl_config).rates))
    return path


def _log_dir(args: argparse.Namespace, instance: int) -> str | None:
    """Vehicle ``instance``'s flight-log directory: --log-dir itself, or DIR/instance_N with several
    vehicles (PX4's multi-vehicle SITL gives each instance its own directory); None: --no-log."""
    if args.no_log:
        return None
    return args.log_dir if args.count == 1 else str(Path(args.log_dir) / f"instance_{instance}")


def _cmd_up(args: argparse.Namespace) -> int:
    from autopilot.control.config import load_controller
    from quadcommon import wire
    from quadcommon.config import MAX_SPACING_M, load_scenario, load_vehicle

    from .up import RestartPolicy, VehicleSpec, run_up

    last = args.instance + args.count - 1
    if args.count < 1 or not wire.INSTANCE_MIN <= args.instance <= last <= wire.INSTANCE_MAX:
        lo, hi = wire.INSTANCE_MIN, wire.INSTANCE_MAX
        print(f"quadsitl up: --instance {args.instance} --count {args.count}: instances must be in "
              f"[{lo}, {hi}] (got {args.instance}..{last})", file=sys.stderr)  # fmt: skip
        return 2
    if args.max_restarts < 0:
        print(f"quadsitl up: --max-restarts {args.max_restarts}: must be >= 0", file=sys.stderr)
        return 2
    if not 0.0 <= args.spacing <= MAX_SPACING_M:
        print(f"quadsitl up: --spacing {args.spacing}: metres between homes, in [0, {MAX_SPACING_M:g}]",
              file=sys.stderr)  # fmt: skip
        return 2
    restart = not args.no_restart and args.max_restarts > 0
    policy = RestartPolicy(enabled=restart, max_restarts=args.max_restarts)
    # Validate names here so a typo fails before any process starts.
    controller = load_controller(args.controller)
    load_scenario(args.scenario)
    load_vehicle(args.vehicle)
    params = [_params_file(args, args.instance + k, controller) for k in range(args.count)]
    if args.impair:  # a bad spec fails here, naming the value, before any process starts
        from quadcommon.impairment import ImpairConfig

        ImpairConfig().with_specs(args.impair)
    if args.signing_key:  # a bad key file fails here, before any process starts
        from autopilot.mavlink.signing import read_key_file

        read_key_file(args.signing_key)
    specs = [
        VehicleSpec(
            instance=args.instance + k, controller=args.controller, vehicle=args.vehicle,
            scenario=args.scenario, speed=args.speed, autostart=args.autostart,
            duration_s=args.duration, sitl_config=args.sitl_config, params_file=params[k],
            signing_key_file=str(Path(args.signing_key).resolve()) if args.signing_key else None,
            sensors=args.sensors, estimator=args.estimator, impair=tuple(args.impair),
            log_dir=_log_dir(args, args.instance + k), spacing_m=args.spacing,
        )
        for k in range(args.count)
    ]  # fmt: skip
    return run_up(specs, policy, view_port=args.view_port if args.view else None)


def _cmd_analyze(args: argparse.Namespace) -> int:
    from gcs_scripts.analysis.analyze import main as analyze_main

    return analyze_main(args.rest, prog="quadsitl analyze")


def build_parser() -> argparse.ArgumentParser:
    """The ``quadsitl`` command line: its global options and every subcommand."""
    parser = argparse.ArgumentParser(prog="quadsitl", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("--version", action="version", version=f"quadsitl {version()}")
    parser.add_argument(
        "--config-dir",
        metavar="DIR",
        default=None,
        help="your own configuration directory, looked in before QUADSITL_CONFIG_DIR and the shipped "
        "files (a scenario of your own: DIR/scenarios/NAME.toml); quadsitl config copy DIR starts one",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("up", help="start the SITL: simulator + autopilot, linked over MAVLink/UDP")
    p.add_argument(
        "--instance",
        type=int,
        default=0,
        help="first vehicle instance N, 0-249 (sysid 1+N; PX4's ports: HIL 4560+N, GCS link 18570+N sending "
        "to 14550 for every vehicle, API link 14580+N sending to 14540+N, 14549 from N=10)",
    )
    p.add_argument(
        "--count", type=int, default=1, help="number of vehicles (instances N..N+K-1, up to instance 249)"
    )
    p.add_argument("--controller", default="intbs_nlhinf",
                   help=f"cascade (config/controllers): {', '.join(CONTROLLER_NAMES)}, or your own")
    p.add_argument("--scenario", default="hover", help="initial state, uncertainty, gusts (config/scenarios)")
    p.add_argument("--vehicle", default="paper_quad", help="vehicle model and plant (config/vehicle)")
    p.add_argument(
        "--speed",
        type=speed_text,
        default="1",
        help="wall-clock pacing: 1 = real time (default), a factor, or max",
    )
    p.add_argument(
        "--autostart",
        action="store_true",
        help="arm at t=0 and fly the scenario's trajectory (the paper's experiment)",
    )
    p.add_argument("--duration", type=float, default=None, help="stop after this simulated time (s)")
    p.add_argument("--sitl-config", default=None, help="alternative sitl.toml")
    p.add_argument(
        "--params",
        metavar="FILE",
        default=None,
        help="autopilot parameter file (params.toml, NAME = value): loaded at start if it exists, "
        "saved on every change; with --count > 1 put {instance} in the path",
    )
    p.add_argument(
        "--signing-key",
        metavar="FILE",
        default=None,
        help="MAVLink 2 signing on the GCS links: a file with the key (64 hex digits) or a passphrase "
        "(as MAVProxy's 'signing setup PASSPHRASE'); state kept as signing-N.json beside --params, "
        "else beside FILE",
    )
    p.add_argument(
        "--log-dir",
        metavar="DIR",
        default="log",
        help="flight logs (ULog, PX4's layout DIR/YYYY-MM-DD/HH_MM_SS.ulg; with --count > 1 "
        "DIR/instance_N/...), written as SDLOG_MODE says (default 0: from arming to disarming) and "
        "served by the MAVLink log download (default: log in the working directory)",
    )
    p.add_argument("--no-log", action="store_true", help="no flight logs at all")
    p.add_argument(
        "--no-restart",
        action="store_true",
        help="a process that dies stays down (default: the survivor's failsafe acts, then the lost "
        "process is restarted)",
    )
    p.add_argument(
        "--max-restarts",
        type=int,
        default=3,
        metavar="N",
        help="restarts of one process per 60 s before it is left down (default 3; 0 = --no-restart)",
    )
    _estimation_arguments(p)
    p.add_argument("--spacing", type=float, default=0.0, metavar="M",
                   help="instance N's home N x M metres north of the configured one (PX4's multi-vehicle "
                   "SITL spawns its instances 3 m apart), so a ground station's map shows them apart")
    p.add_argument("--impair", action="append", default=[], metavar="LINK:SPEC",
                   help="faults on a link, LINK one of hil, gcs, api: e.g. gcs:loss=5%%,delay=50ms,"
                   "jitter=20ms,dup=1%%,reorder=1%% (repeatable; replaces sitl.toml's [impair] entry; "
                   "docs/links.md)")  # fmt: skip
    p.add_argument("--view", action="store_true", help="also start the live view in the browser")
    p.add_argument("--view-port", type=int, default=8080, help="the view's port on 127.0.0.1 (default 8080)")
    p.set_defaults(func=_cmd_up)

    p = sub.add_parser("fleet", help="K vehicles in one process, each on its own MAVLink ports "
                                     "(quadsitl fleet --help)", add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=lambda a: __import__("sitl.fleet", fromlist=["main"]).main(a.rest))

    p = sub.add_parser("router", help="a zenoh router for a fleet over several launches or hosts "
                                      "(quadsitl router --help)", add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)

    p = sub.add_parser(
        "view",
        help="live 3-D view and plots in the browser, or replays of logs (quadsitl view --help)",
        add_help=False,
    )
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=lambda a: __import__("gcs_scripts.view.server", fromlist=["main"]).main(a.rest))

    p = sub.add_parser("compile", help="compile the flight's kernels now (quadsitl compile --help)",
                       add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=lambda a: __import__("sitl.compile", fromlist=["main"]).main(a.rest))

    p = sub.add_parser("tune", help="PX4's attitude autotune flown in-process: gains for a px4_pid cascade "
                       "(quadsitl tune --help)", add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=lambda a: __import__("sitl.tune", fromlist=["main"]).main(a.rest))

    p = sub.add_parser("demo", help="the paper's helix through the SITL for the three cascades (make demo)")
    p.add_argument("--out", default="out/demo", help="output directory (default: out/demo)")
    p.add_argument("--instance", type=int, default=0, help="vehicle instance used for the runs")
    p.add_argument("--speed", type=speed_text, default="max", help="SITL pacing (default max)")
    p.set_defaults(
        func=lambda a: __import__("sitl.demo", fromlist=["main_demo"]).main_demo(a.out, a.instance, a.speed)
    )

    p = sub.add_parser(
        "analyze",
        help="indices, figures and a comparison table from recorded logs (quadsitl analyze --help)",
        add_help=False,
    )
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p.set_defaults(func=_cmd_analyze)

    p = sub.add_parser("paper", help="reproduce the paper's experiment in-process (Tables I-III, figures)")
    p.add_argument("--out", default="out/paper", help="output directory (default: out/paper)")
    p.add_argument(
        "--nominal-plant",
        action="store_true",
        help="fly the nominal Section II model instead of the coupled plant",
    )
    p.add_argument("--scenarios", nargs="+", default=["circle", "helix"], help="scenarios (config/scenarios)")
    p.add_argument("--controllers", nargs="+", default=list(CONTROLLER_NAMES), help="cascades to compare")
    p.add_argument("--workers", type=int, default=2, help="parallel runs (default 2)")
    p.add_argument("--duration", type=float, default=None,
                   help="simulated seconds per run (default: the scenario's, 40 s in the paper)")  # fmt: skip
    _estimation_arguments(p)
    p.set_defaults(func=_cmd_paper)

    p = sub.add_parser("run", help="one in-process run of a scenario")
    p.add_argument("scenario", help="scenario name (config/scenarios) or path")
    p.add_argument("--controller", default="intbs_nlhinf",
                   help=f"cascade (config/controllers): {', '.join(CONTROLLER_NAMES)}, or your own")
    p.add_argument("--nominal-plant", action="store_true",
                   help="fly the nominal Section II model instead of the coupled plant")  # fmt: skip
    p.add_argument("--duration", type=float, default=None, help="seconds (default: the scenario's)")
    p.add_argument("--out", default=None, help="write the time series to this Parquet file")
    _estimation_arguments(p)
    p.set_defaults(func=_cmd_run)

    from .campaign.cli import add_campaign_parser  # Monte Carlo campaigns

    add_campaign_parser(sub)

    for group, text in GROUP_HELP.items():  # parsed in main(); these parsers give --help and errors
        p = sub.add_parser(group, help=text)
        names = p.add_subparsers(dest="name", required=True, metavar="NAME")
        for (g, name), (module, _, about) in DELEGATED.items():
            if g == group:
                q = names.add_parser(name, help=f"{about} (gcs_scripts/{module}.py)", add_help=False)
                q.add_argument("rest", nargs=argparse.REMAINDER)
    p = sub.add_parser("record", help="record a session: tlog + Parquet (quadsitl record --help)",
                       add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p = sub.add_parser("impair", help="change a running vehicle's link faults: quadsitl impair "
                       "api:loss=100%% (docs/links.md)", add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)
    p = sub.add_parser("fail", help="inject a failure as PX4's failure command: quadsitl fail gps off "
                       "[--enable] (quadsitl fail --help, docs/failures.md)", add_help=False)  # fmt: skip
    p.add_argument("rest", nargs=argparse.REMAINDER)

    p = sub.add_parser("config", help="the configuration: copy the shipped files out, or list where names "
                       "are looked up")  # fmt: skip
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    q = actions.add_parser("copy", help="write the shipped configuration into DIR for editing")
    q.add_argument("dir", metavar="DIR", help="directory to write into (created)")
    q.add_argument("--force", action="store_true", help="overwrite files that are there already")
    actions.add_parser("where", help="the directories a name is looked up in, first match wins")
    p.set_defaults(func=_cmd_config)
    return parser


def _split_config_dir(argv: list[str]) -> tuple[str | None, list[str]]:
    """``--config-dir DIR`` (or ``=DIR``) before the command, and the rest."""
    directory = None
    while argv:
        if argv[0] == "--config-dir" and len(argv) > 1:
            directory, argv = argv[1], argv[2:]
        elif argv[0].startswith("--config-dir="):
            directory, argv = argv[0].split("=", 1)[1], argv[1:]
        else:
            break
    return directory, argv


def main(argv: list[str] | None = None) -> int:
    """The ``quadsitl`` entry point: apply ``--config-dir`` (also for the processes started), run the
    subcommand; its exit status, 2 with the message for a configuration error."""
    argv = sys.argv[1:] if argv is None else argv
    directory, argv = _split_config_dir(list(argv))
    try:
        if directory is not None:  # in the environment: the processes `up` starts look there too
            from quadcommon.config import with_config_dir

            os.environ.update(with_config_dir(directory, os.environ))
        return _dispatch(argv)
    except ConfigError as exc:
        print(f"quadsitl: configuration error: {exc}", file=sys.stderr)
        return 2
    except ControllerFailure as exc:  # an in-process run whose law failed (run, paper)
        print(f"quadsitl: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("quadsitl: interrupted", file=sys.stderr)
        return 130


def _dispatch(argv: list[str]) -> int:
    if argv[:1] == ["analyze"]:  # its own parser (options such as --help pass through)
        from gcs_scripts.analysis.analyze import main as analyze_main

        return analyze_main(argv[1:], prog="quadsitl analyze")
    if argv[:1] == ["view"]:  # its own parser too (gcs_scripts/view/server.py)
        from gcs_scripts.view.server import main as view_main

        return view_main(argv[1:], prog="quadsitl view")
    if argv[:1] == ["compile"]:  # its own parser (options such as --help pass through)
        from sitl.compile import main as compile_main

        return compile_main(argv[1:])
    if argv[:1] == ["router"]:  # its own parser too (sitl/router.py)
        from sitl.router import main as router_main

        return router_main(argv[1:])
    if argv[:1] == ["fleet"]:  # its own parser too (sitl/fleet.py)
        from sitl.fleet import main as fleet_main

        return fleet_main(argv[1:])
    if argv[:1] == ["tune"]:  # its own parser too (sitl/tune.py)
        from sitl.tune import main as tune_main

        return tune_main(argv[1:])
    if argv[:1] == ["record"]:
        return _delegate(RECORD_MODULE, argv[1:], "quadsitl record")
    if argv[:1] == ["impair"]:
        return _delegate(IMPAIR_MODULE, argv[1:], "quadsitl impair")
    if argv[:1] == ["fail"]:
        return _delegate(FAIL_MODULE, argv[1:], "quadsitl fail")
    if tuple(argv[:2]) in DELEGATED:
        module, before, _ = DELEGATED[(argv[0], argv[1])]
        if argv[0] in FAN_OUT_GROUPS:
            ran = _each_instance(argv)
            if ran is not None:
                return ran
        return _delegate(module, [*before, *argv[2:]], f"quadsitl {argv[0]} {argv[1]}")
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
