"""Every failure the vehicle models, flown (the whole stack in-process, simulation time).

For each (unit, type) of :data:`quadcommon.failures.FAILURES`, a vehicle hovering at 2 m on its
EKF (GPS, or motion capture for ``vio``) is sent ``MAV_CMD_INJECT_FAILURE`` with
``SYS_FAILURE_EN`` = 1, flies on for a few seconds, and the test checks the three things a PX4 user
rehearsing the failure sees: the announcement (``Injected: gps off, all instances``), the health
report (``SYS_STATUS``: which of its bits read unhealthy, and what the vehicle said about it) and the
vehicle's reaction (it holds its position, drifts with a lying sensor, or the failsafe it triggers
and what became of the flight); then ``ok`` and the announcement of the recovery.

:data:`EXPECTED` is what the vehicle does, row by row, as the "What the vehicle does" section of
docs/failures.md describes; a row of the table without an expectation, or an expectation for a row
the table does not have, fails :func:`test_every_modelled_failure_has_an_expectation`. Every flight
starts from one copy of the same hover, so each costs only its own seconds.
"""

from __future__ import annotations

import copy
import copyreg
import math
import struct
from dataclasses import dataclass, field
from typing import NamedTuple

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from quadcommon.config import estimator_profile_for
from quadcommon.failures import FAILURES, Type, Unit, announcement
from simulator.core import SimulatorSetup
from sitl.inprocess import Lockstep

from ..stack import Gcs

pytestmark = pytest.mark.timeout(120)

# The hover is copied for every flight; pymavlink's codec keeps precompiled struct.Struct objects,
# which copy by their format string.
copyreg.pickle(struct.Struct, lambda s: (struct.Struct, (s.format,)))

HOVER_M = 2.0
ANNOUNCE_S = 0.2  # the ACK and the announcement come within a few frames
HEALTH = {  # SYS_STATUS bits by the names EXPECTED uses
    "gyro": m.MAV_SYS_STATUS_SENSOR_3D_GYRO,
    "accel": m.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
    "mag": m.MAV_SYS_STATUS_SENSOR_3D_MAG,
    "baro": m.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
    "gps": m.MAV_SYS_STATUS_SENSOR_GPS,
    "vision": m.MAV_SYS_STATUS_SENSOR_VISION_POSITION,
    "rates": m.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL,
    "attitude": m.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION,
    "heading": m.MAV_SYS_STATUS_SENSOR_YAW_POSITION,
    "altitude": m.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL,
    "position": m.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL,
    "ahrs": m.MAV_SYS_STATUS_AHRS,
    "battery": m.MAV_SYS_STATUS_SENSOR_BATTERY,
    "prearm": m.MAV_SYS_STATUS_PREARM_CHECK,
}
ESTIMATE_LOST = frozenset({"position", "altitude", "ahrs", "prearm"})  # no local position or height
POSITION_LOST = frozenset({"position", "ahrs", "prearm"})  # no horizontal position

HOLDS = "holds"  # armed, no failsafe, the true position within HOLD_M of the hover
DRIFTS = "drifts"  # armed, no failsafe, the true position moved more than HOLD_M (a lying sensor)
HOLD_M = 1.0


@dataclass(frozen=True)
class Expected:
    """What the vehicle does in a row's flight.

    ``reaction``: :data:`HOLDS`, :data:`DRIFTS`, or the first failsafe action announced
    ("Failsafe activated: ... triggering Descend" -> ``"Descend"``; the battery's and the link's own
    words for theirs); ``unhealthy``: the SYS_STATUS bits (:data:`HEALTH` names) that read enabled
    but unhealthy at the end, exactly; ``said``: what the vehicle says besides the announcement (each
    must appear; a row that holds may say nothing else); ``armed``: at the end of the flight;
    ``params``: set before the injection; ``seconds``: flown after it; ``instance``: param3.
    """

    reaction: str
    unhealthy: frozenset[str] = frozenset()
    said: tuple[str, ...] = ()
    armed: bool = True
    params: dict[str, float] = field(default_factory=dict)
    seconds: float = 4.0
    instance: int = 0


def stream_stopped(what: str) -> str:
    return f"sensor stream stopped: {what} silent for 1.0 s"


IMU_STOPPED = Expected(
    "Terminate",
    frozenset({"gyro", "accel", "rates", "attitude", "heading"}) | ESTIMATE_LOST,
    (stream_stopped("IMU (HIL_SENSOR)"), "flight terminated: motors off"),
    armed=False,
    seconds=3.0,
)
NO_POSITION = "no global position for AUTO.LOITER"
NO_ALTITUDE = "no altitude estimate for AUTO.LOITER"
LOW_BATTERY = {"COM_LOW_BAT_ACT": 3.0}  # critical: return; emergency: land

EXPECTED: dict[tuple[Unit, Type], Expected] = {
    # An IMU that stops: no angular velocity, no mode can run: Terminate (PX4's behaviour).
    (Unit.gyro, Type.off): IMU_STOPPED,
    (Unit.accel, Type.off): IMU_STOPPED,
    # A gyro that repeats itself is called stuck; the attitude it integrates is wrong, the position
    # estimate diverges and the vehicle comes down by the fallback chain (Land, then Descend).
    (Unit.gyro, Type.stuck): Expected(
        "Land", frozenset({"gyro"}) | ESTIMATE_LOST, (NO_POSITION,), seconds=6.0
    ),
    # Garbage, a too-slow or an offset gyro: the estimate is lost, not the sensor's health. (A step
    # of 0.1 rad/s in every axis is not learnt as a bias before the estimate is lost.)
    (Unit.gyro, Type.garbage): Expected(
        "Land", frozenset({"gps"}) | POSITION_LOST, (NO_POSITION,), seconds=6.0
    ),
    (Unit.gyro, Type.wrong): Expected("Descend", frozenset({"ahrs", "prearm"}), (NO_POSITION,), seconds=8.0),
    (Unit.gyro, Type.slow): Expected(
        "Descend", frozenset({"gps"}) | ESTIMATE_LOST, (NO_POSITION,), seconds=6.0
    ),
    (Unit.gyro, Type.intermittent): Expected(HOLDS),
    # A stuck accelerometer is seen once the vehicle's tilt or speed changes; the height goes first.
    (Unit.accel, Type.stuck): Expected(
        "Descend", frozenset({"accel", "ahrs", "altitude", "prearm"}), (NO_ALTITUDE,), seconds=8.0
    ),
    (Unit.accel, Type.garbage): Expected(
        "Descend", frozenset({"gps", "ahrs", "prearm"}), (NO_POSITION,), seconds=6.0
    ),
    # +0.5 m/s^2 on every axis: learnt as a bias too slowly to hold the position; nothing reports it.
    (Unit.accel, Type.wrong): Expected(DRIFTS, seconds=8.0),
    (Unit.accel, Type.slow): Expected(
        "Descend", frozenset({"gps"}) | ESTIMATE_LOST, (NO_POSITION,), seconds=6.0
    ),
    (Unit.accel, Type.intermittent): Expected(HOLDS),
    # The magnetometer: heading kept (GPS velocity, the last fusion); only its silence is reported.
    (Unit.mag, Type.off): Expected(HOLDS, frozenset({"mag"}), (stream_stopped("magnetometer (HIL_SENSOR)"),)),
    **{
        (Unit.mag, t): Expected(HOLDS)
        for t in (Type.stuck, Type.garbage, Type.wrong, Type.slow, Type.delayed, Type.intermittent)
    },
    # The barometer: the height from GNSS alongside; only its silence is reported (a stuck one once
    # the height changed 0.5 m, which a hover does not do).
    (Unit.baro, Type.off): Expected(HOLDS, frozenset({"baro"}), (stream_stopped("barometer (HIL_SENSOR)"),)),
    **{
        (Unit.baro, t): Expected(HOLDS)
        for t in (Type.stuck, Type.garbage, Type.wrong, Type.slow, Type.delayed, Type.intermittent)
    },
    # GNSS: lost -> dead reckoning for EKF2_NOAID_TOUT, then Descend (PX4's "land on GPS lost").
    (Unit.gps, Type.off): Expected(
        "Descend",
        frozenset({"gps"}) | POSITION_LOST,
        (stream_stopped("GPS (HIL_GPS)"), NO_POSITION),
        seconds=8.0,
    ),
    (Unit.gps, Type.garbage): Expected(
        "Descend", frozenset({"gps"}) | POSITION_LOST, (NO_POSITION,), seconds=8.0
    ),
    # A fix 20 m north that looks as good as the truth: the filter follows it, and so does the
    # vehicle (it flies 20 m south to hold where it believes it is), as a PX4 vehicle does.
    # (The jump fails the innovation gate for about 10 s first.)
    (Unit.gps, Type.wrong): Expected(DRIFTS, seconds=12.0),
    # A fix that repeats itself, velocity included, pins the estimate while the vehicle drifts: no
    # check reports it (PX4's GNSS checks look at the receiver's own figures, which stay good).
    (Unit.gps, Type.stuck): Expected(DRIFTS, seconds=8.0),
    **{(Unit.gps, t): Expected(HOLDS) for t in (Type.slow, Type.delayed, Type.intermittent)},
    # Motion capture: lost -> Descend; garbage poses lose the position for a while (Descend), until
    # the filter holds on without them.
    (Unit.vio, Type.off): Expected(
        "Descend",
        frozenset({"vision"}) | POSITION_LOST,
        (stream_stopped("vision (VISION_POSITION_ESTIMATE)"), NO_POSITION),
        seconds=8.0,
    ),
    (Unit.vio, Type.garbage): Expected("Descend", POSITION_LOST, (NO_POSITION,), seconds=6.0),
    **{
        (Unit.vio, t): Expected(HOLDS)
        for t in (Type.stuck, Type.wrong, Type.slow, Type.delayed, Type.intermittent)
    },
    # Motor 1 (right): a quadrotor has no redundancy for a rotor off or stuck (neither has PX4's); it
    # loses its yaw, then its estimate, and comes down.
    (Unit.motor, Type.off): Expected(
        "Descend", ESTIMATE_LOST | {"gps"}, (NO_ALTITUDE,), seconds=8.0, instance=1
    ),
    (Unit.motor, Type.stuck): Expected(
        "Descend", ESTIMATE_LOST | {"gps"}, (NO_ALTITUDE,), seconds=8.0, instance=1
    ),
    (Unit.motor, Type.wrong): Expected(HOLDS, instance=1),  # half its thrust: the cascade makes up for it
    # The battery monitor (COM_LOW_BAT_ACT 3: critical returns, emergency lands).
    (Unit.battery, Type.off): Expected(
        "Failsafe activated due to emergency battery level, triggering land",
        frozenset({"battery"}),
        said=(
            "Low battery level, return advised",
            "Failsafe activated due to critical battery level, triggering RTL",
        ),
        params=LOW_BATTERY,
        seconds=8.0,
    ),
    (Unit.battery, Type.stuck): Expected(HOLDS, params=LOW_BATTERY),  # the reading it had: a full pack
    (Unit.battery, Type.garbage): Expected(
        HOLDS,
        frozenset({"battery"}),
        ("Battery unhealthy: no battery report for 5 s",),
        params=LOW_BATTERY,
        seconds=6.0,
    ),
    (Unit.battery, Type.wrong): Expected(
        HOLDS, frozenset({"battery"}), ("Battery 1: over voltage. Land now!",), params=LOW_BATTERY
    ),
    # No sticks were ever in use: there is no manual control to lose (PX4 acts only on a loss of
    # sticks it had; tests/autopilot/mavlink/test_failure_injection.py flies that case).
    (Unit.rc_signal, Type.off): Expected(HOLDS),
    # The ground station's heartbeats are dropped: data-link loss after COM_DL_LOSS_T, NAV_DLL_ACT 3 lands.
    (Unit.mavlink_signal, Type.off): Expected(
        "GCS connection lost: no heartbeat for 5.0 s (NAV_DLL_ACT 3): landing",
        params={"NAV_DLL_ACT": 3.0, "COM_DL_LOSS_T": 5.0},
        seconds=6.0,
    ),
}

PAIRS = [(unit, failure_type) for unit, model in FAILURES.items() for failure_type in model.effects]


class Outcome(NamedTuple):
    """What one flight showed."""

    answer: int  # COMMAND_ACK result of the injection
    said: str  # every STATUSTEXT after the injection, joined
    unhealthy: frozenset[str]
    armed: bool
    moved_m: float  # the true horizontal and vertical distance from the hover at the end


def _hover(sensors: str) -> tuple[Lockstep, Gcs]:
    sim = SimulatorSetup.load(scenario="hover", sensors=sensors)
    ap = AutopilotSetup(
        sim.sitl,
        sim.vehicle,
        load_controller("intbs_nlhinf"),
        default_remotes=False,
        estimator="ekf",
        estimator_profile=estimator_profile_for(sensors),
    )
    stack = Lockstep(sim, ap)
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    end = stack.t + 20.0
    while gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result != m.MAV_RESULT_ACCEPTED:
        assert stack.t < end, "the filter did not align and converge"
        _fly(gcs, 0.5)
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + HOVER_M).result == 0
    gcs.wait(
        lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > HOVER_M - 0.1,
        sim_timeout=20.0,
        what="takeoff",
    )
    _fly(gcs, 1.0)
    return stack, gcs


def _fly(gcs: Gcs, seconds: float) -> None:
    """Fly on for ``seconds``, the ground station's heartbeat every 0.5 s (a link to lose)."""
    end = gcs.sim_time + seconds
    next_heartbeat = gcs.sim_time
    while gcs.sim_time < end:
        if gcs.sim_time >= next_heartbeat:
            gcs.conn.mav.heartbeat_send(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            next_heartbeat += 0.5
        gcs.poll()


@pytest.fixture(scope="module")
def hovers() -> dict[str, tuple[Lockstep, Gcs]]:
    return {"gps": _hover("gps"), "mocap": _hover("mocap")}


def _texts(gcs: Gcs, since: int) -> str:
    return "".join(gcs.statustext[since:])


def fly_failure(hovers, unit: Unit, failure_type: Type, expected: Expected) -> tuple[Outcome, Lockstep, Gcs]:
    stack, gcs = copy.deepcopy(hovers["mocap" if unit == Unit.vio else "gps"])
    for name, value in expected.params.items():
        stack.autopilot.params.set(name, value)
    hover = stack.sim.truth_row[1:4]
    since = len(gcs.statustext)
    answer = gcs.command(m.MAV_CMD_INJECT_FAILURE, unit, failure_type, expected.instance).result
    _fly(gcs, expected.seconds)
    status = gcs.last["SYS_STATUS"]
    bad = status.onboard_control_sensors_enabled & ~status.onboard_control_sensors_health
    unhealthy = frozenset(name for name, bit in HEALTH.items() if bad & bit)
    moved = math.dist(hover, stack.sim.truth_row[1:4])
    return Outcome(answer, _texts(gcs, since), unhealthy, gcs.armed, moved), stack, gcs


def test_every_modelled_failure_has_an_expectation():
    assert sorted(EXPECTED) == sorted(PAIRS)
    assert len(PAIRS) == sum(len(model.effects) for model in FAILURES.values())


@pytest.mark.parametrize(("unit", "failure_type"), PAIRS, ids=[f"{u.name}-{t.name}" for u, t in PAIRS])
def test_each_failure_is_announced_reported_and_answered_as_px4_does(hovers, unit, failure_type):
    expected = EXPECTED[unit, failure_type]
    outcome, stack, gcs = fly_failure(hovers, unit, failure_type, expected)
    assert outcome.answer == m.MAV_RESULT_ACCEPTED
    injected = announcement(unit, failure_type, expected.instance)
    assert outcome.said.startswith(injected), outcome.said
    rest = outcome.said[len(injected) :]
    for text in expected.said:
        assert text in rest, (text, rest)
    assert outcome.unhealthy == expected.unhealthy, outcome
    assert outcome.armed == expected.armed, outcome
    if expected.reaction in (HOLDS, DRIFTS):
        assert "Failsafe activated" not in rest, rest
        if expected.reaction == HOLDS:
            assert rest == "".join(expected.said), rest  # nothing else said
            assert outcome.moved_m < HOLD_M, outcome
        else:
            assert outcome.moved_m > 5 * HOLD_M, outcome
    elif expected.reaction in ("Land", "Descend", "Terminate"):
        first = rest.split("Failsafe activated: ", 1)[1]
        assert first.split(", triggering ", 1)[1].startswith(expected.reaction), rest
    else:
        assert expected.reaction in rest, rest
    # The recovery: accepted and announced in PX4's words.
    since = len(gcs.statustext)
    assert (
        gcs.command(m.MAV_CMD_INJECT_FAILURE, unit, Type.ok, expected.instance).result
        == m.MAV_RESULT_ACCEPTED
    )
    _fly(gcs, ANNOUNCE_S)
    assert _texts(gcs, since).startswith(announcement(unit, Type.ok, expected.instance))
    assert stack.autopilot.info()["failures"]["active"] == {}
