"""The coupled plant's per-call costs, as the simulator pays them (compiled with numba;
``QUADSITL_PURE_PYTHON=1`` for the same equations run as Python).

* ``plant_frame``: :meth:`Plant.advance` of one lockstep frame at 1 kHz physics and 500 Hz
  control: two RK4 steps, each with its own disturbance, and the truth read-out, then
  :meth:`Plant.truth` (answered from the read-out) and new actuator controls, as
  ``simulator.core`` calls them per frame;
* ``plant_step``: one :meth:`Plant.step` (one RK4 step, the inputs held);
* ``plant_truth``: :meth:`Plant.truth` after a step (one derivative evaluation and the read-out);
* ``plant_step_kinematics``: a :meth:`Plant.step`, then :meth:`Plant.kinematics` (a controller
  with perfect state knowledge, as the tests' reference runners fly).

In this thread's CPU time (wall time on a shared VM also counts the time other processes hold
the core), best of ``--repeat`` short rounds (the least disturbed). It uses only the plant's
public API, so it measures any checkout given by ``PYTHONPATH``: compare two side by side, in
turns.

Run: ``.venv/bin/python benchmarks/plant.py [--vehicle paper_quad] [--calls 2000] [--repeat 50]``.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

from quadcommon.config import load_vehicle
from simulator.dynamics.plant import Plant


def best_us(call: Callable[[], object], calls: int, repeat: int) -> float:
    """The fastest round's CPU time per call (us)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.thread_time()
        for _ in range(calls):
            call()
        best = min(best, time.thread_time() - start)
    return best / calls * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--vehicle", default="paper_quad")
    parser.add_argument("--calls", type=int, default=2000, help="calls per round")
    parser.add_argument("--repeat", type=int, default=50, help="rounds (the best counts)")
    args = parser.parse_args()

    start = time.perf_counter()
    plant = Plant(load_vehicle(args.vehicle), 0.001)
    built_s = time.perf_counter() - start
    plant.reset((0.0, 0.0, 50.0), (0.05, -0.03, 0.5))
    controls = (0.5, 0.01, -0.01, 0.001)
    wind = (1.0, -0.5, 0.0)
    frame = [((1.0, 0.0, 0.0), (0.1, 0.1, 0.1), wind), ((1.01, 0.0, 0.0), (0.1, 0.1, 0.1), wind)]
    plant.set_actuator_controls(controls)
    plant.set_disturbance(*frame[0])

    def lockstep_frame() -> None:
        plant.set_actuator_controls(controls)
        plant.advance(frame)
        plant.truth()

    def truth_after_a_step() -> None:
        plant.set_disturbance(*frame[0])  # an input changed: the truth is read out again
        plant.truth()

    def step_and_kinematics() -> None:
        plant.step()
        plant.kinematics()

    results = {
        "plant_frame": best_us(lockstep_frame, args.calls, args.repeat),
        "plant_step": best_us(plant.step, args.calls, args.repeat),
        "plant_truth": best_us(truth_after_a_step, args.calls, args.repeat),
        "plant_step_kinematics": best_us(step_and_kinematics, args.calls, args.repeat),
    }
    print(f"vehicle {args.vehicle}: the first plant built in {built_s:.2f} s")
    for name, us in results.items():
        print(f"{name}: {us:.2f} us CPU")


if __name__ == "__main__":
    main()
