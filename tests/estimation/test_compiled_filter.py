"""The compiled covariance arithmetic (:mod:`autopilot.estimation.compiled`) against the numpy
products it replaces: the same filter to round-off over whole flights, each fusion kind included
(a prediction per IMU sample; GPS, baro and magnetometer with ``gps``; vision with ``mocap``)."""

from __future__ import annotations

import numpy as np
import pytest

from autopilot.estimation import eskf, load_estimator_params
from simulator.sensors import load_sensors

from .helpers import helix_truth, run_filter

pytest.importorskip("numba")
if eskf._compiled_kernels() is None:  # QUADSITL_PURE_PYTHON=1: there is nothing to compare
    pytest.skip("the compiled filter is off", allow_module_level=True)


@pytest.mark.parametrize("profile", ["mocap", "gps"])
def test_compiled_filter_equals_the_numpy_products(profile, monkeypatch):
    truth = helix_truth(40.0, 10.0)[: round(16.0 * 500)]  # alignment, release, 6 s of the helix
    compiled = run_filter(truth, load_sensors(profile), load_estimator_params(profile), nees_every=50)
    monkeypatch.setattr(eskf, "_compiled_kernels", lambda: None)
    reference = run_filter(truth, load_sensors(profile), load_estimator_params(profile), nees_every=50)
    assert compiled.ekf._kernels is not None and reference.ekf._kernels is None
    a, b = compiled.ekf, reference.ekf
    for name in ("ev_pos", "ev_yaw", "gps_pos", "gps_vel", "baro", "mag"):
        assert a.sources[name].fused == b.sources[name].fused
        assert a.sources[name].rejected == b.sources[name].rejected
    assert sum(a.sources[n].fused for n in a.sources) > 1000  # the fusions did run
    scale = np.sqrt(np.outer(np.diag(b.P), np.diag(b.P)))
    assert np.abs(a.P - b.P).max() <= 1e-9 * scale.max()
    assert np.abs((a.P - b.P) / scale).max() < 1e-6
    assert np.array_equal(a.P, a.P.T)  # the kernels keep P exactly symmetric
    assert np.abs(compiled.pos_err - reference.pos_err).max() < 1e-9  # m
    assert np.abs(compiled.att_err - reference.att_err).max() < 1e-9  # rad
    assert np.allclose(compiled.sigma, reference.sigma, rtol=1e-8, atol=0.0)


def test_one_compiled_prediction_is_the_python_nominal_step_bit_for_bit():
    """predict_step transcribes the nominal propagation in the same order of operations: the same
    floats; the covariance to round-off."""
    from autopilot.estimation import ImuSample

    from .test_eskf import filter_at

    compiled, imu = filter_at()
    reference, _ = filter_at()
    reference._kernels = None
    rng = np.random.default_rng(5)
    for k in range(1, 200):
        gyro, force = tuple(rng.normal(0.0, 0.5, 3)), tuple(rng.normal((0.0, 0.0, 9.8), 0.5))
        step = ImuSample(k * 0.002, 0.002, gyro, force)
        compiled.predict(step)
        reference.predict(step)
        assert (compiled._p, compiled._v, compiled._q) == (reference._p, reference._v, reference._q), k
        assert compiled._prev_acc_world == reference._prev_acc_world and compiled._rate == reference._rate
    assert np.allclose(compiled.P, reference.P, rtol=1e-12, atol=1e-18)
    assert not np.array_equal(compiled.P, np.zeros_like(compiled.P))
