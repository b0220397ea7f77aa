"""The campaign engine's loop order: the coupled plant's RK4 step, compiled, two ways, on this machine.

Run: ``.venv/bin/python benchmarks/engine_choice.py [--batch 1000] [--steps 2000]``.

The plant's own compiled step (``simulator.dynamics.equations.rk4_step``: the coupled rigid body,
wrench actuation, CoM offset, products of inertia, a torque disturbance on the Euler coordinates)
at 1 kHz with the inputs held, measured as nanoseconds per vehicle-step (one RK4 step of one
vehicle):

* ``numba_per_run``: a compiled loop over the steps of one run, then the next run (the engine's);
* ``numba_batch``: the same step, the loop over runs inside the loop over steps.

(Array engines over a batch axis, numpy or JAX, would need an array-shaped second copy of the
plant's equations; none is kept here.)

Then the full closed loop (``numba_closed_loop``: plant + cascade + wire + indices, the
campaign's kernel) per run. Budget for the issue's target: 1,000 runs x 40 s x 1 kHz = 4e7
vehicle-steps (plus 2e7 controller steps) in 30 s on 2 cores, i.e. <= 1.5 µs per physics step
all included. Single-core figures; last lines ``name: value unit``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from autopilot.control.config import load_controller
from quadcommon.config import apply_uncertainty, load_scenario, load_sitl, load_vehicle
from simulator.dynamics.plant import Plant  # noqa: E402
from sitl.campaign import engine as eng  # noqa: E402

H = 1e-3
THRUST = 7.3
TORQUE = (0.001, -0.0005, 0.0002)
DIST_TORQUE = (0.1, 0.1, 0.1)


def _numba_loops():
    from numba import njit

    from simulator.dynamics.equations import INPUTS, rk4_step

    @njit(cache=True)
    def per_run(state0, P, u, steps, runs):
        n = state0.shape[0]
        k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        acc = 0.0
        for _ in range(runs):
            s = state0.copy()
            for _ in range(steps):
                rk4_step(s, k1, k2, k3, k4, tmp, P, u, 1e-3)
            acc += s[2]
        return acc

    @njit(cache=True)
    def batch(state0, P, u, steps, runs):
        n = state0.shape[0]
        S = np.empty((runs, n))
        for b in range(runs):
            S[b, :] = state0
        k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        for _ in range(steps):
            for b in range(runs):
                rk4_step(S[b], k1, k2, k3, k4, tmp, P, u, 1e-3)
        return S[:, 2].sum()

    def inputs():
        u = np.zeros(INPUTS.size)
        u[INPUTS.thrust] = THRUST
        u[INPUTS.torque : INPUTS.torque + 3] = TORQUE
        u[INPUTS.disturbance_torque : INPUTS.disturbance_torque + 3] = DIST_TORQUE
        return u

    return per_run, batch, inputs


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--batch", type=int, default=1000, help="a tenth: runs per loop order")
    parser.add_argument("--steps", type=int, default=2000, help="RK4 steps per run measured")
    args = parser.parse_args()

    vehicle = load_vehicle("paper_quad")
    plant = Plant(vehicle, H)
    plant.reset((0.0, 0.0, 1.0), (0.0, 0.0, 0.5))
    state0 = np.array(plant.state)
    P = np.array(plant.parameters())

    results: dict[str, float] = {}
    per_run, batch, inputs = _numba_loops()
    u = inputs()
    per_run(state0, P, u, 10, 1)
    batch(state0, P, u, 10, 2)  # compile (or load the cache) outside the timing
    runs = max(args.batch // 10, 1)
    start = time.perf_counter()
    per_run(state0, P, u, args.steps, runs)
    results["numba_per_run"] = (time.perf_counter() - start) / (args.steps * runs) * 1e9
    print(f"numba per-run loop: {results['numba_per_run']:.0f} ns per vehicle-step", flush=True)
    start = time.perf_counter()
    batch(state0, P, u, args.steps, runs)
    results["numba_batch"] = (time.perf_counter() - start) / (args.steps * runs) * 1e9
    print(f"numba batch loop ({runs} runs): {results['numba_batch']:.0f} ns per vehicle-step", flush=True)

    # The full closed loop: the campaign kernel, one 40 s helix run, IntBS-NLHinf, wire on.
    scenario = load_scenario("helix")
    rates = load_sitl().rates
    dtp = eng.dt_physics_of(rates)
    s0, Pc = eng.initial_state(apply_uncertainty(vehicle, scenario), dtp, scenario.initial_position_m,
                             scenario.initial_euler_rad)  # fmt: skip
    from simulator.environment.gust_profile import load_gust_profile

    st, rp, gu, dw, win = eng.disturbance_tables(load_gust_profile(scenario.gusts), dtp, scenario.duration_s)
    flight = eng.Flight(
        s0, Pc, eng.pack_controller(load_controller("intbs_nlhinf"), vehicle, 1.0 / rates.control_hz),
        eng.reference_table(scenario.trajectory, rates, scenario.duration_s, True),
        eng.sim_array(rates, scenario.duration_s, True, eng.FailureLimits(), win), st, rp, gu, dw,
    )  # fmt: skip
    eng.fly(flight)
    repeats = 20
    start = time.perf_counter()
    for _ in range(repeats):
        eng.fly(flight)
    per_flight = (time.perf_counter() - start) / repeats
    physics_steps = (flight.samples - 1) * rates.physics_steps_per_control
    results["numba_closed_loop"] = per_flight / physics_steps * 1e9
    print(
        f"numba closed loop (plant + cascade + wire + indices): {per_flight * 1e3:.1f} ms per 40 s run, "
        f"{results['numba_closed_loop']:.0f} ns per physics step",
        flush=True,
    )
    print()
    for name, ns in results.items():
        projected = ns * 4e7 / 2 * 1e-9
        print(f"{name}: {ns:.0f} ns/vehicle-step (4e7 steps on 2 cores: {projected:.0f} s)")


if __name__ == "__main__":
    main()
