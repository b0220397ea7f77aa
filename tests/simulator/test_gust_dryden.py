"""Dryden turbulence: MIL-F-8785C scales, intensities and spectra, determinism, stepping rules."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy import signal

from simulator.environment import dryden
from simulator.environment.dryden import (
    FT,
    DrydenTurbulence,
    DrydenWind,
    TurbulenceOrderError,
    _DiscreteFilter,
    check_step,
    low_altitude_scales,
    shaping_filters,
    zoh,
)
from simulator.environment.gust_profile import DisturbanceSchedule, GustProfile, gust_profile_from_mapping

DT = 1e-3
FAST_V = 30.0  # fast sweep: short correlation times, so 10 minutes hold ~1000 of them


def _series(wind: DrydenWind, n: int) -> np.ndarray:
    at = wind.at_step
    return np.array([at(k) for k in range(n)])


def _autocorrelation(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float(np.dot(x[:-lag], x[lag:]) / np.dot(x, x))


@pytest.fixture(scope="module")
def fast_run() -> tuple[DrydenTurbulence, np.ndarray]:
    """10 minutes at 1 kHz through the per-step path, light turbulence at 2.5 m swept at 30 m/s."""
    params = DrydenTurbulence(w20_m_s=7.7, altitude_m=2.5, seed=2024, airspeed_m_s=FAST_V)
    return params, _series(DrydenWind(params, DT), 600_000)


# -- MIL-F-8785C low-altitude scales --------------------------------------------------------------------
def test_low_altitude_scales_in_feet_and_metres() -> None:
    s = low_altitude_scales(7.7, 2.5)
    h_ft = 2.5 / FT
    k = 0.177 + 0.000823 * h_ft
    assert s.length_w_m == pytest.approx(2.5)
    assert s.length_u_m == s.length_v_m == pytest.approx(h_ft / k**1.2 * FT)
    assert s.length_u_m == pytest.approx(19.09, abs=0.01)  # ~62.6 ft
    assert s.sigma_w_m_s == pytest.approx(0.77)  # 0.1 W20
    assert s.sigma_u_m_s == s.sigma_v_m_s == pytest.approx(0.77 / k**0.4)
    assert s.sigma_u_m_s == pytest.approx(1.516, abs=0.001)
    # At 1000 ft the boundary layer model meets the isotropic one: L = h, sigma_u = sigma_w.
    top = low_altitude_scales(15.4, 1000 * FT)
    assert top.length_u_m == pytest.approx(1000 * FT) and top.length_w_m == pytest.approx(1000 * FT)
    assert top.sigma_u_m_s == pytest.approx(top.sigma_w_m_s)


def test_filter_gains_give_the_one_sided_spectra() -> None:
    s = low_altitude_scales(7.7, 2.5)
    V = 5.0
    (nu, du), (nv, dv), _ = shaping_filters(s, V)
    w = 0.7
    _, hu = signal.freqs(nu, du, [w])
    _, hv = signal.freqs(nv, dv, [w])
    Lu, Lv = s.length_u_m, s.length_v_m
    phi_u = s.sigma_u_m_s**2 * 2 * Lu / (math.pi * V) / (1 + (Lu * w / V) ** 2)
    phi_v = s.sigma_v_m_s**2 * Lv / (math.pi * V) * (1 + 3 * (Lv * w / V) ** 2) / (1 + (Lv * w / V) ** 2) ** 2
    assert abs(hu[0]) ** 2 == pytest.approx(phi_u)
    assert abs(hv[0]) ** 2 == pytest.approx(phi_v)


def test_zoh_matches_scipy_cont2discrete() -> None:
    for num, den in shaping_filters(low_altitude_scales(15.4, 10.0), 5.0):
        A, B, C, D = signal.tf2ss(num, den)
        for dt in (1e-3, 0.05):
            Ad, Bd = zoh(A, B, dt)
            ref = signal.cont2discrete((A, B, C, D), dt, method="zoh")
            np.testing.assert_allclose(Ad, ref[0], rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(Bd, ref[1], rtol=1e-12, atol=1e-15)


def test_lfilter_state_reproduces_the_state_space_free_response() -> None:
    f = _DiscreteFilter([0.4, 1.0], [4.0, 4.0, 1.0], DT)
    x0 = np.array([[0.3], [-0.2]])
    f.set_state(x0)
    y = f.run(np.zeros(50))
    x, expected = x0, []
    for _ in range(50):
        expected.append((f.Cd @ x).item())
        x = f.Ad @ x
    np.testing.assert_allclose(y, expected, rtol=1e-10, atol=1e-15)


def test_discrete_stationary_deviation_equals_sigma() -> None:
    """Noise of variance pi/dt through the ZOH filters: stationary std = sigma (exact algebra)."""
    params = DrydenTurbulence(7.7, 2.5, seed=0)
    wind = DrydenWind(params, DT)
    for f in wind.filters:  # unit-intensity filters
        P = f.stationary_covariance()
        assert math.sqrt((f.Cd @ P @ f.Cd.T).item()) == pytest.approx(1.0, rel=1e-5)


# -- statistics over a long run -----------------------------------------------------------------------
def test_intensities_match_sigma_within_10_percent(fast_run) -> None:
    params, w = fast_run
    s = params.scales()
    std = w.std(axis=0)
    assert std[0] == pytest.approx(s.sigma_u_m_s, rel=0.10)
    assert std[1] == pytest.approx(s.sigma_v_m_s, rel=0.10)
    assert std[2] == pytest.approx(s.sigma_w_m_s, rel=0.10)
    assert np.abs(w.mean(axis=0)).max() < 0.15 * s.sigma_u_m_s


def test_correlation_times_follow_the_dryden_form(fast_run) -> None:
    """u: exp(-tau V/L); v, w: (1 - tau V/(2L)) exp(-tau V/L), zero at tau = 2 L/V."""
    params, w = fast_run
    s = params.scales()
    Tu, Tv, Tw = s.length_u_m / FAST_V, s.length_v_m / FAST_V, s.length_w_m / FAST_V
    assert _autocorrelation(w[:, 0], round(Tu / DT)) == pytest.approx(math.exp(-1), abs=0.06)
    assert _autocorrelation(w[:, 1], round(Tv / DT)) == pytest.approx(0.5 * math.exp(-1), abs=0.06)
    assert _autocorrelation(w[:, 2], round(Tw / DT)) == pytest.approx(0.5 * math.exp(-1), abs=0.04)
    assert _autocorrelation(w[:, 2], round(2 * Tw / DT)) == pytest.approx(0.0, abs=0.04)
    assert _autocorrelation(w[:, 2], round(0.2 * Tw / DT)) == pytest.approx(
        (1 - 0.1) * math.exp(-0.2), abs=0.03
    )


def test_power_spectral_density_follows_the_dryden_form(fast_run) -> None:
    """Welch estimates within 30 % of |H|^2 in bands around the corner V/L (seeds 1-5: <= 21 %)."""
    params, w = fast_run
    s = params.scales()
    for column, nperseg, (num, den) in zip(
        (0, 2), (1 << 15, 1 << 13), shaping_filters(s, FAST_V)[::2], strict=True
    ):
        L = (s.length_u_m, s.length_w_m)[column // 2]
        f, p = signal.welch(w[:, column], fs=1.0 / DT, nperseg=nperseg)
        corner = FAST_V / L / (2 * math.pi)  # Hz
        for lo, hi in ((0.3, 0.7), (0.8, 1.5), (2.0, 4.0)):
            band = (f >= lo * corner) & (f <= hi * corner)
            assert band.sum() >= 3
            _, h = signal.freqs(num, den, 2 * math.pi * f[band])
            measured = p[band].mean() / (2 * math.pi)  # per Hz -> per rad/s (one-sided)
            assert measured == pytest.approx(float(np.mean(np.abs(h) ** 2)), rel=0.3), (column, lo)


def test_warm_start_is_stationary_and_cold_start_is_at_rest() -> None:
    s = low_altitude_scales(7.7, 2.5)
    first = np.array([DrydenWind(DrydenTurbulence(7.7, 2.5, seed=k), DT).at_step(0) for k in range(300)])
    std = first.std(axis=0)
    assert std[0] == pytest.approx(s.sigma_u_m_s, rel=0.15)
    assert std[2] == pytest.approx(s.sigma_w_m_s, rel=0.15)
    cold = DrydenWind(DrydenTurbulence(7.7, 2.5, seed=5, mean_wind_m_s=(0.0, 0.0, 1.0), warm_start=False), DT)
    assert cold.at_step(0) == (0.0, 0.0, 1.0)  # the ZOH filters have no direct feed-through


def test_u_follows_the_horizontal_mean_wind() -> None:
    params = DrydenTurbulence(7.7, 2.5, seed=11, airspeed_m_s=FAST_V, mean_wind_m_s=(0.0, 3.0, 0.0))
    w = _series(DrydenWind(params, DT), 200_000)
    assert w[:, 1].mean() == pytest.approx(3.0, abs=0.25)
    T = params.scales().length_u_m / FAST_V
    lag = round(T / DT)
    # Along y (the mean wind): first-order u correlation; along x: the v form.
    assert _autocorrelation(w[:, 1], lag) == pytest.approx(math.exp(-1), abs=0.1)
    assert _autocorrelation(w[:, 0], lag) == pytest.approx(0.5 * math.exp(-1), abs=0.1)


# -- determinism and stepping rules ----------------------------------------------------------------------
def test_same_seed_same_turbulence_other_seed_other_turbulence() -> None:
    params = DrydenTurbulence(15.4, 5.0, seed=3)
    a = _series(DrydenWind(params, DT), 5000)
    b = _series(DrydenWind(params, DT), 5000)
    c = _series(DrydenWind(DrydenTurbulence(15.4, 5.0, seed=4), DT), 5000)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)


def test_value_depends_on_the_step_index_not_on_the_calls_in_between() -> None:
    params = DrydenTurbulence(7.7, 2.5, seed=9)
    every = _series(DrydenWind(params, DT), 5000)
    sparse = DrydenWind(params, DT)
    for k in range(0, 5000, 7):
        assert sparse.at_step(k) == tuple(every[k])
    jump = DrydenWind(params, DT)
    assert jump.at_step(4321) == tuple(every[4321])  # skips blocks, same value


def test_going_back_in_time_raises_a_clear_error() -> None:
    schedule = DisturbanceSchedule(GustProfile(dryden=DrydenTurbulence(7.7, 2.5, seed=1)))
    first = schedule.evaluate(0.010)
    assert schedule.evaluate(0.010) == first  # the same time twice is fine (frame + first substep)
    schedule.evaluate(0.011)
    with pytest.raises(TurbulenceOrderError, match="forward only.*non-decreasing times"):
        schedule.evaluate(0.009)


def test_schedule_is_deterministic_and_follows_its_start_offset() -> None:
    profile = gust_profile_from_mapping(
        {"dryden": {"w20_m_s": 7.7, "altitude_m": 2.5, "seed": 8, "start_s": 1.0}}
    )
    a = DisturbanceSchedule(profile, start_time_s=2.0)
    b = DisturbanceSchedule(profile, start_time_s=2.0)
    ta = [a.evaluate(k * DT)[2] for k in range(6000)]
    # b sampled at control rate (250 Hz) and physics rate (1 kHz) mixed, as the simulator does.
    for k in range(0, 6000, 4):
        b.evaluate(k * DT)
        for j in range(4):
            assert b.evaluate((k + j) * DT)[2] == ta[k + j]
    assert ta[2999] == (0.0, 0.0, 0.0) and ta[3000] != (0.0, 0.0, 0.0)  # starts at 2 + 1 s
    assert ta[3000] == DrydenWind(profile.dryden, DT).at_step(0)


def test_end_time_switches_the_turbulence_off_and_allows_caching() -> None:
    profile = gust_profile_from_mapping(
        {"dryden": {"w20_m_s": 7.7, "altitude_m": 2.5, "seed": 8, "end_s": 1.0}}
    )
    schedule = DisturbanceSchedule(profile)
    assert schedule.evaluate(0.5)[2] != (0.0, 0.0, 0.0)
    assert schedule.evaluate(1.0)[2] == (0.0, 0.0, 0.0)
    assert schedule._valid_until == math.inf


def test_step_too_coarse_for_the_time_constants_is_refused() -> None:
    params = DrydenTurbulence(7.7, 1.0, seed=0, airspeed_m_s=30.0)  # L_w / V = 33 ms
    check_step(params, 0.008)
    with pytest.raises(ValueError, match="too coarse"):
        check_step(params, 0.01)
    with pytest.raises(ValueError, match="too coarse"):
        DrydenWind(params, 0.01)


def test_the_numpy_filter_design_and_filtering_are_scipys() -> None:
    """dryden.tf2ss / ss2tf / lfilter / solve_discrete_lyapunov (numpy only, so that a simulator
    start does not import scipy.signal) against scipy's, on the Dryden filters and beyond."""
    from scipy import linalg

    rng = np.random.default_rng(5)
    shapes = dryden.shaping_filters(DrydenTurbulence(7.7, 2.5, seed=0).scales(), 15.0)
    for num, den in [*shapes, ([1.0, 2.0, 3.0], [2.0, 0.5, 0.3, 0.1])]:
        mine, ref = dryden.tf2ss(num, den), signal.tf2ss(num, den)
        for a, b in zip(mine, ref, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-15, atol=0.0)
        Ad, Bd = dryden.zoh(mine[0], mine[1], DT)
        b_mine, a_mine = dryden.ss2tf(Ad, Bd, mine[2], mine[3])
        b_ref, a_ref = signal.ss2tf(Ad, Bd, mine[2], mine[3])
        np.testing.assert_allclose(b_mine, b_ref.ravel(), rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(a_mine, a_ref, rtol=1e-13, atol=1e-15)
        x, zi = rng.standard_normal(3000), rng.standard_normal(len(a_ref) - 1)
        y_mine, z_mine = dryden.lfilter(b_ref.ravel(), a_ref, x, zi)
        y_ref, z_ref = signal.lfilter(b_ref.ravel(), a_ref, x, zi=zi)
        np.testing.assert_allclose(y_mine, y_ref, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(z_mine, z_ref, rtol=1e-9, atol=1e-12)
        Q = Bd @ Bd.T
        reference = linalg.solve_discrete_lyapunov(Ad, Q)
        np.testing.assert_allclose(dryden.solve_discrete_lyapunov(Ad, Q), reference, rtol=1e-9, atol=1e-15)


def test_a_simulator_starts_without_importing_scipy_signal() -> None:
    """What the filters cost every start before (~0.8 s of CPU): scipy.signal stays out of a
    simulator core, Dryden turbulence included. (scipy.linalg comes with numba, for its BLAS.)"""
    code = (
        "import sys\n"
        "from simulator.core import SimulatorCore, SimulatorSetup\n"
        "from simulator.environment.gust_profile import load_gust_profile\n"
        "from dataclasses import replace\n"
        "s = SimulatorSetup.load(scenario='hover')\n"
        "core = SimulatorCore(replace(s, gusts=load_gust_profile('dryden_light')))\n"
        "core.begin_frame(); core.end_frame(None)\n"
        "print(sorted(m for m in sys.modules if m.startswith('scipy.signal')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[]", out.stdout
