"""The filter's covariance arithmetic (:mod:`autopilot.estimation.kernels`) by its properties: the
prediction is ``F P F^T + Q`` for the F of the equations and the nominal state the trapezoid of
them; the batch update is the textbook Kalman update; P stays symmetric positive definite over
a flight; and the same source run by Python gives the compiled filter's output to round-off.

The entries tested are the ones the filter calls (compiled, or the kernels themselves in a
session with ``QUADSITL_PURE_PYTHON=1``)."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from autopilot.estimation import load_estimator_params
from autopilot.estimation.eskf import filter_entries
from autopilot.estimation.kernels import IBA, IBG, IP, ITH, IV, ImuStep, N, NominalState, update_work_size
from quadcommon.kernel import PROJECT_ROOT, compiling
from simulator.sensors import load_sensors

from .helpers import helix_truth, run_filter

pytestmark = pytest.mark.timeout(120)

G = 9.81


def random_covariance(rng: np.random.Generator, n: int = N) -> np.ndarray:
    """Symmetric positive definite, entries of a flight's magnitudes (1e-6 to 1e-1)."""
    A = rng.normal(size=(n, n)) * np.exp(rng.uniform(-7.0, -1.0, n))[:, None]
    return A @ A.T + np.diag(np.exp(rng.uniform(-14.0, -2.0, n)))


def skew(a) -> np.ndarray:
    return np.array(((0.0, -a[2], a[1]), (a[2], 0.0, -a[0]), (-a[1], a[0], 0.0)))


def matrix_of(q) -> np.ndarray:
    w, x, y, z = q
    return Rotation.from_quat((x, y, z, w)).as_matrix()


@pytest.mark.parametrize("seed", range(4))
def test_a_prediction_is_the_trapezoid_and_f_p_ft_plus_q(seed):
    """At a random state: the nominal step and ``F P F^T + Q`` built here from the equations of
    :mod:`.eskf`'s docstring, ``F = I + E`` with ``E_pv = I dt``, ``E_v theta = -[a dt]_x`` (the
    step's mean world specific force), ``E_v ba = E_theta bg = -R dt`` (R: the new attitude)."""
    rng = np.random.default_rng(seed)
    dt = (0.002, 0.004, 0.001, 0.0025)[seed]
    P0 = random_covariance(rng)
    noise = np.exp(rng.uniform(-20.0, -8.0, N))
    rate, previous_rate, gyro_bias = (tuple(rng.normal(0.0, s, 3)) for s in (2.0, 2.0, 0.02))
    force, accel_bias = tuple(rng.normal((0.0, 0.0, G), 3.0)), tuple(rng.normal(0.0, 0.2, 3))
    previous_world_force = tuple(rng.normal((0.0, 0.0, G), 3.0))
    q = tuple(Rotation.random(random_state=seed).as_quat(scalar_first=True))
    p, v = tuple(rng.normal(0.0, 10.0, 3)), tuple(rng.normal(0.0, 3.0, 3))

    P = P0.copy()
    q1, p1, v1, a1 = filter_entries().predict(
        P, noise, dt, G, ImuStep(rate, force, previous_rate, previous_world_force),
        NominalState(q, p, v, gyro_bias, accel_bias),
    )  # fmt: skip

    # Nominal: q1 = q (x) Exp(((w_prev + w)/2 - b_g) dt), a = R (f - b_a), the trapezoid for p, v.
    increment = (np.add(rate, previous_rate) / 2.0 - gyro_bias) * dt
    R1 = matrix_of(q) @ Rotation.from_rotvec(increment).as_matrix()
    assert np.linalg.norm(q1) == pytest.approx(1.0, abs=1e-15)
    assert np.abs(matrix_of(q1) - R1).max() < 1e-14
    a0, a = np.array(previous_world_force), R1 @ np.subtract(force, accel_bias)
    assert np.array(a1) == pytest.approx(a, abs=1e-13)
    ez = np.array((0.0, 0.0, 1.0))
    trapezoid = p + np.multiply(v, dt) + (a0 / 3 + a / 6 - G * ez / 2) * dt * dt
    assert np.array(p1) == pytest.approx(trapezoid, abs=1e-12)
    mean = (a0 + a) / 2.0
    assert np.array(v1) == pytest.approx(v + (mean - G * ez) * dt, abs=1e-12)

    F = np.eye(N)
    F[IP : IP + 3, IV : IV + 3] = np.eye(3) * dt
    F[IV : IV + 3, ITH : ITH + 3] = -skew(mean * dt)
    F[IV : IV + 3, IBA : IBA + 3] = -R1 * dt
    F[ITH : ITH + 3, IBG : IBG + 3] = -R1 * dt
    expected = F @ P0 @ F.T + np.diag(noise)
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    assert np.abs((P - expected) / scale).max() < 1e-12
    assert np.array_equal(P, P.T)


@pytest.mark.parametrize("rows", [1, 2, 3, 4, 6])
def test_the_joseph_update_is_the_textbook_kalman_update(rows):
    """``K = P H^T S^-1`` with numpy.linalg, ``(I - K H) P (I - K H)^T + K R K^T``, ``dx = K y``;
    the gates' prior variances are the diagonal of ``H P H^T``. Random P, sparse and dense H."""
    entries = filter_entries()
    rng = np.random.default_rng(100 + rows)
    for case in range(3):
        P0 = random_covariance(rng)
        H = rng.normal(size=(rows, N))
        if case < 2:  # a measurement's rows touch a few states (as the filter's do)
            H *= rng.uniform(size=(rows, N)) < 0.2
            H[np.arange(rows), rng.choice(N, rows, replace=False)] = 1.0
        r = np.exp(rng.uniform(-12.0, -2.0, rows))
        y = rng.normal(size=rows) * np.sqrt(r)

        prior = np.empty(rows)
        entries.prior_variances(P0, H, prior)
        assert prior == pytest.approx(np.diag(H @ P0 @ H.T), rel=1e-12)

        P, dx = P0.copy(), np.empty(N)
        work = np.full(update_work_size(rows, N), np.nan)  # (nothing read before it is written)
        entries.joseph_update(P, H, r, y, dx, work)
        S = H @ P0 @ H.T + np.diag(r)
        K = P0 @ H.T @ np.linalg.inv(S)
        A = np.eye(N) - K @ H
        expected = A @ P0 @ A.T + K @ np.diag(r) @ K.T
        scale = np.sqrt(np.outer(np.diag(P0), np.diag(P0)))
        assert np.abs((P - expected) / scale).max() < 1e-9, case
        assert dx == pytest.approx(K @ y, rel=1e-9, abs=1e-12 * np.abs(K @ y).max())
        assert np.array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > 0.0


@pytest.mark.parametrize("profile", ["mocap", "gps"])
def test_the_covariance_stays_symmetric_positive_definite_over_a_flight(profile):
    """Every fusion kind (vision, GPS, baro, magnetometer) and a prediction per IMU sample, over
    the alignment and 10 s of the paper's helix: P symmetric and positive definite at every
    frame (checked on every fifth), its variances bounded by the aiding."""
    truth = helix_truth(40.0, 2.0)[: round(12.0 * 500)]
    checked = []

    def check(t, ekf):
        if len(checked) % 5 == 0:
            P = ekf.P
            assert np.abs(P - P.T).max() <= 1e-15 * np.abs(P).max(), t
            assert np.linalg.eigvalsh(P).min() > 0.0, t
        checked.append(t)

    run = run_filter(truth, load_sensors(profile), load_estimator_params(profile), nees_every=50,
                     each_frame=check)  # fmt: skip
    assert len(checked) > 5000
    assert sum(s.fused for s in run.ekf.sources.values()) > 500
    assert np.isfinite(run.sigma).all() and run.sigma[-1, IP : IP + 3].max() < 1.0  # m


CHILD = textwrap.dedent("""
    import pickle, sys
    import numpy as np
    from autopilot.estimation import load_estimator_params
    from quadcommon.kernel import compiling
    from simulator.sensors import load_sensors
    from tests.autopilot.estimation.helpers import run_filter

    assert not compiling()
    truth, profile, out = pickle.load(open(sys.argv[1], "rb"))
    run = run_filter(truth, load_sensors(profile), load_estimator_params(profile), nees_every=10)
    e = run.ekf
    np.savez(out, P=e.P, pos_err=run.pos_err, att_err=run.att_err, sigma=run.sigma,
             counts=[(s.fused, s.rejected) for s in e.sources.values()])
""")


@pytest.mark.skipif(not compiling(), reason="numba is not installed or QUADSITL_PURE_PYTHON=1")
@pytest.mark.parametrize("profile", ["mocap", "gps"])
def test_python_runs_the_same_filter_as_the_compiled_path(profile, tmp_path):
    """The same short flight through the compiled entries (here) and through the kernels run by
    Python (a process with ``QUADSITL_PURE_PYTHON=1``): the same fusions, the same state and
    covariance to round-off."""
    truth = helix_truth(40.0, 2.0)[: round(4.0 * 500)]  # the alignment, then 2 s of the helix
    inputs, out = tmp_path / "inputs.pickle", tmp_path / "python.npz"
    inputs.write_bytes(pickle.dumps((truth, profile, str(out))))
    env = {**os.environ, "QUADSITL_PURE_PYTHON": "1"}
    child = subprocess.run([sys.executable, "-c", CHILD, str(inputs)], cwd=PROJECT_ROOT, env=env,
                           capture_output=True, text=True, timeout=100)  # fmt: skip
    assert child.returncode == 0, child.stderr
    python = np.load(out)
    run = run_filter(truth, load_sensors(profile), load_estimator_params(profile), nees_every=10)
    counts = [[s.fused, s.rejected] for s in run.ekf.sources.values()]
    assert python["counts"].tolist() == counts
    assert sum(fused for fused, _ in counts) > 100
    P, Pp = run.ekf.P, python["P"]
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P)))
    assert np.abs((P - Pp) / scale).max() < 1e-9
    assert np.abs(run.pos_err - python["pos_err"]).max() < 1e-9  # m
    assert np.abs(run.att_err - python["att_err"]).max() < 1e-9  # rad
    assert run.sigma == pytest.approx(python["sigma"], rel=1e-9)
