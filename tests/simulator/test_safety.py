"""The simulator's emergency descent (autopilot lost): lands level, near where it was lost, on its own."""

import math
from dataclasses import replace

import pytest

from quadcommon.config import apply_uncertainty, load_scenario, load_vehicle
from simulator.dynamics.plant import make_plant
from simulator.safety import MOTORS_OFF, emergency_descent, normalise, touched_down

DT = 0.001


def vehicle(mode: str):
    v = load_vehicle("paper_quad")
    if mode == "rotors":
        v = replace(v, actuation=replace(v.actuation, mode="rotors"))
    return apply_uncertainty(v, load_scenario("helix"))  # +30 % mass and inertia: the truth differs


def descend(v, position, euler, velocity, rates, max_s=20.0):
    """Fly the law until touchdown; returns (touchdown time, trace of (t, truth))."""
    plant = make_plant(v, DT)
    plant.reset(position, euler, velocity, rates)
    trace = []
    t = 0.0
    for _ in range(int(max_s / DT)):
        truth = plant.truth()
        trace.append((t, truth))
        if touched_down(truth):
            return t, trace, plant
        plant.set_actuator_controls(emergency_descent(truth, v).controls)
        plant.step()
        t += DT
    raise AssertionError(f"no touchdown within {max_s} s: {trace[-1][1].position_m}")


@pytest.mark.parametrize("mode", ["wrench", "rotors"])
def test_lands_level_near_where_it_was_lost(mode):
    v = vehicle(mode)
    start = (1.0, 2.0, 3.0)
    t_down, trace, plant = descend(v, start, (0.2, -0.15, 0.7), (1.0, -0.5, 0.3), (0.5, -0.3, 0.2))
    assert 4.0 < t_down < 12.0  # 3 m at about 0.5 m/s
    # Levelled within a second, then it stays level (tilt only to damp the drift).
    tilts = [max(abs(tr.euler_rad[0]), abs(tr.euler_rad[1])) for t, tr in trace if t > 1.0]
    assert max(tilts) < 0.1
    # Descends at about 0.5 m/s once settled.
    mid = [tr.velocity_m_s[2] for t, tr in trace if 2.0 < t < t_down - 0.5]
    assert sum(mid) / len(mid) == pytest.approx(-0.5, abs=0.05)
    # Drift damped: lands within a couple of metres of where it was lost (it was moving at 1.1 m/s).
    final = trace[-1][1]
    assert math.dist(final.position_m[:2], start[:2]) < 2.0
    # Motors off on the ground: it rests there.
    for _ in range(500):
        plant.set_actuator_controls(MOTORS_OFF)
        plant.step()
    rest = plant.truth()
    assert rest.on_ground and rest.position_m[2] == pytest.approx(0.0, abs=1e-9)


def test_on_the_ground_counts_as_touched_down():
    v = vehicle("wrench")
    plant = make_plant(v, DT)
    plant.reset((0.0, 0.0, 0.0), (0.0, 0.0, 0.3))
    plant.step()
    assert touched_down(plant.truth())
    plant.reset((0.0, 0.0, 0.5), (0.0, 0.0, 0.3))
    assert not touched_down(plant.truth())


def test_thrust_moment_about_the_offset_centre_of_mass_is_cancelled():
    """Level and at rest, the only torque asked for is r_G x (0, 0, U1)."""
    v = vehicle("wrench")
    plant = make_plant(v, DT)
    plant.reset((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    cmd = emergency_descent(plant.truth(), v)
    rx, ry, _ = v.plant.com_offset_m
    assert cmd.torque_body_n_m == pytest.approx((ry * cmd.thrust_n, -rx * cmd.thrust_n, 0.0), abs=1e-12)
    # At rest it asks for more than hover thrust minus the descent (k_z * 0.5 m/s below g).
    g = v.nominal.gravity_m_s2
    assert cmd.thrust_n == pytest.approx(v.plant.mass_kg * (g - 2.0 * 0.5))


def test_rotor_mixer_inverts_the_plant_allocation():
    v = vehicle("rotors")
    rot, arm = v.rotors, v.nominal.arm_length_m
    thrust, torque = 8.0, (0.05, -0.08, 0.01)
    controls = normalise(thrust, torque, v)
    sq = [(c * rot.speed_max_rad_s) ** 2 for c in controls]
    b, d = rot.thrust_coefficient_n_s2, rot.drag_coefficient_n_m_s2
    assert b * sum(sq) == pytest.approx(thrust)
    assert arm * b * (sq[3] - sq[1]) == pytest.approx(torque[0])
    assert arm * b * (sq[2] - sq[0]) == pytest.approx(torque[1])
    assert d * (-sq[0] + sq[1] - sq[2] + sq[3]) == pytest.approx(torque[2])


def test_wrench_controls_are_normalised_and_saturated():
    v = vehicle("wrench")
    c = normalise(1000.0, (0.75, -10.0, 0.0), v)
    assert c == (1.0, 0.5, -1.0, 0.0)
