"""The flight log's cost per control step, in one process (no sockets, no other process's timing).

The paper's experiment on the in-process stack (simulator core, MAVLink frames, autopilot core;
armed at t = 0, so the whole run is logged, as ``benchmarks/sitl_rtf.py --log`` flies it) with the
flight log off and on, alternating, ``--repeat`` pairs; each run's CPU time (this process: the
machine is shared, CPU time moves less than the wall time). Two figures:

* the ratio of the CPU time per run, on / off (the median of the pairs). An upper bound of what
  logging adds to the lockstep: here the log's bytes are also written to disk in the loop (the
  SITL's autopilot writes them in a thread), and the denominator has no MAVLink transport;
* the time inside the autopilot's per-frame logging (``FrameRecords.log_frame`` of
  ``autopilot/logger/frame_records.py``: every sample the frame gives, its bytes packed; wall time
  of each call, summed) per control step, and the whole lockstep's CPU per control step with the
  log off, for scale.

Run: ``.venv/bin/python benchmarks/flight_log.py [--repeat 5] [--duration 20] [--scenario circle]``.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from autopilot.control.config import load_controller
from quadcommon.config import load_scenario
from sitl.inprocess import RunOptions, paper_stack


def fly(scenario, controller, duration_s: float, log_dir: str | None) -> tuple[float, float, int]:
    """One run: (CPU s of the run, s inside log_frame, control steps)."""
    stack = paper_stack(scenario, controller, RunOptions(duration_s=duration_s, log_dir=log_dir))
    records = stack.autopilot.records
    inside = [0.0]
    log_frame = records.log_frame
    clock, tick = time.process_time, time.perf_counter  # (process_time is a syscall: not per frame)

    def timed_log_frame(*args) -> None:
        t0 = tick()
        log_frame(*args)
        inside[0] += tick() - t0

    if log_dir is not None:
        records.log_frame = timed_log_frame
    steps = int(round(duration_s / stack.sim.dt_control))
    start = clock()
    for _ in range(steps):
        stack.step()
    stack.final_frame()
    cpu = clock() - start
    if log_dir is not None:
        assert stack.close(), "no flight log was written"
    return cpu, inside[0], steps


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeat", type=int, default=5, help="pairs of runs (off, on; alternating order)")
    parser.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run")
    parser.add_argument("--scenario", default="circle")
    parser.add_argument("--controller", default="intbs_nlhinf")
    args = parser.parse_args()
    scenario, controller = load_scenario(args.scenario), load_controller(args.controller)
    fly(scenario, controller, 1.0, None)  # warm-up: imports, numba's cache
    ratios, off_us, inside_us = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):
            order = (False, True) if k % 2 == 0 else (True, False)
            cpu = {}
            for on in order:
                log_dir = str(Path(tmp) / f"log{k}") if on else None
                run_cpu, log_cpu, steps = fly(scenario, controller, args.duration, log_dir)
                cpu[on] = run_cpu
                if on:
                    inside_us.append(log_cpu / steps * 1e6)
                else:
                    off_us.append(run_cpu / steps * 1e6)
            ratios.append(cpu[True] / cpu[False])
            print(f"pair {k + 1}: off {cpu[False]:.2f} s CPU, on {cpu[True]:.2f} s CPU, "
                  f"on/off {ratios[-1]:.3f}, log_frame {inside_us[-1]:.1f} us per control step")  # fmt: skip
    print(f"scenario {args.scenario}, {args.duration:g} s simulated per run, {args.repeat} pairs; "
          f"on/off from {min(ratios):.3f} to {max(ratios):.3f}")  # fmt: skip
    print(f"flight_log_inprocess_cpu_on_over_off: {statistics.median(ratios):.3f} ratio")
    print(f"flight_log_core_per_control_step: {statistics.median(inside_us):.1f} us")
    print(f"lockstep_per_control_step_log_off: {statistics.median(off_us):.1f} us")


if __name__ == "__main__":
    main()
