"""Estimator cost: microseconds per IMU prediction, per fusion of each kind, per control step.

Run: ``.venv/bin/python benchmarks/estimator.py [--repeat N] [--seconds S]``. The inputs are the
sensor models' own samples (profiles ``gps`` and ``mocap``) of a vehicle held at a pose for ``S``
simulated seconds, generated before timing; the filter (``autopilot.estimation``) is then fed
exactly as the autopilot feeds it, each call timed. Reports the best of N runs per figure (the
machine is shared: the best run is the least disturbed). Also measured, in the same run, why the
hot path is written as it is: the covariance prediction ``F P F^T + Q`` as the filter computes it
(:func:`autopilot.estimation.kernels.predict_covariance`, compiled; run by Python with
``QUADSITL_PURE_PYTHON=1``), as two numpy products and as a block-sparse plain-float version
written out below; and the nominal propagation in plain floats against small numpy arrays.
Last lines: ``name: value unit``.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from autopilot.estimation import (
    BaroSample,
    ErrorStateEkf,
    GpsFix,
    ImuSample,
    MagSample,
    VisionPose,
    load_estimator_params,
)
from autopilot.estimation.kernels import predict_covariance
from quadcommon.kernel import compiled, compiling
from quadcommon.rigid_body import quaternion_from_euler, rotation_from_quaternion
from simulator.dynamics.plant import TruthState
from simulator.sensors import SensorSuite, load_sensors

RATE_HZ = 500.0
HOME_ALT_M = 488.0


def held_truth() -> TruthState:
    q = quaternion_from_euler(0.02, -0.01, 0.5)
    R = rotation_from_quaternion(*q)
    g = 9.81
    return TruthState(
        position_m=(0.5, 0.0, 1.0), velocity_m_s=(0.0, 0.0, 0.0), acceleration_m_s2=(0.0, 0.0, 0.0),
        quaternion=q, euler_rad=(0.02, -0.01, 0.5), body_rates_rad_s=(0.0, 0.0, 0.0),
        euler_rates_rad_s=(0.0, 0.0, 0.0), specific_force_body_m_s2=(R[2][0] * g, R[2][1] * g, R[2][2] * g),
        rotor_speeds_rad_s=(0.0, 0.0, 0.0, 0.0), thrust_n=0.0, torque_body_n_m=(0.0, 0.0, 0.0),
        on_ground=False,
    )  # fmt: skip


def make_inputs(profile: str, seconds: float) -> list:
    """Per frame: the calls the autopilot would make, as ``(kind, sample)`` lists."""
    suite = SensorSuite(load_sensors(profile), HOME_ALT_M, imu_rate_hz=RATE_HZ)
    truth = held_truth()
    frames = []
    dt = 1.0 / RATE_HZ
    for k in range(round(seconds * RATE_HZ)):
        t = k * dt
        f = suite.step(t, truth)
        calls = [("predict", ImuSample(t, dt, f.imu.angular_rate_rad_s, f.imu.specific_force_m_s2))]
        if f.gps is not None:
            g = f.gps
            fix = GpsFix(t, g.position_m, g.velocity_m_s, g.eph_m, g.epv_m, g.speed_accuracy_m_s, g.fix_type)
            calls.append(("gps", fix))
        if f.baro is not None:
            calls.append(("baro", BaroSample(t, f.baro.pressure_altitude_m - HOME_ALT_M)))
        if f.mag is not None:
            calls.append(("mag", MagSample(t, f.mag.field_gauss)))
        if f.vision is not None:
            v = f.vision
            calls.append(("vision", VisionPose(t, v.position_m, v.yaw_rad, v.position_std_m, v.yaw_std_rad)))
        calls.append(("estimate", None))
        frames.append(calls)
    return frames


def feed(profile: str, frames: list) -> tuple[dict[str, float], dict[str, int], float, int]:
    """Feed one run; per-kind total seconds and counts of the calls that fused or gated a sample
    (after the alignment; a sample skipped by a fusion-rate limit is not counted), and the
    total over the control steps."""
    ekf = ErrorStateEkf(load_estimator_params(profile))
    methods = {
        "predict": ekf.predict, "gps": ekf.fuse_gps, "baro": ekf.fuse_baro, "mag": ekf.fuse_mag,
        "vision": ekf.fuse_vision,
    }  # fmt: skip
    total = dict.fromkeys((*methods, "estimate"), 0.0)
    count = dict.fromkeys(total, 0)
    clock = time.perf_counter
    sources = list(ekf.sources.values())
    step_total, steps = 0.0, 0
    for calls in frames:
        measured = ekf.initialised  # alignment steps are cheaper: not counted
        step_start = clock()
        for kind, sample in calls:
            tested = sum(s.fused + s.rejected for s in sources) if kind not in ("predict", "estimate") else 0
            start = clock()
            if kind == "estimate":
                ekf.estimate()
            else:
                methods[kind](sample)
            elapsed = clock() - start
            if measured and (
                kind in ("predict", "estimate") or sum(s.fused + s.rejected for s in sources) != tested
            ):
                total[kind] += elapsed
                count[kind] += 1
        if measured:
            step_total += clock() - step_start
            steps += 1
    return total, count, step_total, steps


# -- the alternatives measured against the filter's choices ------------------------------------------
def covariance_numpy(
    P: np.ndarray, F: np.ndarray, q: np.ndarray, diag: np.ndarray, dt: float, S: np.ndarray, B: np.ndarray
) -> np.ndarray:
    """F P F^T + Q as numpy products: fill F's moving blocks (see covariance_plain), two products,
    add Q."""
    F[0, 3] = F[1, 4] = F[2, 5] = dt
    F[3:6, 6:9] = S
    F[3:6, 12:15] = F[6:9, 9:12] = B
    P = F @ P @ F.T
    P.flat[diag] += q
    return P


def covariance_plain(P: list, dt: float, S: list, B: list, q: list) -> list:
    """F P F^T + Q in plain floats, using F = I + G with G's four non-zero 3x3 blocks
    (p<-v: dt I, v<-theta: S, v<-b_a: B, theta<-b_g: B); rows then columns."""
    n = len(P)
    M = [row[:] for row in P]
    for i in range(3):  # rows: M = F P
        M[i] = [a + dt * b for a, b in zip(P[i], P[3 + i], strict=True)]
        s0, s1, s2 = S[i]
        b0, b1, b2 = B[i]
        M[3 + i] = [
            P[3 + i][c]
            + s0 * P[6][c]
            + s1 * P[7][c]
            + s2 * P[8][c]
            + b0 * P[12][c]
            + b1 * P[13][c]
            + b2 * P[14][c]
            for c in range(n)
        ]
        M[6 + i] = [P[6 + i][c] + b0 * P[9][c] + b1 * P[10][c] + b2 * P[11][c] for c in range(n)]
    out = [row[:] for row in M]
    for r in range(n):  # columns: (F P) F^T
        Mr = M[r]
        o = out[r]
        for i in range(3):
            s0, s1, s2 = S[i]
            b0, b1, b2 = B[i]
            o[i] = Mr[i] + dt * Mr[3 + i]
            o[3 + i] = (
                Mr[3 + i] + s0 * Mr[6] + s1 * Mr[7] + s2 * Mr[8] + b0 * Mr[12] + b1 * Mr[13] + b2 * Mr[14]
            )
            o[6 + i] = Mr[6 + i] + b0 * Mr[9] + b1 * Mr[10] + b2 * Mr[11]
        o[r] += q[r]
    return out


def nominal_numpy(p, v, R, f, g, dt):
    """The nominal position/velocity step with small numpy arrays (the alternative to floats)."""
    a = R @ f - g
    return p + v * dt + 0.5 * a * dt * dt, v + a * dt


def nominal_floats(p, v, R, f, g, dt):
    """The same step in plain floats (how the filter writes it)."""
    ax = R[0][0] * f[0] + R[0][1] * f[1] + R[0][2] * f[2]
    ay = R[1][0] * f[0] + R[1][1] * f[1] + R[1][2] * f[2]
    az = R[2][0] * f[0] + R[2][1] * f[1] + R[2][2] * f[2] - g
    h = 0.5 * dt * dt
    return (
        (p[0] + v[0] * dt + ax * h, p[1] + v[1] * dt + ay * h, p[2] + v[2] * dt + az * h),
        (v[0] + ax * dt, v[1] + ay * dt, v[2] + az * dt),
    )


def best_us(fn, n: int, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - start) / n)
    return best * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per run")
    args = parser.parse_args()

    figures: dict[str, float] = {}
    for profile in ("gps", "mocap"):
        frames = make_inputs(profile, args.seconds)
        best_kind: dict[str, float] = {}
        best_step = math.inf
        for _ in range(args.repeat):
            total, count, step_total, steps = feed(profile, frames)
            for kind, seconds in total.items():
                if count[kind]:
                    best_kind[kind] = min(best_kind.get(kind, math.inf), seconds / count[kind] * 1e6)
            best_step = min(best_step, step_total / steps * 1e6)
        per_call = ", ".join(f"{k} {v:.1f}" for k, v in best_kind.items())
        print(f"{profile}: us per call (fusions: per sample fused or gated): {per_call}; "
              f"per control step {best_step:.1f} us")  # fmt: skip
        figures[f"estimator_step_{profile}"] = best_step
        for kind, us in best_kind.items():
            figures.setdefault(f"estimator_{kind}", us)

    # The hot-path choices, measured in this run.
    n = 19
    rng = np.random.default_rng(1)
    A = rng.normal(size=(n, n))
    P = A @ A.T * 1e-3 + np.eye(n) * 1e-3
    F = np.eye(n)
    q = np.full(n, 1e-9)
    diag = np.arange(n) * (n + 1)
    Pl = P.tolist()
    S = [[0.0, 0.02, -0.001], [-0.02, 0.0, 0.003], [0.001, -0.003, 0.0]]
    B = [[-0.002, 0.0001, 0.0], [-0.0001, -0.002, 0.0], [0.0, 0.0, -0.002]]
    Sa, Ba = np.array(S), np.array(B)
    numpy_us = best_us(lambda: covariance_numpy(P, F, q, diag, 0.002, Sa, Ba), 5000, args.repeat)
    ql = q.tolist()
    plain_us = best_us(lambda: covariance_plain(Pl, 0.002, S, B, ql), 500, args.repeat)
    ref = F.copy()
    ref[0:3, 3:6] = np.eye(3) * 0.002
    ref[3:6, 6:9], ref[3:6, 12:15], ref[6:9, 9:12] = S, B, B
    assert np.allclose(np.array(covariance_plain(Pl, 0.002, S, B, ql)), ref @ P @ ref.T + np.diag(q))
    # The filter's kernel on the same F (R = -B / dt; S = -[m dt]_x).
    kernel = compiled(predict_covariance)
    dt = 0.002
    R = tuple(tuple(-b / dt for b in row) for row in B)
    md = (S[1][2], S[2][0], S[0][1])
    Pk = P.copy()
    kernel(Pk, q, dt, md, R)
    assert np.allclose(Pk, ref @ P @ ref.T + np.diag(q), rtol=1e-12, atol=1e-18)
    kernel_us = best_us(lambda: kernel(Pk, q, dt, md, R), 5000 if compiling() else 200, args.repeat)
    p3, v3, f3, g3 = np.zeros(3), np.ones(3), np.array([0.1, 0.2, 9.8]), np.array([0.0, 0.0, 9.81])
    R3 = np.eye(3)
    nominal_np_us = best_us(lambda: nominal_numpy(p3, v3, R3, f3, g3, 0.002), 20000, args.repeat)
    Rt = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    nominal_fl_us = best_us(
        lambda: nominal_floats((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), Rt, (0.1, 0.2, 9.8), 9.81, 0.002),
        20000,
        args.repeat,
    )
    print(
        f"F P F^T: the filter's kernel{'' if compiling() else ' (run by Python)'} {kernel_us:.1f} us "
        f"vs numpy {numpy_us:.1f} us "
        f"vs block-sparse plain floats {plain_us:.1f} us "
        f"({plain_us / numpy_us:.0f}x); nominal p, v step: numpy {nominal_np_us:.1f} us vs floats "
        f"{nominal_fl_us:.1f} us ({nominal_np_us / nominal_fl_us:.0f}x)"
    )
    print()
    for name, value in figures.items():
        print(f"{name}: {value:.1f} us")
    print(f"covariance_prediction_{'compiled' if compiling() else 'python'}: {kernel_us:.1f} us")
    print(f"covariance_prediction_numpy: {numpy_us:.1f} us")
    print(f"covariance_prediction_plain_floats: {plain_us:.1f} us")
    print(f"nominal_pv_step_numpy: {nominal_np_us:.1f} us")
    print(f"nominal_pv_step_floats: {nominal_fl_us:.1f} us")


if __name__ == "__main__":
    main()
