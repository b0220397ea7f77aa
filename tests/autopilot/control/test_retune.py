"""Gains changed in flight: the laws' state maps so that their action is continuous across the
change, and the new gains act afterwards (each law's retune, Cascade.retune)."""

from dataclasses import replace

import numpy as np
import pytest

from autopilot.control import command_filter as cf
from autopilot.control.cascade import CASCADE_NUMBERS, Cascade
from autopilot.control.config import load_controller
from autopilot.control.laws.nlhinf import nlhinf_gains
from autopilot.records import StateEstimate
from quadcommon.config import load_vehicle
from quadcommon.rigid_body import euler_torque_from_body_torque
from quadcommon.trajectories import Reference
from tests.autopilot.laws import DT, rotational, state_term, translational

M, G = 0.74, 9.81
Z3 = (0.0, 0.0, 0.0)


def random_translational_args(rng):
    p, v = tuple(rng.normal(scale=0.3, size=3)), tuple(rng.normal(scale=0.3, size=3))
    eta = tuple(rng.normal(scale=0.1, size=3))
    rp, rv, ra = (tuple(rng.normal(scale=0.2, size=3)) for _ in range(3))
    return (p, v, eta, rp, rv, ra, 0.0, DT, False)


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs"])
def test_translational_integral_term_is_continuous_and_new_gains_act(name):
    law = translational(name)
    law.state = [0.4, -0.7, 1.3]
    args = random_translational_args(np.random.default_rng(3))
    before, out_before = state_term(law, args)[3:6], law.step(*args)
    new = replace(law.gains, c2=(4.0, 1.0, 3.0), k_integral=(0.5, 3.0, 0.8))
    law.retune(new)
    assert state_term(law, args)[3:6] == pytest.approx(before, abs=1e-12, rel=1e-12)
    # The new gains act: the proportional part changes (same state, different c2).
    assert law.step(*args)[3:6] != pytest.approx(out_before[3:6])


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs"])
def test_translational_output_is_identical_when_only_the_integral_gain_changes(name):
    """On the reference position (e1 = 0) the integral gain enters only through the integral term,
    so the whole output (U1, phi_r, theta_r, a) is unchanged at the change (1e-9)."""
    law = translational(name)
    law.state = [0.3, 0.2, -0.5]
    rp = (0.5, -0.2, 2.0)
    args = (rp, (0.1, -0.3, 0.2), (0.05, -0.02, 0.4), rp, (0.2, 0.1, -0.1), (0.3, 0.0, 0.1), 0.0, DT, False)
    out_before = law.step(*args)
    law.retune(replace(law.gains, k_integral=(0.2, 5.0, 0.75)))
    assert np.allclose(law.step(*args), out_before, rtol=0, atol=1e-9)
    assert law.state != [0.3, 0.2, -0.5]  # rescaled, not kept


def test_translational_new_integral_gain_acts_afterwards():
    law = translational("intbs_nlhinf")
    law.retune(replace(law.gains, k_integral=(3.0, 3.0, 3.0)))
    # A constant error of 0.1 m in x for 1 s: xi grows by e2 = c1 e1 per second.
    for _ in range(500):
        law.step((0.1, 0, 1), Z3, Z3, (0, 0, 1), Z3, Z3, 0.0, DT, True)
    assert law.state[0] == pytest.approx(17 * 0.1 * 1.0)
    args = ((0, 0, 1), Z3, Z3, (0, 0, 1), Z3, Z3, 0.0, DT, False)
    assert state_term(law, args)[3] == pytest.approx(-3.0 * 1.7)


def random_attitude(rng):
    eta = tuple(rng.uniform(-0.5, 0.5, size=3))
    eta_dot = tuple(rng.normal(scale=1.0, size=3))
    ref, ref_rate, ref_acc = (tuple(rng.normal(scale=0.2, size=3)) for _ in range(3))
    return (eta, eta_dot, Z3, ref, ref_rate, ref_acc, DT, False)


@pytest.mark.parametrize(
    "new",
    [
        nlhinf_gains(0.1, 3.0, 4.0, 1.5),  # lower omega3 (k_p and K_I)
        nlhinf_gains(0.1, 3.0, 9.0, 0.8),  # omega_u: the integral enters through (C + w_u^-2) k_p
        nlhinf_gains(0.2, 5.0, 20.0, 1.2),  # everything
    ],
)
def test_nlhinf_integral_torque_is_continuous_at_the_state_of_the_change(new):
    rng = np.random.default_rng(11)
    law = rotational("intbs_nlhinf")
    old = law.gains
    for _ in range(20):
        law.state = list(rng.normal(scale=0.2, size=3))
        args = random_attitude(rng)
        law.step(*args)  # the latest state
        before = state_term(law, args)
        law.retune(new)
        assert np.allclose(state_term(law, args), before, rtol=0, atol=1e-9)
        law.retune(old)  # and back


@pytest.mark.parametrize("omega_u", [3.0, 900.0])
def test_raising_omega_u_keeps_the_integrals_share_of_s_and_its_torque_shrinks(omega_u):
    """A larger w_u would need a larger integral for the same torque (and s = ... + k_p int enters
    tau through C s too): the integral's share of s is kept, so at hover its torque scales by
    w_u^2 / w_u'^2 and never grows."""
    rng = np.random.default_rng(5)
    law = rotational("intbs_nlhinf")
    old = law.gains
    hover = (Z3, Z3, Z3, Z3, Z3, Z3, DT, False)
    for _ in range(10):
        law.state = list(rng.normal(scale=0.2, size=3))
        law.step(*random_attitude(rng))  # the latest state
        share = old.k_p * np.array(law.state)
        shrunk = state_term(law, hover) * (old.omega_u / omega_u) ** 2
        law.retune(replace(old, omega_u=omega_u))
        assert np.allclose(law.gains.k_p * np.array(law.state), share, rtol=1e-12, atol=0)
        assert np.allclose(state_term(law, hover), shrunk, rtol=1e-9, atol=1e-15)
        law.retune(old)  # and back: lowering w_u keeps the (smaller) torque
        assert np.allclose(state_term(law, hover), shrunk, rtol=1e-9, atol=1e-15)


def test_nlhinf_torque_is_continuous_on_the_reference_when_the_gains_change():
    """On the reference (eta~ = eta~' = 0) the integral is the whole feedback: tau unchanged."""
    law = rotational("intbs_nlhinf")
    law.state = [0.05, -0.03, 0.02]
    eta, eta_dot = (0.1, -0.2, 0.3), (0.4, 0.1, -0.3)
    args = (eta, eta_dot, Z3, eta, eta_dot, Z3, DT, False)
    tau_before = law.step(*args)
    law.retune(nlhinf_gains(0.1, 3.0, 3.0, 1.0))
    assert np.allclose(law.step(*args), tau_before, rtol=0, atol=1e-9)
    assert law.gains.k_p == pytest.approx(30.0)  # the new gains act on an error


def test_nlhinf_retune_before_any_state_uses_the_hover_approximation():
    law = rotational("intbs_nlhinf")
    law.state = [1.0, 2.0, 3.0]
    law.retune(nlhinf_gains(0.1, 3.0, 4.5, 1.0))
    scale = (90.0 / 1.5**2) / (45.0 / 1.0**2)
    assert law.state == pytest.approx([scale, 2 * scale, 3 * scale])


def test_intbs_attitude_integral_term_is_continuous():
    law = rotational("intbs")
    rng = np.random.default_rng(2)
    law.state = list(rng.normal(scale=0.1, size=3))
    args = random_attitude(rng)
    eta = args[0]
    before = euler_torque_from_body_torque(eta[0], eta[1], state_term(law, args))
    tau_before = law.step(*args)
    # Only lambda and c2 together such that c2 lambda changes, c1 kept.
    law.retune(replace(law.gains, c2=(50.0, 90.0, 40.0), k_integral=(45.0, 60.0, 100.0)))
    after = euler_torque_from_body_torque(eta[0], eta[1], state_term(law, args))
    assert np.allclose(after, before, rtol=0, atol=1e-12)
    assert not np.allclose(law.step(*args), tau_before)  # the proportional part changes as it must


def test_command_filter_keeps_its_state_across_a_retune():
    config = load_controller("intbs_nlhinf")
    cascade = Cascade(config, load_vehicle("paper_quad"), DT)
    state = StateEstimate((0.0, 0.0, 1.0), Z3, Z3, Z3)
    ref = Reference((0.3, -0.2, 1.0), Z3, Z3, 0.0, 0.0, 0.0)
    for _ in range(20):
        cascade.step(state, ref, integrate=False)
    filt = list(cascade.filt)
    slow = replace(config, command_filter=replace(config.command_filter, natural_frequency_rad_s=20.0))
    cascade.retune(slow)
    assert list(cascade.filt) == filt
    coefficients = cf.discretise(20.0, config.command_filter.damping, DT)
    at = CASCADE_NUMBERS.filter
    assert list(cascade.K[at : at + cf.FILTER_COEFFICIENTS.size]) == pytest.approx(coefficients, abs=0)
    expected = list(filt)
    raw = cascade.step(state, ref, integrate=False).roll_pitch_raw_rad
    cf.advance(coefficients, 0, expected, *raw)
    assert list(cascade.filt) == pytest.approx(expected, abs=1e-15)


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs", "bs_nlhinf"])
def test_cascade_thrust_is_continuous_across_a_retune(name):
    """Hovering with built-up integrals: U1 does not jump when the integral gains change."""
    config = load_controller(name)
    cascade = Cascade(config, load_vehicle("paper_quad"), DT)
    ref = Reference((0.0, 0.0, 2.0), Z3, Z3, 0.0, 0.0, 0.0)
    # A steady offset below the reference (as under a sustained disturbance) builds the integrals.
    offset = StateEstimate((0.01, -0.01, 1.98), Z3, (0.01, -0.01, 0.0), Z3)
    for _ in range(1000):
        cascade.step(offset, ref)
    # Then evaluated on the reference position: U1 = m (g + a_z) / (cos phi cos theta), with a_z
    # the integral term alone.
    on_ref = StateEstimate((0.0, 0.0, 2.0), Z3, (0.01, -0.01, 0.0), Z3)
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
