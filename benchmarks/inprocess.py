"""In-process simulation speed: one 40 s paper scenario at 1 kHz physics, 500 Hz control.

Run: ``.venv/bin/python benchmarks/inprocess.py [--repeat N]``. Reports the best of N runs (the
machine is shared; the best run is the least disturbed) and, for comparison in the same run, the
cost of one RK4 step of the plant alone. Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import time

from autopilot.control.config import load_controller
from quadcommon.config import load_scenario, load_vehicle
from simulator.dynamics.plant import Plant
from sitl.inprocess import run_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenario", default="circle")
    parser.add_argument("--controller", default="intbs_nlhinf")
    args = parser.parse_args()

    scenario, controller = load_scenario(args.scenario), load_controller(args.controller)
    best = float("inf")
    for i in range(args.repeat):
        start = time.perf_counter()
        record = run_scenario(scenario, controller)
        elapsed = time.perf_counter() - start
        best = min(best, elapsed)
        print(f"run {i + 1}: {elapsed:.3f} s")
    sim_time = float(record.time_s[-1])
    physics_steps = round(sim_time * 1000)

    plant = Plant(load_vehicle(), 0.001)
    plant.reset((0.0, 0.0, 1.0), (0.0, 0.0, 0.5))
    plant.set_wrench(7.3, (0.001, 0.0, 0.0))
    plant.set_disturbance((1.0, 0.0, 0.0), (0.1, 0.1, 0.1))
    n = 20000
    start = time.perf_counter()
    for _ in range(n):
        plant.step()
    rk4_us = (time.perf_counter() - start) / n * 1e6

    print(f"scenario {args.scenario}, controller {args.controller}, {sim_time:.0f} s simulated")
    print(f"inprocess_real_time_factor: {sim_time / best:.1f} x")
    print(f"inprocess_physics_steps_per_s: {physics_steps / best:.0f} steps/s")
    print(f"plant_rk4_step: {rk4_us:.1f} us")


if __name__ == "__main__":
    main()
