"""Fly a scenario's reference trajectory (the paper's circle or helix) through the SITL, in OFFBOARD.

Steps: connect, wait for the heartbeat, request LOCAL_POSITION_NED at --rate (simulation Hz),
stream position setpoints at the trajectory's start point p_d(0) (one setpoint per
LOCAL_POSITION_NED received, so the stream is paced in simulation time at any --speed), wait
until the vehicle is ready to arm (as fly_setpoints.py does), arm on the ground (no takeoff:
OFFBOARD lifts the vehicle to p_d(0)) and switch to OFFBOARD; once within
--tolerance of p_d(0) and nearly still, hold it --settle seconds; then stream the trajectory:
position + velocity + acceleration (feed-forward) + yaw, sampled at t - t0 where t0 is a
simulation time planned just ahead (printed as ``t0=...``: the analysis aligns on it, e.g.
``quadsitl analyze LOG --t0 T0 --duration D``). Progress every 5 s of simulation time; at the
end hold the last point --hold seconds, land and disarm. If the vehicle is already flying the
script skips arming and flies to p_d(0) from where it is.

In-process runs start the scenario at its initial state; through the SITL the vehicle starts
wherever it is, so the first seconds after t0 differ (the trajectory is then flown from rest at
p_d(0), not from the scenario's initial state). The simulator applies the scenario's gust
profile from ITS start; ``--gusts PROFILE`` uploads a profile (config/gusts name or file) over
zenoh to start exactly at t0, so disturbances hit at the same trajectory times as in-process
(the upload replaces the simulator's active profile; needs the simulator's sim/gusts queryable).

Frames: the scenario's trajectory is in the paper's frame (x north, y left, z up); setpoints
are converted to MAVLink's NED at the edge (quadcommon.frames). Errors reported here come from
MAVLink telemetry (LOCAL_POSITION_NED, float32); record the run for ground truth.

Exit status 0 on success, 1 on a failure or timeout (reason on stderr; the script asks the
vehicle to land if it was flying), 2 on bad arguments, 3 if no vehicle answers.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs_scripts import link as mavlink_link  # noqa: E402
from gcs_scripts.link import Link, LinkError, PositionTarget, SetpointStream  # noqa: E402
from quadcommon import wire  # noqa: E402
from quadcommon.cli_help import HelpFormatter  # noqa: E402
from quadcommon.config import ScenarioConfig, config_path, load_scenario  # noqa: E402
from quadcommon.schema import ConfigError  # noqa: E402
from quadcommon.trajectories import Reference, Trajectory, trajectory_from_spec  # noqa: E402

say = mavlink_link.report
LOCAL_POSITION_NED_ID = 32
EXTENDED_SYS_STATE_ID = 245
PROGRESS_EVERY_S = 5.0
SETTLE_SPEED_M_S = 0.05  # "nearly still" before the settle period starts
T0_LEAD_S = 0.1  # t0 is planned this far ahead (sim s) ...
T0_LEAD_GUSTS_S = 1.0  # ... or this far with a gust upload (done within it even at max speed)


def build_parser(prog: str = "fly_trajectory.py") -> argparse.ArgumentParser:
    """The ``fly_trajectory.py`` command line (instance, URL, scenario, duration, gusts, rates)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    parser.add_argument("--instance", type=int, default=0,
                        help="vehicle instance N (default 0); through quadsitl also a range, "
                        "0-9 or 3,5,8: the script once per vehicle")
    parser.add_argument(
        "--url",
        default=None,
        help="MAVLink URL (default udpin:127.0.0.1:14540+N; from N=10 udpout:127.0.0.1:14580+N)",
    )
    parser.add_argument(
        "--scenario", default="circle", help="scenario name (config/scenarios) or path (default circle)"
    )
    parser.add_argument(
        "--duration", type=float, default=None, help="trajectory duration, sim s (default: the scenario's)"
    )
    parser.add_argument(
        "--rate", type=float, default=100.0, help="setpoint rate = LOCAL_POSITION_NED rate, sim Hz (>= 50)"
    )
    parser.add_argument("--tolerance", type=float, default=0.05, help="p_d(0) reached within this, m")
    parser.add_argument("--settle", type=float, default=2.0, help="hold p_d(0) this long first, sim s")
    parser.add_argument("--hold", type=float, default=2.0, help="hold the last point this long, sim s")
    parser.add_argument(
        "--timeout",
        type=float,
        default=60.0,
        help="sim seconds allowed for each step other than the trajectory",
    )
    parser.add_argument(
        "--gusts",
        default=None,
        metavar="PROFILE",
        help="upload this gust profile (config/gusts name or .toml/.json file) to start at t0 (zenoh)",
    )
    return parser


def parse_args(
    argv: list[str] | None = None, prog: str = "fly_trajectory.py"
) -> tuple[argparse.Namespace, ScenarioConfig]:
    """The parsed command line and its scenario; a parser error for an unknown scenario or a
    non-positive duration."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    try:
        scenario = load_scenario(args.scenario)
    except ConfigError as exc:
        parser.error(str(exc))
    if args.duration is None:
        args.duration = scenario.duration_s
    if not args.duration > 0.0:
        parser.error(f"--duration must be > 0 s, got {args.duration}")
    if not 50.0 <= args.rate <= 500.0:
        parser.error(f"--rate must be in [50, 500] Hz, got {args.rate}")
    if not args.tolerance > 0.0 or args.settle < 0.0 or args.hold < 0.0 or not args.timeout > 0.0:
        parser.error("--tolerance and --timeout must be > 0, --settle and --hold >= 0")
    if not wire.INSTANCE_MIN <= args.instance <= wire.INSTANCE_MAX:
        parser.error(f"--instance must be in [{wire.INSTANCE_MIN}, {wire.INSTANCE_MAX}], got {args.instance}")
    args.gust_profile = None
    if args.gusts is not None:
        try:
            args.gust_profile = load_gust_profile_mapping(args.gusts)
        except (ConfigError, ValueError) as exc:
            parser.error(f"--gusts: {exc}")
    return args, scenario


def load_gust_profile_mapping(name_or_path: str) -> dict:
    """A gust profile as a mapping (the simulator validates it): a config/gusts name or a file."""
    from gcs_scripts.upload_gusts import load_profile_file

    path = Path(name_or_path)
    if not path.exists():
        path = config_path("gusts", name_or_path)
    return load_profile_file(path)


def reference_target(ref: Reference) -> PositionTarget:
    """A trajectory sample as a full setpoint: position, velocity and acceleration, yaw."""
    return PositionTarget(ref.position_m, ref.velocity_m_s, ref.acceleration_m_s2, ref.yaw_rad)


class TrajectoryFlight:
    """What the stream sends: a fixed point, or the trajectory from t0."""

    def __init__(self, link: Link, trajectory: Trajectory, duration_s: float) -> None:
        self.link = link
        self.trajectory = trajectory
        self.duration_s = duration_s
        start = trajectory.sample(0.0)
        self.start_target = PositionTarget(start.position_m, yaw_rad=start.yaw_rad)
        end = trajectory.sample(duration_s)
        self.end_target = PositionTarget(end.position_m, yaw_rad=end.yaw_rad)
        self.fixed: PositionTarget | None = self.start_target
        self.t0: float | None = None
        self.tracking = False
        self.finished_at: float | None = None
        self.errors_sq_sum = 0.0
        self.errors_n = 0
        self.error_max = 0.0
        self.next_progress = PROGRESS_EVERY_S

    def start_at(self, t0: float) -> None:
        """Fly the trajectory from simulation time ``t0`` (the hold continues until then)."""
        self.t0 = t0
        self.tracking = True

    def provide(self, t: float) -> PositionTarget | None:
        """The setpoint at simulation time ``t`` (s): the fixed target before ``t0`` and after the
        trajectory's end, else the trajectory's reference at ``t - t0`` (whose tracking error is
        measured)."""
        if not self.tracking or t < self.t0:
            return self.fixed
        tau = t - self.t0
        if tau > self.duration_s:
            self.tracking = False
            self.finished_at = t
            self.fixed = self.end_target
            return self.fixed
        ref = self.trajectory.sample(tau)
        self._measure(tau, ref)
        return reference_target(ref)

    def _measure(self, tau: float, ref: Reference) -> None:
        p = self.link.position_paper  # the sample that triggered this call
        if p is None:
            return
        err = math.dist(p, ref.position_m)
        self.errors_sq_sum += err * err
        self.errors_n += 1
        self.error_max = max(self.error_max, err)
        if tau >= self.next_progress:
            self.next_progress += PROGRESS_EVERY_S
            say(
                self.link,
                f"tau={tau:5.1f} s p=({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) "
                f"p_d=({ref.position_m[0]:+.3f}, {ref.position_m[1]:+.3f}, {ref.position_m[2]:+.3f}) "
                f"error {err:.3f} m",
            )

    @property
    def rms_error(self) -> float:
        """RMS of the telemetry tracking errors measured so far (m); NaN before any."""
        return math.sqrt(self.errors_sq_sum / self.errors_n) if self.errors_n else math.nan


def fmt(p: tuple[float, ...]) -> str:
    """A position as ``(x, y, z)`` with millimetre precision, for messages."""
    return "(" + ", ".join(f"{v:.3f}" for v in p) + ")"


def fly(link: Link, args: argparse.Namespace, flight: TrajectoryFlight) -> SetpointStream:
    """Arm, enter OFFBOARD, go to ``p_d(0)`` and settle, upload the gusts, fly the trajectory from a
    ``t0`` shortly ahead (printed as ``t0=...`` for the analysis) and hold its end; return the
    setpoint stream (still running). Raises LinkError when the vehicle leaves OFFBOARD or a wait times
    out."""
    link.set_message_interval(LOCAL_POSITION_NED_ID, args.rate)
    link.set_message_interval(EXTENDED_SYS_STATE_ID, 5.0)
    link.wait_ready_to_arm()  # (at once if armed): an EKF has no position until it aligns
    link.wait_until(
        lambda lk: lk.position_paper is not None and lk.landed_state != 0,
        5.0,
        what="LOCAL_POSITION_NED and EXTENDED_SYS_STATE",
    )
    start = flight.start_target.position_m
    stream = SetpointStream(link, flight.provide).start()
    link.sleep_sim(0.5, "setpoint stream warm-up")  # PX4 refuses OFFBOARD without a stream
    flying = link.armed and link.landed_state == mavlink_link.MAV_LANDED_STATE_IN_AIR
    if not flying:
        link.arm_when_ready()
        say(link, "armed on the ground")
    link.set_mode("OFFBOARD")
    link.wait_mode("OFFBOARD")
    say(link, f"OFFBOARD: going to p_d(0) = {fmt(start)}")

    def settled(lk: Link) -> bool:
        return (
            math.dist(lk.position_paper, start) < args.tolerance
            and math.hypot(*lk.velocity_paper) < SETTLE_SPEED_M_S
        )

    link.wait_until(settled, args.timeout, what=f"p_d(0) within {args.tolerance:g} m, at rest")
    say(link, f"at p_d(0), error {math.dist(link.position_paper, start):.3f} m; settling {args.settle:g} s")
    if args.settle > 0.0:
        link.sleep_sim(args.settle, "settling at p_d(0)")
    _check_offboard(link)
    say(link, f"error at p_d(0) after settling {math.dist(link.position_paper, start):.3f} m")

    t0 = round(link.now() + (T0_LEAD_GUSTS_S if args.gust_profile is not None else T0_LEAD_S), 3)
    if args.gust_profile is not None:
        _upload_gusts(link, args, t0)
    flight.start_at(t0)
    say(link, f"trajectory starts at t0={t0:.3f} s (simulation time)")
    link.wait_until(
        lambda lk: flight.finished_at is not None or lk.mode != "OFFBOARD",
        args.duration + 5.0,
        what=f"the {args.duration:g} s trajectory",
    )
    _check_offboard(link)
    say(
        link,
        f"trajectory done ({args.duration:g} s from t0={flight.t0:.3f} s): telemetry tracking error "
        f"RMS {flight.rms_error:.4f} m, max {flight.error_max:.4f} m over {flight.errors_n} samples",
    )
    print(f"t0={flight.t0:.3f}", flush=True)  # machine-readable line for the analysis
    if args.hold > 0.0:
        link.sleep_sim(args.hold, "the final hold")
        _check_offboard(link)
        error = math.dist(link.position_paper, flight.end_target.position_m)
        say(link, f"held the last point {args.hold:g} s: error {error:.3f} m")
    return stream


def _upload_gusts(link: Link, args: argparse.Namespace, t0: float) -> None:
    """Upload --gusts to start at t0; the zenoh session was opened early (opening can take 0.5 s)."""
    from gcs_scripts.upload_gusts import NoSimulatorAnswer, upload_gusts

    try:
        answer = upload_gusts(args.gust_profile, args.instance, {"at_s": t0}, timeout=3.0, session=args.zenoh)
    except NoSimulatorAnswer as exc:
        raise LinkError(f"--gusts: {exc}") from None
    if not answer.get("accepted"):
        raise LinkError(f"--gusts: the simulator rejected the profile: {answer.get('error')}")
    if link.now() >= t0:
        raise LinkError(f"--gusts: the upload finished after t0={t0:.3f} s (now t={link.now():.3f} s)")
    say(link, f"gust profile {args.gusts} starts at t0={t0:.3f} s ({answer.get('summary', '')})")


def _check_offboard(link: Link) -> None:
    if link.mode != "OFFBOARD":
        raise LinkError(f"the vehicle left OFFBOARD (now {link.mode}); recent: {_last_text(link)}")


def _last_text(link: Link) -> str:
    return link.statustext[-1][2] if link.statustext else "no STATUSTEXT"


def run(args: argparse.Namespace, scenario: ScenarioConfig) -> int:
    """Connect, :func:`fly`, then land and disarm; 0 on success, 1 on a failed flight (after an
    emergency landing), 3 when no vehicle answers, the port cannot be bound or the gust bus cannot
    be opened, 130 on Ctrl-C."""
    trajectory = trajectory_from_spec(scenario.trajectory)
    flight = TrajectoryFlight(None, trajectory, args.duration)  # type: ignore[arg-type]
    try:
        link = mavlink_link.connect(args.url, args.instance, log=print)
    except mavlink_link.LinkTimeout as exc:
        print(f"fly_trajectory: {exc}", file=sys.stderr)
        return 3
    except OSError as exc:
        where = args.url or mavlink_link.api_url(args.instance)
        print(f"fly_trajectory: cannot listen on {where}: {exc}", file=sys.stderr)
        return 3
    flight.link = link
    args.zenoh = None
    if args.gust_profile is not None:
        from quadcommon import bus
        from quadcommon.config import load_sitl

        sitl = load_sitl()
        try:
            args.zenoh = bus.open_peer(sitl.zenoh_port_base + args.instance, sitl.zenoh_router)
        except bus.BusError as exc:
            link.close()
            print(f"fly_trajectory: --gusts: {exc}", file=sys.stderr)
            return 3
    say(
        link,
        f"connected to system {link.target_system} ({link.mode}, {link.landed_state_name}); scenario "
        f"{scenario.name}: {args.duration:g} s at {args.rate:g} Hz",
    )
    stream = None
    try:
        stream = fly(link, args, flight)
        mavlink_link.land_and_disarm(link, args.timeout, stream)
        say(link, "done")
        return 0
    except LinkError as exc:
        print(f"fly_trajectory: failed: {exc}", file=sys.stderr)
        link.on_local_position = None
        mavlink_link.emergency_land(link, "fly_trajectory")
        return 1
    except KeyboardInterrupt:
        print("fly_trajectory: interrupted", file=sys.stderr)
        link.on_local_position = None
        mavlink_link.emergency_land(link, "fly_trajectory")
        return 130
    finally:
        link.close()
        if args.zenoh is not None:
            args.zenoh.close()


def main(argv: list[str] | None = None, prog: str = "fly_trajectory.py") -> int:
    """Parse the command line and :func:`run` it; the exit status."""
    args, scenario = parse_args(argv, prog)
    return run(args, scenario)


if __name__ == "__main__":
    sys.exit(main())
