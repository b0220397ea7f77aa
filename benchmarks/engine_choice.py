"""Which engine for campaigns? The coupled plant's RK4 step, four ways, on this machine.

Run: ``.venv/bin/python benchmarks/engine_choice.py [--batch 1000] [--steps 2000]``.

The same plant (the coupled rigid body of ``simulator.dynamics.plant``, wrench actuation, CoM
offset, products of inertia, a torque disturbance on the Euler coordinates) integrated by RK4 at
1 kHz with the inputs held, measured as nanoseconds per vehicle-step (one RK4 step of one
vehicle):

* ``numpy_batch``: a batch axis over runs, every operation on arrays of ``--batch`` runs;
* ``jax_batch``: the same array code under ``jax.jit`` with ``lax.fori_loop`` over the steps
  (float64, CPU), the way crazyflow batches worlds (skipped if JAX is not installed);
* ``numba_per_run``: the campaign kernel's ``rk4_step``, a compiled loop over the steps of one
  run, then the next run;
* ``numba_batch``: the same compiled step, the loop over runs inside the loop over steps.

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


def _constants(plant: Plant):
    J = np.array(plant.inertia, dtype=float)
    K = np.array(plant.inertia_inv, dtype=float)
    return plant.mass, plant.gravity, J, K, np.array(plant.com_offset, dtype=float)


def derivative_xp(xp, s, m, g, J, K, rc):
    """The coupled plant's derivative on a batch ``s`` of shape (13, B), any array module."""
    vx, vy, vz, qw, qx, qy, qz, p, q, r = s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11], s[12]
    xx, yy = qx * qx, qy * qy
    xz, yz = qx * qz, qy * qz
    wx, wy = qw * qx, qw * qy
    R02, R12 = 2.0 * (xz + wy), 2.0 * (yz - wx)
    R20, R21, R22 = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)
    thrust = THRUST
    tx = TORQUE[0] - rc[1] * thrust
    ty = TORQUE[1] + rc[0] * thrust
    tz = TORQUE[2]
    ap, aq, ar = DIST_TORQUE
    st = -R20
    ct = xp.sqrt(xp.maximum(1.0 - st * st, 1e-12))
    sf, cf = R21 / ct, R22 / ct
    rhs = (ar + st * ap) / ct
    tx = tx + ap
    ty = ty + cf * aq + sf * rhs
    tz = tz - sf * aq + cf * rhs
    hx = J[0, 0] * p + J[0, 1] * q + J[0, 2] * r
    hy = J[1, 0] * p + J[1, 1] * q + J[1, 2] * r
    hz = J[2, 0] * p + J[2, 1] * q + J[2, 2] * r
    ex = tx - (q * hz - r * hy)
    ey = ty - (r * hx - p * hz)
    ez = tz - (p * hy - q * hx)
    dp = K[0, 0] * ex + K[0, 1] * ey + K[0, 2] * ez
    dq = K[1, 0] * ex + K[1, 1] * ey + K[1, 2] * ez
    dr = K[2, 0] * ex + K[2, 1] * ey + K[2, 2] * ez
    return xp.stack(
        [
            vx, vy, vz, R02 * thrust / m, R12 * thrust / m, R22 * thrust / m - g,
            -0.5 * (qx * p + qy * q + qz * r), 0.5 * (qw * p + qy * r - qz * q),
            0.5 * (qw * q + qz * p - qx * r), 0.5 * (qw * r + qx * q - qy * p),
            dp, dq, dr,
        ]
    )  # fmt: skip


def rk4_xp(xp, s, consts):
    f = derivative_xp
    k1 = f(xp, s, *consts)
    k2 = f(xp, s + 0.5 * H * k1, *consts)
    k3 = f(xp, s + 0.5 * H * k2, *consts)
    k4 = f(xp, s + H * k3, *consts)
    s = s + H / 6.0 * (k1 + 2.0 * (k2 + k3) + k4)
    n = 1.0 / xp.sqrt(s[6] ** 2 + s[7] ** 2 + s[8] ** 2 + s[9] ** 2)
    return xp.concatenate([s[:6], s[6:10] * n, s[10:]])


def bench_numpy(state0, consts, batch, steps) -> float:
    s = np.repeat(state0[:13, None], batch, axis=1)
    start = time.perf_counter()
    for _ in range(steps):
        s = rk4_xp(np, s, consts)
    return (time.perf_counter() - start) / (steps * batch) * 1e9


def bench_jax(state0, consts, batch, steps) -> tuple[float, float] | None:
    try:
        import jax
    except ImportError:
        return None
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    jconsts = tuple(jnp.asarray(c) if isinstance(c, np.ndarray) else c for c in consts)

    @jax.jit
    def run(s):
        return jax.lax.fori_loop(0, steps, lambda i, x: rk4_xp(jnp, x, jconsts), s)

    s = jnp.asarray(np.repeat(state0[:13, None], batch, axis=1))
    start = time.perf_counter()
    run(s).block_until_ready()
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    run(s).block_until_ready()
    return (time.perf_counter() - start) / (steps * batch) * 1e9, compile_s


def _numba_loops():
    from numba import njit

    from simulator.dynamics.equations import U_SIZE, U_TAU, U_THRUST, U_TORQUE, rk4_step

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
        u = np.zeros(U_SIZE)
        u[U_THRUST] = THRUST
        u[U_TAU : U_TAU + 3] = TORQUE
        u[U_TORQUE : U_TORQUE + 3] = DIST_TORQUE
        return u

    return per_run, batch, inputs


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--batch", type=int, default=1000, help="runs in the batch (numpy, JAX, numba batch)")
    parser.add_argument("--steps", type=int, default=2000, help="RK4 steps per run measured")
    args = parser.parse_args()

    vehicle = load_vehicle("paper_quad")
    plant = Plant(vehicle, H)
    plant.reset((0.0, 0.0, 1.0), (0.0, 0.0, 0.5))
    state0 = np.array(plant.state)
    consts = _constants(plant)
    P = np.array(plant.parameters())

    results: dict[str, float] = {}
    # numpy is slow: a tenth of the steps gives the per-step cost just as well.
    results["numpy_batch"] = bench_numpy(state0, consts, args.batch, max(args.steps // 10, 20))
    print(f"numpy batch ({args.batch} runs): {results['numpy_batch']:.0f} ns per vehicle-step", flush=True)
    jax_result = bench_jax(state0, consts, args.batch, args.steps)
    if jax_result is not None:
        results["jax_batch"], jax_compile = jax_result
        print(
            f"JAX jit+fori_loop float64 ({args.batch} runs): {results['jax_batch']:.0f} ns per "
            f"vehicle-step (compile {jax_compile:.1f} s)",
            flush=True,
        )
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
        s0, Pc, eng.controller_array(load_controller("intbs_nlhinf"), vehicle, 1.0 / rates.control_hz),
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
