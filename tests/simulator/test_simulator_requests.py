"""Requests to the simulator in the lockstep answer (quadcommon.wire): taken from the answer the
simulator applies, once, from the next frame; anything hostile refused and counted, never raised."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from quadcommon import wire
from quadcommon.failures import Type, Unit
from simulator.core import SimulatorCore, SimulatorSetup

pytestmark = pytest.mark.timeout(60)

SYSTEM = wire.system_id(0)


def packer(system: int = SYSTEM, component: int = wire.AUTOPILOT_COMPONENT_ID) -> m.MAVLink:
    return m.MAVLink(None, srcSystem=system, srcComponent=component)


def controls(core: SimulatorCore) -> bytes:
    flags = wire.HIL_FLAG_LOCKSTEP | wire.HIL_FLAG_WRENCH
    mode = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    msg = m.MAVLink_hil_actuator_controls_message(core.time_usec, [0.0] * 16, mode, flags)
    return msg.pack(packer())


def inject(unit: float, failure_type: float, instance: float = 0.0, *, mav: m.MAVLink | None = None,
           target: tuple[int, int] = (SYSTEM, wire.SIMULATOR_COMPONENT_ID),
           command: int = m.MAV_CMD_INJECT_FAILURE, effectiveness: float = 1.0) -> bytes:  # fmt: skip
    msg = m.MAVLink_command_long_message(*target, command, 0, unit, failure_type, instance, effectiveness,
                                         0, 0, 0)  # fmt: skip
    return msg.pack(mav or packer())


def param_set(name: bytes, value: float, *,
              target: tuple[int, int] = (SYSTEM, wire.SIMULATOR_COMPONENT_ID)) -> bytes:  # fmt: skip
    msg = m.MAVLink_param_set_message(*target, name, value, m.MAV_PARAM_TYPE_REAL32)
    return msg.pack(packer())


def answered(core: SimulatorCore, *requests: bytes):
    """Frame ``k``: sent, answered with the controls and ``requests``; the answer the core took."""
    core.begin_frame()
    answer = core.answer_to_frame(controls(core) + b"".join(requests))
    assert answer is not None
    core.end_frame(answer)
    return answer


@pytest.fixture
def core() -> SimulatorCore:
    return SimulatorCore(SimulatorSetup.load(sensors="gps"))


def test_a_request_applies_once_from_the_next_frame(core):
    for _ in range(3):
        answered(core)
    answer = answered(core, inject(Unit.gps, Type.off))  # frame 3's answer
    (fault,) = core.sensors.faults
    assert (fault.kind, fault.start_s) == ("gps_off", 4 * core.dt_control)  # from frame 4 on
    assert core.info()["failures"] == {"gps": "off"} and core.requests_applied == 1
    # The answer to frame 3 taken once more (a copy): its requests do not apply twice.
    core.begin_frame()
    core._take_requests(answer)  # noqa: SLF001 - the duplicate guard itself
    core.end_frame(core.answer_to_frame(controls(core)))
    assert len(core.sensors.faults) == 1 and core.requests_applied == 1
    answered(core, inject(Unit.gps, Type.ok))
    assert core.sensors.faults[0].duration_s == pytest.approx(2 * core.dt_control)
    assert core.info()["failures"] == {}


def test_a_stale_copy_of_an_answer_applies_nothing(core):
    core.begin_frame()
    data = controls(core) + inject(Unit.baro, Type.stuck)
    core.end_frame(core.answer_to_frame(data))
    core.begin_frame()
    assert core.answer_to_frame(data) is None  # the copy a resent frame brings back: stale
    core.end_frame(core.answer_to_frame(controls(core)))
    assert [f.kind for f in core.sensors.faults] == ["baro_stuck"]


def test_the_answer_that_ends_an_outage_carries_its_requests(core):
    answered(core)
    core.begin_frame()
    core.autopilot_lost()
    core.end_frame(None)
    core.begin_frame()
    late = controls(core) + inject(Unit.mag, Type.off)
    assert core.answers_again(late)
    core.end_frame(None)
    assert [(f.kind, f.start_s) for f in core.sensors.faults] == [("mag_off", core.t)]


HOSTILE = {
    "bad checksum": inject(Unit.gps, Type.off)[:-1] + b"\x00",
    "another sender": inject(Unit.gps, Type.off, mav=packer(system=SYSTEM + 1)),
    "a ground station's id": inject(Unit.gps, Type.off, mav=packer(255, 190)),
    "to the autopilot": inject(Unit.gps, Type.off, target=(SYSTEM, wire.AUTOPILOT_COMPONENT_ID)),
    "to another system": inject(Unit.gps, Type.off, target=(SYSTEM + 1, wire.SIMULATOR_COMPONENT_ID)),
    "another command": inject(1.0, 0.0, command=m.MAV_CMD_COMPONENT_ARM_DISARM),
    "not a request": m.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(packer()),
    "NaN unit": inject(math.nan, Type.off),
    "infinite type": inject(Unit.gps, math.inf),
    "negative instance": inject(Unit.gps, Type.off, -1.0),
    "a fraction": inject(Unit.gps, 1.5),
    "too large": inject(300.0, Type.off),
    "an unmodelled unit": inject(Unit.servo, Type.off),
    "an unmodelled type": inject(Unit.gyro, Type.delayed),
    "no such instance": inject(Unit.motor, Type.off, 7.0),
    "the autopilot's own unit": inject(Unit.rc_signal, Type.off),
    "a motor's effectiveness above 1": inject(Unit.motor, Type.wrong, 1.0, effectiveness=1.5),
    "a NaN effectiveness": inject(Unit.motor, Type.wrong, 1.0, effectiveness=math.nan),
    "bytes that are not MAVLink": b"\x01\x02garbage",
    "a parameter that is not the simulator's": param_set(b"MPC_XY_VEL_MAX", 3.0),
    "a simulator parameter out of range": param_set(b"SIM_BAT_MIN_PCT", 150.0),
    "a NaN simulator parameter": param_set(b"SIM_BAT_DRAIN", math.nan),
    "a parameter to the autopilot": param_set(b"SIM_BAT_DRAIN", 60.0, target=(SYSTEM, 1)),
    "a truncated frame": inject(Unit.gps, Type.off)[:15],
}


@pytest.mark.parametrize("what", list(HOSTILE))
def test_hostile_requests_are_refused_and_counted(core, what):
    answered(core, HOSTILE[what])
    requests = core.info()["requests"]
    assert requests["applied"] == 0 and sum(requests["refused"].values()) == 1, requests
    assert core.sensors.faults == [] and core.failures == {} and core.plant.truth() is not None
    assert any("refused" in w for w in core.warnings)


def test_at_most_a_few_requests_an_answer(core):
    types = (Type.off, Type.stuck, Type.ok, Type.off, Type.slow, Type.ok)
    answered(core, *(inject(Unit.gps, t) for t in types))
    requests = core.info()["requests"]
    assert requests["applied"] == wire.MAX_REQUESTS_PER_ANSWER
    assert sum(requests["refused"].values()) == 6 - wire.MAX_REQUESTS_PER_ANSWER


def test_a_sim_parameter_reaches_the_battery_model(core):
    """PX4's SIM_BAT_* forwarded by the autopilot as PARAM_SET: applied to the battery model."""
    answered(core, param_set(b"SIM_BAT_DRAIN", 120.0), param_set(b"SIM_BAT_MIN_PCT", 10.0))
    info = core.info()
    assert (info["battery"]["SIM_BAT_DRAIN"], info["battery"]["SIM_BAT_MIN_PCT"]) == (120.0, 10.0)
    assert info["requests"]["applied"] == 2 and not info["requests"]["refused"]
