"""Fly a list of position setpoints in OFFBOARD, as a MAVSDK/pymavlink script would with PX4.

Steps: connect, wait for the heartbeat, wait until the vehicle is ready to arm (SYS_STATUS's
pre-arm bit and on the ground: an EKF aligns and converges first; the reason is printed, and after
30 s of simulation time the script fails with it), arm, take off (NAV_TAKEOFF), wait until at altitude,
stream position setpoints (one per LOCAL_POSITION_NED received, requested at 50 Hz, so the
stream is paced in simulation time at any --speed), switch to OFFBOARD, fly each setpoint in
turn (reach it within --tolerance, hold it --hold seconds of simulation time), land (NAV_LAND),
wait for the landing, make sure the vehicle is disarmed. Each step is reported with its
simulation time. Exit status 0 on success, 1 on a failure or timeout (the reason on stderr;
the script asks the vehicle to land if it was flying), 2 on bad arguments, 3 if no vehicle
answers.

Frames: setpoints are in the paper's frame, x forward/north, y LEFT (west), z UP, metres, in the
vehicle's local frame (origin at the configured home); yaw in degrees counter-clockwise from x
seen from above. They are converted to MAVLink's NED at the edge (quadcommon.frames).

Setpoints file (--setpoints-file): plain text, one setpoint per line "x y z [yaw_deg]",
blank lines and '#' comments ignored; or a JSON list of [x, y, z] / [x, y, z, yaw_deg] lists or
of {"x": .., "y": .., "z": .., "yaw_deg": ..} objects.
Default setpoints: a 2 m square at 2.5 m: (2,0,2.5) (2,2,2.5) (0,2,2.5) (0,0,2.5).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

# Allow ``python gcs_scripts/fly_setpoints.py`` from a checkout without installing.
if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs_scripts import link as mavlink_link  # noqa: E402
from gcs_scripts.link import Link, LinkError, PositionTarget, SetpointStream  # noqa: E402
from quadcommon import wire  # noqa: E402
from quadcommon.cli_help import HelpFormatter  # noqa: E402

Vector3 = tuple[float, float, float]
DEFAULT_SQUARE: tuple[tuple[float, float, float, float | None], ...] = (
    (2.0, 0.0, 2.5, None),
    (2.0, 2.0, 2.5, None),
    (0.0, 2.0, 2.5, None),
    (0.0, 0.0, 2.5, None),
)
STREAM_RATE_HZ = 50.0
LOCAL_POSITION_NED_ID = 32
EXTENDED_SYS_STATE_ID = 245


@dataclass(frozen=True)
class Setpoint:
    """Paper frame: x north, y left, z up (m); yaw in degrees CCW from x, or None (keep)."""

    x: float
    y: float
    z: float
    yaw_deg: float | None = None

    @property
    def position(self) -> Vector3:
        """The target position (world frame, x north, y left, z up; m)."""
        return (self.x, self.y, self.z)

    def target(self) -> PositionTarget:
        """The setpoint as a :class:`PositionTarget` (yaw in rad, or None to keep the heading)."""
        yaw = None if self.yaw_deg is None else math.radians(self.yaw_deg)
        return PositionTarget(self.position, yaw_rad=yaw)

    def __str__(self) -> str:
        yaw = "" if self.yaw_deg is None else f" yaw {self.yaw_deg:g} deg"
        return f"({self.x:.2f}, {self.y:.2f}, {self.z:.2f}){yaw}"


def _setpoint(values: list[float], where: str) -> Setpoint:
    if len(values) not in (3, 4):
        raise ValueError(f"{where}: expected 'x y z [yaw_deg]', got {len(values)} values")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{where}: values must be finite, got {values}")
    return Setpoint(values[0], values[1], values[2], values[3] if len(values) == 4 else None)


def parse_setpoints_text(text: str, source: str = "setpoints") -> list[Setpoint]:
    """Setpoints from a file's text: JSON list, or lines "x y z [yaw_deg]" with # comments."""
    stripped = text.strip()
    if stripped.startswith("["):
        data = json.loads(stripped)
        if not isinstance(data, list):
            raise ValueError(f"{source}: JSON must be a list")
        out = []
        for i, item in enumerate(data):
            where = f"{source}: item {i}"
            if isinstance(item, dict):
                unknown = set(item) - {"x", "y", "z", "yaw_deg"}
                if unknown or not {"x", "y", "z"} <= set(item):
                    raise ValueError(f"{where}: needs keys x, y, z (optional yaw_deg), got {sorted(item)}")
                values = [float(item["x"]), float(item["y"]), float(item["z"])]
                if item.get("yaw_deg") is not None:
                    values.append(float(item["yaw_deg"]))
            elif isinstance(item, list):
                values = [float(v) for v in item]
            else:
                raise ValueError(f"{where}: expected a list or an object, got {item!r}")
            out.append(_setpoint(values, where))
        return out
    out = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0].strip()
        if not content:
            continue
        try:
            values = [float(v) for v in content.replace(",", " ").split()]
        except ValueError:
            raise ValueError(f"{source}:{number}: not numbers: {line.strip()!r}") from None
        out.append(_setpoint(values, f"{source}:{number}"))
    return out


def build_parser(prog: str = "fly_setpoints.py") -> argparse.ArgumentParser:
    """The ``fly_setpoints.py`` command line (instance, URL, takeoff altitude, setpoints, tolerances)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    parser.add_argument("--instance", type=int, default=0,
                        help="vehicle instance N (default 0); through quadsitl also a range, "
                        "0-9 or 3,5,8: the script once per vehicle")
    parser.add_argument(
        "--url", default=None,
        help="MAVLink URL (default udpin:127.0.0.1:14540+N; from N=10 udpout:127.0.0.1:14580+N)"
    )
    parser.add_argument(
        "--takeoff-alt", type=float, default=2.5, help="takeoff altitude above home, m (default 2.5)"
    )
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--setpoints-file", type=Path, default=None, help="file of setpoints (see above)")
    group.add_argument(
        "--setpoint",
        nargs="+",
        type=float,
        action="append",
        metavar="X Y Z [YAW_DEG]",
        help="one setpoint, paper frame (x north, y left, z up; m); repeat for more",
    )
    parser.add_argument("--hold", type=float, default=2.0, help="hold each setpoint this long, sim s")
    parser.add_argument("--tolerance", type=float, default=0.1, help="reached within this distance, m")
    parser.add_argument(
        "--timeout",
        type=float,
        default=60.0,
        help="simulation seconds allowed for each step (takeoff, each setpoint, landing)",
    )
    return parser


def parse_args(
    argv: list[str] | None = None, prog: str = "fly_setpoints.py"
) -> tuple[argparse.Namespace, list[Setpoint]]:
    """Arguments and the setpoints they name (the default square when none are given)."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    try:
        if args.setpoints_file is not None:
            try:
                text = args.setpoints_file.read_text()
            except OSError as exc:
                raise ValueError(f"cannot read {args.setpoints_file}: {exc.strerror}") from None
            setpoints = parse_setpoints_text(text, str(args.setpoints_file))
        elif args.setpoint:
            setpoints = [_setpoint(v, f"--setpoint {' '.join(map(str, v))}") for v in args.setpoint]
        else:
            setpoints = [Setpoint(*s) for s in DEFAULT_SQUARE]
    except ValueError as exc:
        parser.error(str(exc))
    if not setpoints:
        parser.error("no setpoints given")
    if not 0.2 <= args.takeoff_alt <= 100.0:
        parser.error(f"--takeoff-alt must be in [0.2, 100] m, got {args.takeoff_alt}")
    if not args.tolerance > 0.0:
        parser.error(f"--tolerance must be > 0 m, got {args.tolerance}")
    if args.hold < 0.0 or not args.timeout > 0.0:
        parser.error("--hold must be >= 0 and --timeout > 0")
    if not wire.INSTANCE_MIN <= args.instance <= wire.INSTANCE_MAX:
        parser.error(f"--instance must be in [{wire.INSTANCE_MIN}, {wire.INSTANCE_MAX}], got {args.instance}")
    for sp in setpoints:
        if sp.z < 0.2:
            parser.error(f"setpoint {sp} is below 0.2 m (z is UP in the paper's frame)")
    return args, setpoints


say = mavlink_link.report


def distance(a: Vector3, b: Vector3) -> float:
    """Euclidean distance between two positions (m)."""
    return math.dist(a, b)


class Flight:
    """The sequence of steps; ``current`` is the setpoint the stream sends."""

    def __init__(self, link: Link, args: argparse.Namespace) -> None:
        self.link = link
        self.args = args
        self.current: PositionTarget | None = None

    def error_to(self, position: Vector3) -> float:
        """Distance from the vehicle's reported position to ``position`` (m); infinite before any position."""
        p = self.link.position_paper
        return math.inf if p is None else distance(p, position)

    def takeoff(self) -> None:
        """Stream the position at a fast rate, wait until the vehicle can arm and reports a position and
        a landed state, then arm, take off ``--takeoff-alt`` m above the start and wait until there and
        out of AUTO.TAKEOFF; a vehicle already flying is taken as it is."""
        link, args = self.link, self.args
        link.set_message_interval(LOCAL_POSITION_NED_ID, STREAM_RATE_HZ)
        link.set_message_interval(EXTENDED_SYS_STATE_ID, 5.0)  # faster landing detection
        link.wait_ready_to_arm()  # (at once if armed): an EKF has no position until it aligns
        link.wait_until(
            lambda lk: lk.position_paper is not None and lk.landed_state != 0,
            5.0,
            what="LOCAL_POSITION_NED and EXTENDED_SYS_STATE",
        )
        if link.armed and link.landed_state == mavlink_link.MAV_LANDED_STATE_IN_AIR:
            say(link, f"already flying ({link.mode}); skipping arming and takeoff")
            return
        link.arm_when_ready()
        say(link, "armed")
        start = link.position_paper
        link.takeoff(args.takeoff_alt)
        target_z = (start[2] if start else 0.0) + args.takeoff_alt
        say(link, f"taking off to {args.takeoff_alt:.2f} m")
        link.wait_until(
            # Done when near the altitude and PX4-like hold (AUTO.LOITER) has taken over.
            lambda lk: (
                abs(lk.position_paper[2] - target_z) < args.tolerance
                and abs(lk.velocity_paper[2]) < 0.2
                and lk.mode != "AUTO.TAKEOFF"
            ),
            args.timeout,
            what=f"takeoff to z={target_z:.2f} m",
        )
        say(link, f"at altitude z={link.position_paper[2]:.3f} m ({link.mode})")

    def start_offboard(self) -> SetpointStream:
        """Start streaming SET_POSITION_TARGET_LOCAL_NED at the current position (entering OFFBOARD
        does not move the vehicle), then switch to OFFBOARD (PX4 refuses it without a stream); return the
        stream."""
        link = self.link
        # First setpoint = where we are, so entering OFFBOARD does not move the vehicle.
        here = link.position_paper
        self.current = PositionTarget(here)
        stream = SetpointStream(link, lambda t: self.current).start()
        link.sleep_sim(0.5, "setpoint stream warm-up")  # PX4 refuses OFFBOARD without a stream
        link.set_mode("OFFBOARD")
        link.wait_mode("OFFBOARD")
        say(link, f"OFFBOARD (stream of {stream.sent} setpoints so far)")
        return stream

    def fly(self, index: int, sp: Setpoint) -> None:
        """Fly to setpoint ``index`` and wait until within ``--tolerance`` m (``--timeout`` s of
        simulation time); then hold ``--hold`` s, reporting the worst error. Raises LinkError on a
        timeout or if the vehicle leaves OFFBOARD."""
        link, args = self.link, self.args
        self.current = sp.target()
        say(link, f"flying to setpoint {index} {sp}")
        link.wait_until(
            lambda lk: self.error_to(sp.position) < args.tolerance,
            args.timeout,
            what=f"setpoint {index} {sp} within {args.tolerance:g} m",
        )
        say(link, f"reached setpoint {index} {sp} error {self.error_to(sp.position):.3f} m")
        if args.hold > 0.0:
            worst = [0.0]

            def track(lk: Link) -> bool:
                worst[0] = max(worst[0], self.error_to(sp.position))
                return False

            start = link.now()
            link.wait_until(
                lambda lk: track(lk) or lk.now() - start >= args.hold, args.hold + 1.0, what="the hold"
            )
            if link.mode != "OFFBOARD":
                raise LinkError(f"left OFFBOARD while holding setpoint {index}: mode {link.mode}")
            say(
                link,
                f"held setpoint {index} for {args.hold:g} s: error {self.error_to(sp.position):.3f} m "
                f"(max {worst[0]:.3f} m)",
            )


def run(args: argparse.Namespace, setpoints: list[Setpoint]) -> int:
    """Connect (as MAVSDK would, ``udpin:127.0.0.1:14540+N``) and :func:`fly`; 3 when no vehicle
    answers or the port cannot be bound."""
    try:
        link = mavlink_link.connect(args.url, args.instance, log=print)
    except mavlink_link.LinkTimeout as exc:
        print(f"fly_setpoints: {exc}", file=sys.stderr)
        return 3
    except OSError as exc:
        print(f"fly_setpoints: cannot listen on {args.url or mavlink_link.api_url(args.instance)}: {exc}",
              file=sys.stderr)  # fmt: skip
        return 3
    try:
        return fly(link, args, setpoints)
    finally:
        link.close()


def fly(link: Link, args: argparse.Namespace, setpoints: list[Setpoint]) -> int:
    """The whole flight on a connected ``link``; the exit status (see the module)."""
    say(link, f"connected to system {link.target_system} ({link.mode}, {link.landed_state_name})")
    flight = Flight(link, args)
    stream = None
    try:
        flight.takeoff()
        stream = flight.start_offboard()
        for i, sp in enumerate(setpoints, start=1):
            flight.fly(i, sp)
        mavlink_link.land_and_disarm(link, args.timeout, stream)
        say(link, "done")
        return 0
    except LinkError as exc:
        print(f"fly_setpoints: failed: {exc}", file=sys.stderr)
        if stream is not None:
            stream.stop()
        mavlink_link.emergency_land(link, "fly_setpoints")
        return 1
    except KeyboardInterrupt:
        print("fly_setpoints: interrupted", file=sys.stderr)
        if stream is not None:
            stream.stop()
        mavlink_link.emergency_land(link, "fly_setpoints")
        return 130


def main(argv: list[str] | None = None, prog: str = "fly_setpoints.py") -> int:
    """Parse the command line and :func:`run` it; the exit status."""
    args, setpoints = parse_args(argv, prog)
    return run(args, setpoints)


if __name__ == "__main__":
    sys.exit(main())
