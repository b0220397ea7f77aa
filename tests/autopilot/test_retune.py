"""Gains changed in flight: the integral action's contribution is continuous across the change,
and the new gains act afterwards (Translational/NLHinf/IntBS retune, Cascade.retune)."""

from dataclasses import replace

import numpy as np
import pytest

from autopilot.control.cascade import Cascade, StateEstimate
from autopilot.control.command_filter import SecondOrderFilter
from autopilot.control.config import load_controller
from autopilot.control.laws.integral_backstepping_attitude import IntegralBacksteppingAttitude
from autopilot.control.laws.nlhinf import NonlinearHinfAttitude, nlhinf_gains
from autopilot.control.translational import TranslationalController
from quadcommon.config import load_vehicle
from quadcommon.trajectories import Reference

INERTIA = (0.004, 0.004, 0.0084)
NOMINAL = load_vehicle("paper_quad").nominal  # m 0.74 kg, the inertia above
M, G, UMAX = 0.74, 9.81, 28.0
DT = 0.002


def translational_step(ctrl, rng, integrate=False):
    """One update at a random (but reproducible by seed) state; returns the output."""
    p, v = tuple(rng.normal(scale=0.3, size=3)), tuple(rng.normal(scale=0.3, size=3))
    eta = tuple(rng.normal(scale=0.1, size=3))
    rp, rv, ra = (tuple(rng.normal(scale=0.2, size=3)) for _ in range(3))
    return ctrl.update(p, v, eta, rp, rv, ra, DT, integrate)


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs"])
def test_translational_integral_term_is_continuous_and_new_gains_act(name):
    gains = load_controller(name).translational
    ctrl = TranslationalController.for_gains(gains, NOMINAL, UMAX)
    ctrl.integral = [0.4, -0.7, 1.3]
    before = ctrl.integral_acceleration()
    out_before = translational_step(ctrl, np.random.default_rng(3))
    new = replace(gains, c2=(4.0, 1.0, 3.0), k_integral=(0.5, 3.0, 0.8))
    ctrl.retune(new)
    after = ctrl.integral_acceleration()
    assert after == pytest.approx(before, abs=1e-12, rel=1e-12)
    # The new gains act: the proportional part changes (same state, different c2) ...
    out_after = translational_step(ctrl, np.random.default_rng(3))
    assert out_after.acceleration_cmd_m_s2 != pytest.approx(out_before.acceleration_cmd_m_s2)
    # ... and the integral grows at the new rate.
    assert ctrl.gains == new


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs"])
def test_translational_output_is_identical_when_only_the_integral_gain_changes(name):
    """On the reference position (e1 = 0) the integral gain enters only through the integral term,
    so the whole output (U1, phi_r, theta_r, a) is unchanged at the change (1e-9)."""
    gains = load_controller(name).translational
    ctrl = TranslationalController.for_gains(gains, NOMINAL, UMAX)
    ctrl.integral = [0.3, 0.2, -0.5]
    rp = (0.5, -0.2, 2.0)
    args = (rp, (0.1, -0.3, 0.2), (0.05, -0.02, 0.4), rp, (0.2, 0.1, -0.1), (0.3, 0.0, 0.1), DT, False)
    out_before = ctrl.update(*args)
    ctrl.retune(replace(gains, k_integral=(0.2, 5.0, 0.75)))
    out_after = ctrl.update(*args)
    for a, b in zip(out_before, out_after, strict=True):
        assert np.allclose(a, b, rtol=0, atol=1e-9)
    assert ctrl.integral != [0.3, 0.2, -0.5]  # rescaled, not kept


def test_translational_new_integral_gain_acts_afterwards():
    gains = load_controller("intbs_nlhinf").translational
    ctrl = TranslationalController.for_gains(gains, NOMINAL, UMAX)
    ctrl.retune(replace(gains, k_integral=(3.0, 3.0, 3.0)))
    ctrl.integral = [0.0, 0.0, 0.0]
    # A constant error of 0.1 m in x for 1 s: xi grows by e2 = c1 e1 per second.
    for _ in range(500):
        ctrl.update((0.1, 0, 1), (0, 0, 0), (0, 0, 0), (0, 0, 1), (0, 0, 0), (0, 0, 0), DT)
    assert ctrl.integral[0] == pytest.approx(17 * 0.1 * 1.0)
    assert ctrl.integral_acceleration()[0] == pytest.approx(-3.0 * 1.7)


def random_attitude(rng):
    eta = tuple(rng.uniform(-0.5, 0.5, size=3))
    eta_dot = tuple(rng.normal(scale=1.0, size=3))
    ref, ref_rate, ref_acc = (tuple(rng.normal(scale=0.2, size=3)) for _ in range(3))
    return eta, eta_dot, ref, ref_rate, ref_acc


@pytest.mark.parametrize(
    "new",
    [
        nlhinf_gains(0.1, 3.0, 4.0, 1.5),  # lower omega3 (k_p and K_I)
        nlhinf_gains(0.1, 3.0, 9.0, 0.8),  # omega_u: the integral enters through (C + w_u^-2) k_p
        nlhinf_gains(0.2, 5.0, 20.0, 3.0),  # everything
    ],
)
def test_nlhinf_integral_torque_is_continuous_at_the_state_of_the_change(new):
    rng = np.random.default_rng(11)
    law = NonlinearHinfAttitude(load_controller("intbs_nlhinf").rotational, NOMINAL)
    for _ in range(20):
        law.integral = list(rng.normal(scale=0.2, size=3))
        eta, eta_dot, ref, ref_rate, ref_acc = random_attitude(rng)
        law.update(eta, eta_dot, ref, ref_rate, ref_acc, DT, integrate=False)  # the latest state
        before = law.integral_torque(eta, eta_dot)
        old = law.gains
        law.retune(new)
        after = law.integral_torque(eta, eta_dot)
        assert np.allclose(after, before, rtol=0, atol=1e-9)
        law.retune(old)  # and back


def test_nlhinf_torque_is_continuous_on_the_reference_when_the_gains_change():
    """On the reference (eta~ = eta~' = 0) the integral is the whole feedback: tau unchanged."""
    law = NonlinearHinfAttitude(load_controller("intbs_nlhinf").rotational, NOMINAL)
    law.integral = [0.05, -0.03, 0.02]
    eta, eta_dot = (0.1, -0.2, 0.3), (0.4, 0.1, -0.3)
    tau_before = law.update(eta, eta_dot, eta, eta_dot, (0.0, 0.0, 0.0), DT, integrate=False)
    law.retune(nlhinf_gains(0.1, 3.0, 3.0, 1.0))
    tau_after = law.update(eta, eta_dot, eta, eta_dot, (0.0, 0.0, 0.0), DT, integrate=False)
    assert np.allclose(tau_after, tau_before, rtol=0, atol=1e-9)
    # The new gains act on an error: a smaller omega3 gives a smaller k_p.
    assert law.k_p == pytest.approx(30.0)


def test_nlhinf_retune_before_any_state_uses_the_hover_approximation():
    gains = load_controller("intbs_nlhinf").rotational
    law = NonlinearHinfAttitude(gains, NOMINAL)
    law.integral = [1.0, 2.0, 3.0]
    law.retune(nlhinf_gains(0.1, 3.0, 4.5, 3.0))
    scale = (90.0 / 1.5**2) / (45.0 / 3.0**2)
    assert law.integral == pytest.approx([scale, 2 * scale, 3 * scale])


def test_intbs_attitude_integral_term_is_continuous():
    rot = load_controller("intbs").rotational
    law = IntegralBacksteppingAttitude(rot, NOMINAL)
    rng = np.random.default_rng(2)
    law.integral = list(rng.normal(scale=0.1, size=3))
    eta, eta_dot, ref, ref_rate, ref_acc = random_attitude(rng)
    before = law.integral_acceleration()
    tau_before = law.update(eta, eta_dot, ref, ref_rate, ref_acc, DT, integrate=False)
    # Only lambda and c2 together such that c2 lambda changes, c1 kept.
    law.retune(replace(rot, c2=(50.0, 90.0, 40.0), k_integral=(45.0, 60.0, 100.0)))
    after = law.integral_acceleration()
    assert np.allclose(after, before, rtol=0, atol=1e-12)
    tau_after = law.update(eta, eta_dot, ref, ref_rate, ref_acc, DT, integrate=False)
    assert not np.allclose(tau_after, tau_before)  # the proportional part changes as it must


def test_command_filter_keeps_its_state():
    cfg = load_controller("intbs_nlhinf").command_filter
    f = SecondOrderFilter(cfg, DT)
    for _ in range(20):
        f.advance((0.2, -0.1))
    value, rate = list(f.value), list(f.rate)
    f.retune(replace(cfg, natural_frequency_rad_s=20.0))
    assert f.value == value and f.rate == rate
    slow = SecondOrderFilter(replace(cfg, natural_frequency_rad_s=20.0), DT)
    slow.value, slow.rate, slow.initialised = list(value), list(rate), True
    f.advance((0.2, -0.1))
    slow.advance((0.2, -0.1))
    assert f.value == pytest.approx(slow.value, abs=1e-15)


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs", "bs_nlhinf"])
def test_cascade_thrust_is_continuous_across_a_retune(name):
    """Hovering with built-up integrals: U1 does not jump when the integral gains change."""
    config = load_controller(name)
    cascade = Cascade(config, load_vehicle("paper_quad"), DT)
    ref = Reference((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
    # A steady offset below the reference (as under a sustained disturbance) builds the integrals.
    offset = StateEstimate((0.01, -0.01, 1.98), (0.0, 0.0, 0.0), (0.01, -0.01, 0.0), (0.0, 0.0, 0.0))
    for _ in range(1000):
        cascade.step(offset, ref)
    # Then evaluated on the reference position: U1 = m (g + a_z) / (cos phi cos theta), with a_z
    # the integral term alone.
    on_ref = StateEstimate((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.01, -0.01, 0.0), (0.0, 0.0, 0.0))
    before = cascade.step(on_ref, ref, integrate=False)
    tr, rot = config.translational, config.rotational
    if rot.law == "nlhinf" and rot.omega3 > 0:
        rot = replace(rot, omega3=4.0)
    elif rot.law != "nlhinf":
        rot = replace(rot, k_integral=tuple(0.5 * k for k in rot.k_integral))
    if tr.law != "backstepping":
        tr = replace(tr, k_integral=(0.5, 0.5, 0.5))
    cascade.retune(replace(config, translational=tr, rotational=rot))
    after = cascade.step(on_ref, ref, integrate=False)
    assert after.thrust_n == pytest.approx(before.thrust_n, abs=1e-9)
    assert after.roll_pitch_raw_rad == pytest.approx(before.roll_pitch_raw_rad, abs=1e-9)
    if config.translational.law != "backstepping":
        assert abs(before.thrust_n - M * G) > 0.01  # there was an integral to keep


def test_cascade_refuses_a_different_law():
    cascade = Cascade(load_controller("intbs_nlhinf"), load_vehicle("paper_quad"), DT)
    with pytest.raises(ValueError, match="restart"):
        cascade.retune(load_controller("intbs"))
