"""The kernels' numeric helpers: clipping that lets NaN through, PX4's filtered derivative."""

import math

import pytest

from quadcommon.numerics import (
    DERIVATIVE,
    clip,
    filtered_derivative,
    low_pass_alpha,
)


def test_clip_passes_nan():
    assert clip(2.0, -1.0, 1.0) == 1.0 and clip(-2.0, -1.0, 1.0) == -1.0
    assert math.isnan(clip(math.nan, -1.0, 1.0))


def test_low_pass_alpha_is_px4s_block_low_pass():
    b = 2.0 * math.pi * 5.0 * 0.002
    assert low_pass_alpha(5.0, 0.002) == pytest.approx(b / (1.0 + b), abs=1e-15)
    assert low_pass_alpha(0.0, 0.002) == 1.0


def test_filtered_derivative_of_a_ramp_converges_to_its_slope():
    dt, alpha = 0.002, low_pass_alpha(5.0, 0.002)
    x = [0.0] * (2 + DERIVATIVE.size)  # at an offset, as inside a law's state
    assert filtered_derivative(x, 2, (1.0, 2.0, 3.0), alpha, dt, True) == (0.0, 0.0, 0.0)  # first sample
    slope = (0.5, -1.0, 2.0)
    for k in range(1, 2000):  # 4 s: 125 time constants of the 5 Hz low pass
        sample = (1.0 + slope[0] * k * dt, 2.0 + slope[1] * k * dt, 3.0 + slope[2] * k * dt)
        d = filtered_derivative(x, 2, sample, alpha, dt, True)
    assert d == pytest.approx(slope, rel=1e-9)
    # after one step, the filter has moved by alpha towards the raw difference quotient
    x = [0.0] * DERIVATIVE.size
    filtered_derivative(x, 0, (0.0, 0.0, 0.0), alpha, dt, True)
    assert filtered_derivative(x, 0, (0.01, 0.0, 0.0), alpha, dt, True)[0] == pytest.approx(alpha * 0.01 / dt)
    assert x[DERIVATIVE.filtered] == pytest.approx(alpha * 0.01 / dt)


def test_filtered_derivative_state_does_not_move_without_integrate():
    dt, alpha = 0.002, 0.3
    x = [0.0] * DERIVATIVE.size
    filtered_derivative(x, 0, (1.0, 1.0, 1.0), alpha, dt, True)
    saved = list(x)
    assert filtered_derivative(x, 0, (1.1, 1.0, 1.0), alpha, dt, False)[0] == pytest.approx(alpha * 0.1 / dt)
    assert x == saved
