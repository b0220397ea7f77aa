"""The SITL under traffic: real-time factor and control-step latency with ground stations at work.

Runs of the two-process SITL (the paper's circle, autostart, 500 Hz control, 1 kHz physics) at
``--speed 1`` (paced to the wall clock, as a user flies it: does it keep real time?) and at
``--speed max`` (as fast as it goes: what does the traffic cost?), each with different traffic on
the autopilot's GCS port:

* ``quiet``: nothing;
* ``load``: 8 well-behaved ground stations (``python -m sitl.spray load``), each heartbeating
  and asking for 12 streams at the control rate (SET_MESSAGE_INTERVAL 2000 µs), reading it all;
* ``hostile``: ``python -m sitl.spray hostile --rate 3000`` (3,000 datagrams per wall second that
  must each be refused or ignored, from 300 source ports);
* ``flood``: the same, flat out (as fast as one Python sender goes, 1,000 source ports).

At ``--speed 1`` the real-time factor is measured from "linked" to the simulator's exit, start-up
and shutdown of a 10 s run included (~0.95 when nothing is wrong); the pacer's re-anchors (frames
that missed their wall-clock slot, after which pacing restarts from now) say whether real time
was kept. The control step's latency is the simulator's HIL round trip (frame sent -> its
HIL_ACTUATOR_CONTROLS received: the autopilot's whole frame, GCS traffic it had to drain first
included), median and p99. The traffic processes run on the same 2 cores as the SITL, so part of
any slowdown is CPU contention, not the autopilot's own work; the ratios against ``quiet`` in one
run are the figures to read.

Run: ``.venv/bin/python benchmarks/hostile_load.py [--duration 40] [--paced-duration 10]``.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import re
import sys
import time

from sitl.launcher import LINKED, Child, Launcher, VehicleSpec

INSTANCE = 94
RTT = re.compile(r"HIL round trip median (\d+) us, p99 (\d+) us")
REANCHORS = re.compile(r"(\d+) re-anchors")
TRAFFIC = {
    "quiet": [],
    "load": [["load", "--clients", "8"]],
    "hostile": [["hostile", "--rate", "3000", "--sources", "300", "--datagrams", "1000000"]],
    "flood": [["hostile", "--rate", "0", "--sources", "1000", "--datagrams", "10000000"]],
}


def run_once(traffic: list[list[str]], duration: float, speed: str) -> tuple[float, int, int, int, list[str]]:
    spec = VehicleSpec(instance=INSTANCE, scenario="circle", speed=speed, autostart=True, duration_s=duration,
                       extra_autopilot_args=("--quiet",))  # fmt: skip
    clients: list[Child] = []
    with Launcher() as launcher:
        sim = launcher.spawn("simulator", spec.simulator_command())
        sim.wait_line("waiting for the autopilot", 30.0)
        for args in traffic:
            cmd = [sys.executable, "-u", "-m", "sitl.spray", *args, "--instance", str(INSTANCE),
                   "--seconds", "120"]  # fmt: skip
            clients.append(launcher.spawn(f"spray {args[0]}", cmd))
        time.sleep(0.5)  # the traffic is flowing before the autopilot starts
        launcher.spawn("autopilot", spec.autopilot_command())
        sim.wait_line(LINKED, 30.0)
        start = time.perf_counter()
        sim.wait(600.0)
        elapsed = time.perf_counter() - start
        match = RTT.search(sim.output)
        late = REANCHORS.search(sim.output)
        for client in clients:
            client.stop()
        notes = [line for c in clients for line in c.output.splitlines()[:1]]
    median, p99 = (int(match.group(1)), int(match.group(2))) if match else (0, 0)
    return duration / elapsed, median, p99, int(late.group(1)) if late else -1, notes


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--duration", type=float, default=40.0, help="simulated s per run at max speed")
    parser.add_argument("--paced-duration", type=float, default=10.0, help="simulated s per run at speed 1")
    args = parser.parse_args()
    results = {}
    for speed, duration in (("1", args.paced_duration), ("max", args.duration)):
        for name, traffic in TRAFFIC.items():
            rtf, median, p99, late, notes = run_once(traffic, duration, speed)
            results[speed, name] = (rtf, median, p99, late)
            print(f"speed {speed:3s} {name:8s}: {rtf:5.2f}x real time, HIL round trip median {median} us, "
                  f"p99 {p99} us, {late} pacer re-anchors"
                  + (f"  [{'; '.join(notes)}]" if notes else ""), flush=True)  # fmt: skip
    print()
    for (speed, name), (rtf, _median, p99, late) in results.items():
        tag = "paced" if speed == "1" else "max"
        print(f"sitl_rtf_{tag}_{name}: {rtf:.2f} x")
        if tag == "paced":
            print(f"pacer_reanchors_paced_{name}: {late} frames")
        print(f"control_step_latency_p99_{tag}_{name}: {p99} us")
        if name != "quiet":
            print(f"rtf_ratio_{tag}_{name}_vs_quiet: {rtf / results[speed, 'quiet'][0]:.2f}")


if __name__ == "__main__":
    main()
