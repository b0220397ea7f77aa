"""The project's own fuzzing (sitl.fuzz), seeded: 3 x 10^4 hostile inputs against the autopilot core
while it flies (then a clean landing), 2 x 10^4 against the simulator core's HIL side; and proof
that the fuzzer does catch what it is meant to (a planted fault, a NaN sent, a parameter changed
behind its rules)."""

from __future__ import annotations

import math
import struct

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.mavlink import telemetry
from autopilot.params.store import ParameterStore
from sitl.fuzz import (
    AUTOPILOT_KINDS,
    SIMULATOR_KINDS,
    FuzzFailure,
    FuzzReport,
    Watch,
    fuzz_autopilot,
    fuzz_simulator,
)

pytestmark = pytest.mark.timeout(240)


def test_the_autopilot_core_takes_30000_hostile_inputs_and_still_lands():
    """Every input kind and hostile class (commands, corrupted, truncated, MAVLink 1, dialect, HIL
    frames, random bytes, handled messages) at the counts asserted below; seed 1."""
    report = fuzz_autopilot(30_000, seed=1)
    assert report.total == 30_000
    assert set(report.inputs) == set(AUTOPILOT_KINDS)
    # The inputs reach the handlers: commands are accepted and refused, missions answered.
    results = report.results
    assert results["COMMAND_ACK MAV_RESULT_ACCEPTED"] > 1000
    assert results["COMMAND_ACK MAV_RESULT_DENIED"] > 1000
    assert results["MISSION_ACK MAV_MISSION_ACCEPTED"] > 0 and results["dropped: bad data"] > 1000
    assert any("ARM_DISARM refused" in reason for reason in report.refusals)
    assert any(reason.startswith("setpoint refused") for reason in report.refusals)


@pytest.mark.parametrize("sensors", ["gps"])
def test_the_autopilot_core_on_its_ekf_takes_20000_hostile_inputs(sensors):
    """On the estimate, fed by the sensor models (seed 15 asks for HIGHRES_IMU, among the rest: the
    sensors come back finite), vision messages among the inputs."""
    report = fuzz_autopilot(20_000, seed=15, sensors=sensors)
    assert report.results["COMMAND_ACK MAV_RESULT_ACCEPTED"] > 100


def test_the_simulator_core_takes_20000_hostile_inputs():
    report = fuzz_simulator(20_000, seed=1)
    assert set(report.inputs) == set(SIMULATOR_KINDS)
    assert report.results["answer applied"] > 1000 and report.results["gust upload refused"] > 1000


def test_the_fuzzer_catches_a_nan_on_the_wire(monkeypatch):
    real = telemetry.vfr_hud

    def nan_climb(status):
        msg = real(status)
        msg.climb = math.nan
        return msg

    monkeypatch.setitem(telemetry.BUILDERS, telemetry.m.MAVLINK_MSG_ID_VFR_HUD, nan_climb)
    with pytest.raises(FuzzFailure, match="VFR_HUD.climb"):
        fuzz_autopilot(200, seed=2)


def test_an_integer_parameter_sent_bytewise_is_not_taken_for_a_nan():
    """PX4 sends INT32 parameters bytewise: SDLOG_MODE = -1 is 0xffffffff, a NaN read as a float.
    The watch reads it as the integer it is, and still catches a REAL32 NaN."""
    mav = m.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.robust_parsing = True
    minus_one = struct.unpack("<f", struct.pack("<i", -1))[0]
    watch = Watch(FuzzReport(0), set())
    sdlog = m.MAVLink_param_value_message(b"SDLOG_MODE", minus_one, m.MAV_PARAM_TYPE_INT32, 200, 7)
    watch(0, ("127.0.0.1", 14550), sdlog.pack(mav), "bytewise")
    real = m.MAVLink_param_value_message(b"MPC_XY_VEL_MAX", math.nan, m.MAV_PARAM_TYPE_REAL32, 200, 8)
    with pytest.raises(FuzzFailure, match="PARAM_VALUE.param_value = nan"):
        watch(0, ("127.0.0.1", 14550), real.pack(mav), "real32")


def test_the_fuzzer_catches_a_parameter_set_behind_its_rules(monkeypatch):
    monkeypatch.setattr(ParameterStore, "validate", lambda self, name, value: None)  # checks nothing
    with pytest.raises(FuzzFailure, match="rules refuse|PARAM_VALUE.param_value"):
        fuzz_autopilot(20_000, seed=1)
