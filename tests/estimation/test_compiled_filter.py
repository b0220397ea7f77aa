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
