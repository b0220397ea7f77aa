"""STABILIZED, ALTCTL, ACRO (and MANUAL) flown from MANUAL_CONTROL, for the paper's cascade, the
integral backstepping one and the baselines px4_pid and se3: the attitude, climb rate and body
rates follow the sticks within the tolerances docs/manual-control.md states; takeoff and landing
on the throttle. In simulation time, the whole stack in-process (truth from the simulator core,
the commanded U1 from the autopilot's rows)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import MAIN_ACRO, MAIN_ALTCTL, MAIN_MANUAL, MAIN_STABILIZED, FlightMode
from autopilot.guidance.sticks import stick_tilt, throttle_curve
from quadcommon.bus_records import CONTROLLER_FIELDS
from quadcommon.rigid_body import body_rates_from_euler_rates
from tests.autopilot.mavlink.test_manual import airborne, enter_mode, hold_sticks, texts, truth
from tests.sitl.test_params_failsafes import INT32, param_set
from tests.stack import Gcs, make_stack

DEG = math.radians(1.0)
TILT_MAX = math.radians(35.0)  # MPC_MAN_TILT_MAX
YAW_RATE_MAX = math.radians(150.0)  # MPC_MAN_Y_MAX
ACRO_RATE_MAX = math.radians(100.0)  # MC_ACRO_R_MAX, _P_MAX, _Y_MAX
U1_MAX = 28.0  # config/vehicle/paper_quad.toml thrust_max_n
HOVER = 0.259  # MPC_THR_HOVER: the paper quad's m g / U1_max
U1 = CONTROLLER_FIELDS.index("U1_n")


class Tolerances(NamedTuple):
    """The tolerances of docs/manual-control.md, "How closely the modes follow the sticks"."""

    attitude: float  # rad, roll, pitch: 0.3 s after a step of the sticks
    rate: float  # rad/s, body rates (ACRO: 0.2 s after a step), yaw rate (0.5 s after)
    climb: float  # m/s, 1 s after a step of the throttle
    hold: float  # m, altitude held in ALTCTL while tilting


PAPER = Tolerances(attitude=0.5 * DEG, rate=1.0 * DEG, climb=0.02, hold=0.02)
TOLERANCES = {
    "intbs_nlhinf": PAPER,
    "intbs": PAPER,
    # PX4's gains on the paper's vehicle: slower attitude and rate loops, an attitude P without
    # roll/pitch rate feed-forward (ACRO's rates lag), and U1 projected on the axis the position
    # law commands rather than the sticks' tilt (ALTCTL sinks while tilted until the velocity
    # loop makes it up; the integral it wound up then unwinds into the next climb-rate step).
    "px4_pid": Tolerances(attitude=7.0 * DEG, rate=30.0 * DEG, climb=0.15, hold=0.12),
    # SE(3): U1 is the desired force on the body z axis, not compensated for the sticks' tilt.
    "se3": PAPER._replace(hold=0.05),
}
CONTROLLERS = list(TOLERANCES)
ATTITUDE_TOL, RATE_TOL = PAPER.attitude, PAPER.rate  # the tests flown with the paper's cascade only


class Recorder:
    """Truth samples (t, position, velocity, Euler angles, body rates) after each stick message."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, ...]] = []

    def __call__(self, stack) -> None:
        s = truth(stack)
        rates = body_rates_from_euler_rates(s.euler_rad[0], s.euler_rad[1], s.euler_rates_rad_s)
        self.rows.append((stack.t, *s.position_m, *s.velocity_m_s, *s.euler_rad, *rates))

    def window(self, t0: float, t1: float) -> np.ndarray:
        rows = np.asarray(self.rows)
        return rows[(rows[:, 0] >= t0 - 1e-9) & (rows[:, 0] <= t1 + 1e-9)]

    def step(self, stack, gcs, seconds: float, settle: float, **sticks) -> np.ndarray:
        """Hold the sticks for ``seconds`` (at 50 Hz); the samples from ``settle`` s on."""
        t0 = stack.t
        hold_sticks(stack, gcs, seconds, every_s=0.02, sample=self, **sticks)
        return self.window(t0 + settle, stack.t)


X, Y, Z, VX, VY, VZ, PHI, THETA, PSI, P, Q, R = range(1, 13)


def worst(values: np.ndarray, target: float) -> float:
    assert len(values) > 5
    return float(np.max(np.abs(values - target)))


@pytest.mark.timeout(120)
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_stabilized_sticks_to_attitude_throttle_to_thrust_yaw_to_rate(controller):
    tol = TOLERANCES[controller]
    stack, gcs = airborne(6.0, controller)
    enter_mode(stack, gcs, MAIN_STABILIZED)
    rec = Recorder()
    level = rec.step(stack, gcs, 1.0, 0.5)
    assert worst(level[:, PHI], 0.0) < tol.attitude and worst(level[:, THETA], 0.0) < tol.attitude
    # Pitch forward half, roll right 30 %, throttle 56 %: the tilt and the thrust the sticks give.
    tilted = rec.step(stack, gcs, 1.0, 0.3, x=500, y=300, z=560)
    phi, theta = stick_tilt(0.5, -0.3, TILT_MAX)  # (forward, left): the roll stick right is -left
    assert phi > 0.0 and theta > 0.0  # right wing down, nose down
    assert worst(tilted[:, PHI], phi) < tol.attitude and worst(tilted[:, THETA], theta) < tol.attitude
    u1 = np.asarray(stack.controller_rows)[-40:, U1]
    expected = throttle_curve(0.12, HOVER, 0.08, 1.0, True) * U1_MAX
    assert np.allclose(u1, expected, rtol=1e-6)  # the throttle is the thrust: no altitude loop
    assert truth(stack).velocity_m_s[0] > 1.0 and truth(stack).velocity_m_s[1] < -0.3  # forward, right
    rec.step(stack, gcs, 1.0, 0.0, x=-500, y=-300, z=560)  # brake
    # Yaw stick 40 % clockwise: the yaw rate it commands (negative in the paper's frame).
    turning = rec.step(stack, gcs, 1.5, 0.5, r=400)
    assert worst(turning[:, R], -0.4 * YAW_RATE_MAX) < tol.rate
    assert stack.autopilot.commander.mode == FlightMode.STABILIZED and truth(stack).position_m[2] > 3.0


@pytest.mark.timeout(120)
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_altctl_throttle_to_climb_rate_altitude_held_while_the_sticks_tilt(controller):
    tol = TOLERANCES[controller]
    stack, gcs = airborne(4.0, controller)
    enter_mode(stack, gcs, MAIN_ALTCTL)
    rec = Recorder()
    rec.step(stack, gcs, 2.0, 0.0)
    climbing = rec.step(stack, gcs, 3.0, 1.0, z=800)  # throttle 80 %: (0.6 - 0.1) / 0.9 of 1.5 m/s
    assert worst(climbing[:, VZ], (0.6 - 0.1) / 0.9 * 1.5) < tol.climb
    rec.step(stack, gcs, 3.0, 0.0)  # centred: the climb stops, the altitude is held
    z0 = truth(stack).position_m[2]
    tilted = rec.step(stack, gcs, 2.0, 0.0, x=600)  # pitch 60 %: tilt forward, altitude held
    assert worst(tilted[:, Z], z0) < tol.hold
    theta = stick_tilt(0.6, 0.0, TILT_MAX)[1]
    assert worst(tilted[tilted[:, 0] > tilted[0, 0] + 0.3, THETA], theta) < tol.attitude
    assert truth(stack).velocity_m_s[0] > 2.0  # it flies forward as it would tilted
    descending = rec.step(stack, gcs, 3.0, 1.0, z=200)  # throttle 20 %: down at (0.6-0.1)/0.9 of 1 m/s
    assert worst(descending[:, VZ], -(0.6 - 0.1) / 0.9 * 1.0) < tol.climb
    assert stack.autopilot.commander.mode == FlightMode.ALTCTL


@pytest.mark.timeout(120)
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_acro_sticks_to_body_rates_centred_holds_the_attitude(controller):
    tol = TOLERANCES[controller]
    stack, gcs = airborne(8.0, controller)
    enter_mode(stack, gcs, MAIN_ACRO)
    rec = Recorder()
    rec.step(stack, gcs, 1.0, 0.0, z=520)
    pitching = rec.step(stack, gcs, 0.6, 0.2, x=500, z=520)  # pitch forward at half MC_ACRO_P_MAX
    assert worst(pitching[:, Q], 0.5 * ACRO_RATE_MAX) < tol.rate
    held = rec.step(stack, gcs, 1.0, 0.3, z=560)  # centred: no rotation, the attitude stays
    assert worst(held[:, Q], 0.0) < tol.rate and worst(held[:, P], 0.0) < tol.rate
    assert held[0, THETA] > 20.0 * DEG and worst(held[:, THETA], held[0, THETA]) < tol.attitude
    rec.step(stack, gcs, 0.6, 0.0, x=-500, z=520)  # and back
    rolling = rec.step(stack, gcs, 0.6, 0.2, y=400, z=520)  # roll right: +p
    assert worst(rolling[:, P], 0.4 * ACRO_RATE_MAX) < tol.rate
    rec.step(stack, gcs, 0.6, 0.0, y=-400, z=520)
    yawing = rec.step(stack, gcs, 1.0, 0.2, r=500, z=520)  # clockwise: -r in the paper's frame
    assert worst(yawing[:, R], -0.5 * ACRO_RATE_MAX) < tol.rate
    assert stack.autopilot.commander.mode == FlightMode.ACRO and truth(stack).position_m[2] > 2.0


def test_acro_cannot_flip_its_attitude_stops_at_the_tilt_limit():
    stack, gcs = airborne(8.0)
    assert param_set(gcs, "ACRO_TILT_LIM", 30.0).param_value == pytest.approx(30.0)
    enter_mode(stack, gcs, MAIN_ACRO)
    rec = Recorder()
    over = rec.step(stack, gcs, 0.8, 0.0, x=1000, z=540)  # 100 deg/s for 0.8 s: 80 deg asked
    assert np.max(over[:, THETA]) < 31.0 * DEG  # stopping from 100 deg/s overshoots < 1 deg
    assert worst(over[-10:, THETA], 30.0 * DEG) < ATTITUDE_TOL and worst(over[-10:, Q], 0.0) < RATE_TOL
    rec.step(stack, gcs, 0.3, 0.0, x=-1000, z=540)
    assert stack.autopilot.commander.mode == FlightMode.ACRO


def test_manual_flies_as_stabilized():
    stack, gcs = airborne(6.0)
    enter_mode(stack, gcs, MAIN_MANUAL)
    rec = Recorder()
    rec.step(stack, gcs, 0.5, 0.0)
    tilted = rec.step(stack, gcs, 1.0, 0.3, x=400, z=540)
    assert worst(tilted[:, THETA], stick_tilt(0.4, 0.0, TILT_MAX)[1]) < ATTITUDE_TOL
    u1 = np.asarray(stack.controller_rows)[-20:, U1]
    assert np.allclose(u1, throttle_curve(0.08, HOVER, 0.08, 1.0, True) * U1_MAX, rtol=1e-6)


def throttle_for(main: int, stack, climb: float) -> int:
    """The throttle stick (MANUAL_CONTROL z) for a climb rate: ALTCTL's stick asks for it; in
    STABILIZED the throttle is thrust, so a pilot flies the climb rate (proportionally)."""
    if main == MAIN_ALTCTL:
        up = climb / 1.5 if climb > 0.0 else climb / 1.0  # MPC_Z_VEL_MAX_UP / _DN
        up = math.copysign(0.1 + 0.9 * abs(up), up) if up else 0.0  # past the deadzone
    else:
        up = 0.5 * (climb - truth(stack).velocity_m_s[2])
    return int(round(500 + 500 * min(max(up, -1.0), 1.0)))


@pytest.mark.timeout(120)
@pytest.mark.parametrize("main", [MAIN_ALTCTL, MAIN_STABILIZED])
def test_takeoff_and_landing_on_the_throttle(main):
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    enter_mode(stack, gcs, main)  # selected on the ground, the sticks streaming
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    hold_sticks(stack, gcs, 1.0, z=600)  # throttle 60 %: below PX4's 62.5 % takeoff threshold
    assert truth(stack).position_m[2] < 0.01 and stack.autopilot.commander.phase.name == "IDLE"
    hold_sticks(stack, gcs, 0.2, z=700)  # 70 %: takes off
    for _ in range(30):  # climb at 1 m/s for 3 s
        hold_sticks(stack, gcs, 0.1, z=throttle_for(main, stack, 1.0))
    assert truth(stack).position_m[2] > 1.5 and stack.autopilot.commander.phase.name == "MANUAL"
    assert "taking off on the sticks" in texts(gcs) or gcs.wait(
        lambda g: "taking off on the sticks" in texts(g), sim_timeout=1.0, what="the takeoff notice") is None
    # Down at 0.7 m/s; on the ground the throttle goes to the bottom: touchdown, disarmed after
    # COM_DISARM_LAND (2 s).
    for _ in range(200):
        on_ground = truth(stack).position_m[2] < 0.02
        hold_sticks(stack, gcs, 0.1, z=0 if on_ground else throttle_for(main, stack, -0.7))
        if not stack.autopilot.commander.armed:
            break
    assert not stack.autopilot.commander.armed, "still armed"
    gcs.wait(lambda g: "landing detected" in texts(g) and "landed: disarmed" in texts(g), sim_timeout=2.0,
             what="the landing")  # fmt: skip
    assert truth(stack).position_m[2] < 0.01
    assert stack.autopilot.commander.mode == FlightMode.from_px4(main, 0)  # the mode stays selected
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 4, 3).result == m.MAV_RESULT_ACCEPTED  # and can go


def test_acro_rates_follow_the_parameters():
    stack, gcs = airborne(8.0)
    assert param_set(gcs, "MC_ACRO_P_MAX", 200.0).param_value == pytest.approx(200.0)
    assert param_set(gcs, "MC_ACRO_EXPO", 1.0).param_value == pytest.approx(1.0)  # cubic
    assert param_set(gcs, "MPC_THR_CURVE", 1, INT32) is not None
    enter_mode(stack, gcs, MAIN_ACRO)
    rec = Recorder()
    rec.step(stack, gcs, 0.5, 0.0, z=540)
    pitching = rec.step(stack, gcs, 0.4, 0.2, x=500, z=540)
    assert worst(pitching[:, Q], 0.125 * math.radians(200.0)) < RATE_TOL  # 0.5^3 of 200 deg/s
