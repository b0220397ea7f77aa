"""The cascade's overrides, which the manual modes fly: the sticks' tilt before the command filter,
a whole attitude reference, a thrust; the rotational law tracks whatever reaches it."""

from __future__ import annotations

import copy

import pytest

from autopilot.control.cascade import AttitudeReference, Cascade
from autopilot.control.config import load_controller
from autopilot.records import StateEstimate
from quadcommon.config import load_vehicle
from quadcommon.trajectories import Reference

HOVER_REF = Reference((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
AT_REF = StateEstimate((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


@pytest.fixture(params=["intbs_nlhinf", "intbs", "bs_nlhinf", "px4_pid", "se3"])
def cascade(request) -> Cascade:
    return Cascade(load_controller(request.param), load_vehicle("paper_quad"), 0.002)


@pytest.fixture(params=["intbs_nlhinf", "intbs", "bs_nlhinf"])
def backstepping(request) -> Cascade:
    """The backstepping cascades, whose six law states (integrals) the last test reads by index."""
    return Cascade(load_controller(request.param), load_vehicle("paper_quad"), 0.002)


def test_roll_pitch_reaches_the_attitude_law_through_the_command_filter(cascade):
    for _ in range(500):  # 1 s: the 60 rad/s filter has settled
        out = cascade.step(AT_REF, HOVER_REF, roll_pitch=(0.2, -0.1))
    assert out.roll_pitch_raw_rad == (0.2, -0.1)
    assert out.euler_ref_rad[0] == pytest.approx(0.2, abs=1e-6)
    assert out.euler_ref_rad[1] == pytest.approx(-0.1, abs=1e-6)
    assert out.torque_euler_n_m[1] < 0.0 < out.torque_euler_n_m[0]  # level vehicle: roll up, pitch down


def test_an_attitude_reference_replaces_the_filter_and_the_yaw(cascade):
    att = AttitudeReference((0.0, 0.0, 0.3), (0.0, 0.0, 0.5), (0.0, 0.0, 0.0))
    out = cascade.step(AT_REF, HOVER_REF, attitude=att)
    assert out.euler_ref_rad == (0.0, 0.0, 0.3) and out.euler_rate_ref_rad_s == (0.0, 0.0, 0.5)
    assert out.torque_euler_n_m[2] > 0.0  # yaw towards +0.3 rad


def test_a_thrust_replaces_the_laws_and_is_saturated(cascade):
    assert cascade.step(AT_REF, HOVER_REF, thrust_n=3.0).thrust_n == pytest.approx(3.0)
    assert cascade.step(AT_REF, HOVER_REF, thrust_n=1e6).thrust_n == pytest.approx(28.0)


def test_the_overrides_leave_the_compiled_path_in_step_with_the_laws(backstepping):
    """An overridden step and then plain steps: the laws' states carry across (no reset)."""
    cascade = backstepping
    for _ in range(50):
        cascade.step(AT_REF._replace(position_m=(0.0, 0.0, 0.9)), HOVER_REF)
    names, before = cascade.law_states()
    assert len(names) == len(before) == 6 and before[2] != 0.0 or cascade.name == "bs_nlhinf"
    cascade.step(AT_REF._replace(position_m=(0.0, 0.0, 0.9)), HOVER_REF, thrust_n=7.0)
    _, after = cascade.law_states()
    assert after[2] == pytest.approx(before[2], rel=0.05)


def test_a_copied_cascade_flies_on_its_own_buffer(cascade):
    """A deep copy (the failure flights copy whole stacks) reads and writes its own buffer: its
    overrides reach its step, its outputs come from its step, the original is untouched."""
    twin = copy.deepcopy(cascade)
    out = twin.step(AT_REF, HOVER_REF, thrust_n=3.0)
    assert out.thrust_n == pytest.approx(3.0)
    assert list(twin.out) == [*out.actuator_controls, *out.rotor_speeds_rad_s]
    assert not cascade.given.any() and not cascade.out.any()
