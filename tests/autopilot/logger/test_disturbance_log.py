"""The simulator's disturbance in the flight log: reported in the lockstep frames (``DISTURB``,
quadcommon.wire), held between reports, and logged as ``sim_disturbance``; in simulation time."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from autopilot.logger.logger import LogOptions
from autopilot.mavlink.hil import disturbance_of
from quadcommon import wire
from quadcommon.config import load_scenario
from quadcommon.mavlink_fast import MessageParts
from quadcommon.ulog_topics import DISTURBANCE
from simulator.core import SimulatorSetup
from simulator.environment.gust_profile import load_gust_profile
from sitl.inprocess import Lockstep, RunOptions, flight_record, paper_stack
from tests.stack import Gcs
from tests.ulog_check import check_ulog

pytestmark = pytest.mark.timeout(180)


def debug_array(name: bytes, data: list[float], system_id: int = 1) -> bytes:
    mav = m.MAVLink(None, srcSystem=system_id, srcComponent=wire.SIMULATOR_COMPONENT_ID)
    mav.robust_parsing = True
    return m.MAVLink_debug_float_array_message(123, name, 0, data + [0.0] * (58 - len(data))).pack(mav)


@pytest.mark.parametrize(
    "frame, why",
    [
        (debug_array(b"DISTURB", [1.0, 2.0, float("nan"), 0.0, 0.0, 0.0]), "a NaN"),
        (debug_array(b"DISTURB", [1.0, float("inf"), 0.0, 0.0, 0.0, 0.0]), "an infinity"),
        (debug_array(b"OTHER", [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]), "another array"),
        (debug_array(b"DISTURB", [1.0] * 6)[:-1], "truncated"),
        (debug_array(b"DISTURB", [1.0] * 6)[:-2] + b"\0\0", "a bad checksum"),
        (debug_array(b"DISTURB", [1.0] * 10 + [0.5, 0.0, 0.0, 0.0]), "a failure type that is not a byte"),
        (debug_array(b"DISTURB", [1.0] * 10 + [-1.0, 0.0, 0.0, 0.0]), "a negative failure type"),
    ],
)
def test_a_report_that_is_not_a_sound_disturbance_is_ignored(frame, why):
    assert disturbance_of(MessageParts.of_datagram(frame)) is None, why


def test_a_report_comes_in_the_papers_frames():
    # NED force (1, 2, 3) is the paper's (1, -2, -3); MAVLink Euler torque (4, 5, 6) is (4, -5, -6);
    # the rotors' health as it is (rotor 2 at 70 %, a loss of effectiveness; rotor 4 off)
    frame = debug_array(b"DISTURB", [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 1.0, 0.75, 1.0, 0.0, 0.0, 4.0, 0.0, 1.0])
    assert disturbance_of(MessageParts.of_datagram(frame)) == (
        123, (1.0, -2.0, -3.0), (4.0, -5.0, -6.0), (1.0, 0.75, 1.0, 0.0), (0, 4, 0, 1)
    )


def zero_order_hold(times: np.ndarray, samples_t: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """The last sample at or before each time (the log read as a reader holds it)."""
    index = np.searchsorted(samples_t, times, side="right") - 1
    assert np.all(index >= 0)
    return samples[index]


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """16 s of the paper's circle under the mixed profile (steps, a torque ramp), logged."""
    out = tmp_path_factory.mktemp("mixed")
    options = RunOptions(gusts=load_gust_profile("mixed"))
    base = paper_stack(load_scenario("circle"), load_controller("intbs_nlhinf"), options)
    stack = Lockstep(base.sim.setup, replace(base.autopilot.setup, log=LogOptions(str(out / "log"))))
    for _ in range(round(16 * stack.sim.control_hz)):
        stack.step()
    stack.final_frame()
    record = flight_record(stack, "circle", "intbs_nlhinf")
    (ulg,) = stack.close()
    return check_ulog(ulg), record


def test_the_log_holds_the_disturbance_as_applied(mixed):
    log, record = mixed
    data = log.get_dataset(DISTURBANCE).data
    t = data["timestamp"] * 1e-6
    columns = [f"force_n[{i}]" for i in range(3)] + [f"torque_n_m[{i}]" for i in range(3)]
    logged = np.column_stack([data[c] for c in columns])
    applied = np.column_stack([record.disturbance_force_n, record.disturbance_torque_n_m])
    held = zero_order_hold(record.time_s + 1e-9, t, logged)
    off = np.any(np.abs(held - applied) > 1e-6 * np.maximum(1.0, np.abs(applied)), axis=1)
    # exact but while the torque ramp (10 s to 15 s) changes: there, at most 10 ms behind
    lagging = record.time_s[off]
    assert lagging.size and lagging.min() > 10.0 and lagging.max() < 15.0
    ramp = record.disturbance_torque_n_m[:, 2]
    for k in np.flatnonzero(off):
        assert np.any(np.abs(ramp[max(k - 5, 0) : k + 1] - held[k, 5]) < 1e-6), record.time_s[k]
    # the step at 5 s is a step: the value before it, just before it, then the new one
    before = np.flatnonzero(t < 5.0)[-1]
    assert t[before] == pytest.approx(5.0 - 1e-6) and logged[before, 0] == 0.0
    assert t[before + 1] == pytest.approx(5.0) and logged[before + 1, 0] == 1.0
    # steady stretches cost a sample a second, not one a frame
    assert np.count_nonzero(t < 5.0) <= 6


def test_a_log_that_starts_late_starts_with_the_disturbance_that_applies(tmp_path):
    sim = replace(SimulatorSetup.load(scenario="hover"), gusts=load_gust_profile("mixed"))
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        log=LogOptions(str(tmp_path)))  # fmt: skip
    stack = Lockstep(sim, ap)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    # the force_x step (1 N at 5 s) is reported before anyone logs, and again at 6 s and 7 s
    stack.run_until(6.2)
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert ack.result == m.MAV_RESULT_ACCEPTED, ack
    stack.run_until(6.9)
    (ulg,) = stack.close()
    log = check_ulog(ulg, flight_review=False)
    data = log.get_dataset(DISTURBANCE).data
    assert list(data["force_n[0]"]) == [1.0] and data["timestamp"][0] == log.start_timestamp >= 6_200_000
