"""In-process simulation speed at 1 kHz physics, 500 Hz control, the whole flight stack.

Three measurements, best of N runs each (the machine is shared; the best run is the least
disturbed), in wall time and in this process's CPU time, the CPU also per control frame:

* the paper's experiment (``run_scenario``: the scenario's 40 s from its initial state, armed at
  t = 0; simulator core, MAVLink frames, autopilot core with commander, health checks and cascade),
  flown on the simulator's state (the scenario's estimator, the truth by default);
* the same on the EKF (``--ekf-sensors``, ``gps`` by default: the autopilot decodes every
  frame's sensors and flies on its own estimate);
* the full-stack mission (``fly_mission_experiment``, the scenario flown as ``gcs_scripts/fly_paper.py``
  flies it through the SITL: its trajectory uploaded as a timed mission by the upload script's own
  client, takeoff, the curve under the gust profile, landing, until disarmed);

and, for comparison in the same run, one RK4 step of the plant alone (compiled with numba when it
is installed, as the simulator runs it; ``QUADSITL_PURE_PYTHON=1`` for the Python reference).

Run: ``.venv/bin/python benchmarks/inprocess.py [--repeat N] [--scenario helix] [--ekf-sensors gps]``.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import time

from autopilot.control.config import load_controller
from quadcommon.config import load_scenario, load_sitl, load_vehicle
from simulator.dynamics.plant import Plant
from sitl.inprocess import RunOptions, fly_mission_experiment, run_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenario", default="helix")
    parser.add_argument("--controller", default="intbs_nlhinf")
    parser.add_argument("--ekf-sensors", default="gps", help="sensor profile of the run on the EKF")
    args = parser.parse_args()

    scenario, controller = load_scenario(args.scenario), load_controller(args.controller)

    def best_of(fly) -> tuple[float, float, float]:
        """(simulated s, best wall s, best CPU s) of ``args.repeat`` runs of ``fly()``."""
        wall = cpu = float("inf")
        for _ in range(args.repeat):
            w0, c0 = time.perf_counter(), time.process_time()
            simulated = fly()
            wall, cpu = min(wall, time.perf_counter() - w0), min(cpu, time.process_time() - c0)
        return simulated, wall, cpu

    def paper() -> float:
        return float(run_scenario(scenario, controller).time_s[-1])

    def paper_ekf() -> float:
        options = RunOptions(estimator="ekf", sensors=args.ekf_sensors)
        return float(run_scenario(scenario, controller, options).time_s[-1])

    def mission() -> float:
        with contextlib.redirect_stdout(io.StringIO()):  # the mission client's progress lines
            _, _, stack = fly_mission_experiment(scenario, controller)
        return stack.t  # takeoff, the curve, landing: the whole flight

    results = {"paper_run": best_of(paper), "paper_run_ekf": best_of(paper_ekf), "mission": best_of(mission)}
    control_hz = load_sitl().rates.control_hz
    for name, (simulated, wall, cpu) in results.items():
        print(f"{name}: {simulated:.1f} s simulated in {wall:.2f} s wall, {cpu:.2f} s CPU "
              f"(best of {args.repeat})")  # fmt: skip
    sim_time = results["paper_run"][0]
    best = results["paper_run"][1]
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

    print(f"scenario {args.scenario}, controller {args.controller}")
    for name, (simulated, wall, cpu) in results.items():
        print(f"inprocess_{name}_real_time_factor: {simulated / wall:.1f} x")
        print(f"inprocess_{name}_real_time_factor_cpu: {simulated / cpu:.1f} x")
        print(f"inprocess_{name}_cpu_per_frame: {cpu / (simulated * control_hz) * 1e6:.1f} us")
    print(f"inprocess_physics_steps_per_s: {physics_steps / best:.0f} steps/s")
    print(f"plant_rk4_step: {rk4_us:.1f} us")


if __name__ == "__main__":
    main()
