"""Fly the paper's experiment through a running SITL: mission + gust profile, recorded.

Against ``quadsitl up --scenario helix`` (or ``circle``), this script, like any ground station:

1. starts the recorder (``record.py`` on the GCS port 14550, keeping system id 1+N, until the vehicle
   disarms);
2. clears the simulator's start-up disturbances (an empty gust profile, over zenoh), so that
   nothing pushes the vehicle while it takes off;
3. uploads the scenario's trajectory as a mission: NAV_TAKEOFF to the height of p_d(0), then the
   curve sampled into timed items (MAV_CMD_WAYPOINT_USER_1, param1 = time from the mission start,
   ``--start-time`` + tau), then NAV_LAND; downloads it back and checks it is identical;
4. waits until the vehicle is ready to arm, arms and starts AUTO.MISSION; the autopilot takes
   off, joins the curve at rest at p_d(0) and
   flies it on the clock from t0 = (mission start) + ``--start-time``;
5. uploads the paper's disturbance schedule anchored at t0, so the steps hit at the same
   trajectory times as in the in-process experiment (the mission start is read exactly from the
   autopilot's controller stream on zenoh);
6. waits for the landing and disarm, stops the recorder, and prints t0 and how to analyse:
   ``quadsitl analyze LOG --t0 T0 --duration 40``. A sidecar ``LOG.flight.json`` keeps t0.

The curve is flown from rest at p_d(0) after the take-off, not from the scenario's initial state
(the paper's runs start at t = 0 with cold integrators and a yaw error of 0.5 rad): compare
indices over a window after the start-up transient (e.g. ``--t0 T0+4 --duration 36`` against the
in-process run trimmed the same way), or use ``quadsitl up --autostart`` for a start identical to
the in-process run.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs_scripts import upload_mission  # noqa: E402
from gcs_scripts.link import LinkError  # noqa: E402
from gcs_scripts.link import report as say  # noqa: E402
from gcs_scripts.upload_gusts import NoSimulatorAnswer, upload_gusts  # noqa: E402
from quadcommon import bus, wire  # noqa: E402
from quadcommon.bus_records import CONTROLLER_CODEC  # noqa: E402
from quadcommon.cli_help import HelpFormatter  # noqa: E402

AUTO_MISSION = (4 << 16) | (4 << 24)
CURVE_MARGIN_S = 1.0


def build_parser(prog: str = "fly_paper.py") -> argparse.ArgumentParser:
    """The ``fly_paper.py`` command line (instance, scenario, gusts, curve start time and rate)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    parser.add_argument("--instance", type=int, default=0,
                        help="vehicle instance N (default 0); through quadsitl also a range, "
                        "0-9 or 3,5,8: the script once per vehicle")
    parser.add_argument("--scenario", default="helix", help="paper scenario: helix (default) or circle")
    parser.add_argument("--gusts", default=None, help="gust profile (default: the scenario's)")
    parser.add_argument(
        "--start-time",
        type=float,
        default=12.0,
        help="time of the curve's first sample after the mission start, s (default 12)",
    )
    parser.add_argument("--rate", type=float, default=20.0, help="curve samples per second (default 20)")
    parser.add_argument("--out", default=None, help="log path without extension (default runs/paper_<time>, "
                        "+ _instance_N past instance 0)")
    parser.add_argument("--timeout", type=float, default=300.0, help="simulation seconds allowed")
    return parser


def _start_recorder(instance: int, out: Path) -> subprocess.Popen:
    cmd = [
        sys.executable,
        "-u",
        "-m",
        "gcs_scripts.record",
        "--instance",
        str(instance),
        "--out",
        str(out),
        "--until-disarmed",
    ]
    recorder = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert recorder.stdout is not None
    deadline = time.monotonic() + 20.0
    for line in recorder.stdout:  # wait until it records (bounded by the recorder's own timeouts)
        print(f"  {line.rstrip()}", flush=True)
        if "recording" in line or time.monotonic() > deadline:
            break
    return recorder


def _mission_start_time(session, instance: int, wall_timeout_s: float) -> float:
    """Simulation time at which AUTO.MISSION began, from the controller stream (exact)."""
    import zenoh

    sub = session.declare_subscriber(wire.zenoh_key(instance, "controller"), zenoh.handlers.FifoChannel(4096))
    try:
        deadline = time.monotonic() + wall_timeout_s
        previous_time = None
        while time.monotonic() < deadline:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.002)
                continue
            rows = CONTROLLER_CODEC.decode(sample.payload.to_bytes())
            for row in rows:
                t, mode = float(row[0]), int(row[-1])
                if mode == AUTO_MISSION:
                    # The mode changed between the frame before and this one: the executor started
                    # on the simulation clock of the frame before.
                    return previous_time if previous_time is not None else t
                previous_time = t
        raise LinkError("did not see AUTO.MISSION begin on the controller stream")
    finally:
        sub.undeclare()


def run(args: argparse.Namespace) -> int:
    """Fly the paper's scenario as a mission on vehicle ``args.instance``: clear the disturbances,
    upload and verify the sampled curve, start a recorder, arm, start AUTO.MISSION, schedule the
    gusts at the curve's start ``t0`` (simulation s), fly to the end; 0 on success, 1 on failure."""
    from gcs_scripts.fly_trajectory import load_gust_profile_mapping
    from quadcommon.config import load_scenario
    from quadcommon.trajectories import trajectory_from_spec

    scenario = load_scenario(args.scenario)
    trajectory = trajectory_from_spec(scenario.trajectory)
    gusts = load_gust_profile_mapping(args.gusts or scenario.gusts) if (args.gusts or scenario.gusts) else {}
    default = time.strftime("paper_%Y%m%d_%H%M%S") + (f"_instance_{args.instance}" if args.instance else "")
    out = Path(args.out) if args.out else Path("runs") / default  # (one per vehicle: --instance 0-9)
    out.parent.mkdir(parents=True, exist_ok=True)
    link = upload_mission.connect(None, args.instance)
    from quadcommon.config import load_sitl

    session = bus.open_peer(load_sitl().ports(args.instance).zenoh)
    recorder = None
    try:
        say(link, f"connected; flying the paper's {scenario.name} (duration {scenario.duration_s:g} s)")
        upload_gusts({}, args.instance, "now", timeout=5.0, session=session)
        say(link, "start-up disturbances cleared")
        height = trajectory.sample(0.0).position_m[2]
        # The curve runs CURVE_MARGIN_S past the scenario's duration, so that its last instant (the
        # paper's "final error") is taken while the curve is still flown, not as the landing begins.
        items = upload_mission.curve_items(
            trajectory,
            scenario.duration_s + CURVE_MARGIN_S,
            args.rate,
            args.start_time,
            takeoff_altitude_m=height,
            end="land",
        )
        link.upload(items)
        problems = upload_mission.verify(link, items)
        if problems:
            raise LinkError("mission download differs from the upload: " + "; ".join(problems[:3]))
        say(link, f"mission uploaded and verified: {len(items)} items")
        recorder = _start_recorder(args.instance, out)
        # Read what queued while the recorder started (at 20x real time, seconds of simulated
        # telemetry) before arming: else the arm's ACK waits behind it, the mode follows only that
        # much later, and the vehicle may disarm first (COM_DISARM_PRFLT, 10 s of simulation).
        for _ in range(100):
            if link.poll() == 0:
                break
        link.arm_when_ready()
        link.set_mode("AUTO.MISSION")
        start = _mission_start_time(session, args.instance, 30.0)
        t0 = start + args.start_time
        answer = upload_gusts(gusts, args.instance, {"at_s": t0}, timeout=5.0, session=session)
        say(
            link,
            f"mission started at t={start:.3f} s; curve t0={t0:.3f} s; gusts: {answer.get('summary', '')}",
        )
        print(f"t0={t0:.3f}", flush=True)
        (out.parent / f"{out.name}.flight.json").write_text(
            json.dumps({"t0_s": t0, "duration_s": scenario.duration_s, "scenario": scenario.name}, indent=1)
        )
        upload_mission.fly(link, items, args.timeout)
    except (LinkError, NoSimulatorAnswer, upload_mission.MissionError) as exc:
        print(f"fly_paper: failed: {exc}", file=sys.stderr)
        return 1
    finally:
        if recorder is not None:
            try:
                recorder.wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                recorder.send_signal(signal.SIGINT)
                recorder.wait(timeout=10.0)
            for line in recorder.stdout or []:
                print(f"  {line.rstrip()}", flush=True)
        session.close()
        link.close()
    print(f"log: {out}.parquet (and {out}.tlog)")
    print(f"analyse: quadsitl analyze {out}.parquet --t0 {t0:.3f} --duration {scenario.duration_s:g}")
    return 0


def main(argv: list[str] | None = None, prog: str = "fly_paper.py") -> int:
    """Parse the command line and :func:`run` it; 2 for a negative start time or rate."""
    args = build_parser(prog).parse_args(argv)
    if not (args.start_time >= 0 and args.rate > 0 and math.isfinite(args.start_time)):
        print("fly_paper: --start-time must be >= 0 and --rate > 0", file=sys.stderr)
        return 2
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
