"""The disturbance in the lockstep frame (``DISTURB``, quadcommon.wire): when the simulator reports
it, and that a receiver holding the last report knows the disturbance as applied."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from autopilot.mavlink.hil import DISTURBANCE_ID, disturbance_of
from quadcommon import wire
from quadcommon.bus_records import TRUTH_FIELDS
from quadcommon.mavlink_fast import MessageParts, split_frames
from simulator.core import DisturbanceReport, SimulatorCore, SimulatorSetup
from simulator.environment.gust_profile import load_gust_profile

pytestmark = pytest.mark.timeout(60)

FRAME_US = 2_000  # 500 Hz
# The truth row's columns of the applied disturbance (force, world; torque on the Euler coordinates).
APPLIED = [TRUTH_FIELDS.index(n) for n in ("Ax_n", "Ay_n", "Az_n", "Ap_n_m", "Aq_n_m", "Ar_n_m")]


def reports(signal: list[float]) -> dict[int, tuple[int, float]]:
    """Frame index -> (sample time, value) of every report over a scalar signal."""
    report = DisturbanceReport()
    out = {}
    for k, value in enumerate(signal):
        due = report.due(k * FRAME_US, (value,))
        if due is not None:
            out[k] = (due[0], due[1][0])
    return out


def test_a_step_is_reported_in_the_frame_it_happens_and_a_steady_value_once_a_second():
    signal = [0.0] * 1000 + [1.0] * 1000  # 2 s: a step at t = 2 s
    got = reports(signal)
    assert got == {0: (0, 0.0), 500: (1_000_000, 0.0), 1000: (2_000_000, 1.0), 1500: (3_000_000, 1.0)}


def test_a_ramp_is_reported_every_10_ms_and_where_it_settles():
    ramp = [min(k / 100, 1.0) for k in range(200)]  # rises for 100 frames (0.2 s), then stays at 1
    signal = [0.0] * 50 + ramp
    got = reports(signal)
    onset = 51  # the first frame that differs from the steady 0
    assert got[0] == (0, 0.0) and got[onset] == (onset * FRAME_US, signal[onset])
    changing = [k for k in got if onset < k <= 150]
    gaps = {(b - a) * FRAME_US for a, b in zip([onset, *changing[:-1]], changing, strict=True)}
    assert gaps <= {10_000, FRAME_US}, gaps  # every 10 ms while it changes
    settled_at = 150  # the first frame at 1.0; reported one frame later, stamped with its own time
    assert got[settled_at + 1] == (settled_at * FRAME_US, 1.0)
    assert all(k <= settled_at + 1 for k in got if k > 0)  # then nothing more within the second


def test_a_change_right_after_settling_is_an_onset():
    signal = [0.0] * 10 + [0.5, 1.0, 1.0, 2.0, 2.0, 2.0]
    got = reports(signal)
    assert got[10] == (10 * FRAME_US, 0.5)  # onset
    assert got[12] == (11 * FRAME_US, 1.0)  # settled at frame 11
    assert got[13] == (13 * FRAME_US, 2.0)  # an onset again: 1.0 was held since frame 11


@pytest.fixture(scope="module")
def mixed_flight():
    """4,000 frames of the simulator under every kind of disturbance (steps, a torque ramp, a 1-cos
    gust; Dryden is wind, not in the report), never stepped: only the disturbance matters here."""
    setup = SimulatorSetup.load(scenario="hover")
    setup = replace(setup, gusts=load_gust_profile("mixed"))
    sim = SimulatorCore(setup)
    applied, held = [], []
    current = None
    for _ in range(round(sim.control_hz * 16)):
        datagram = sim.begin_frame()
        parts = MessageParts.of_datagram(datagram)
        if DISTURBANCE_ID in parts:
            report = disturbance_of(parts)
            assert report.time_usec <= sim.time_usec
            assert report.rotor_effectiveness == (1.0,) * 4 and report.rotor_failure == (0,) * 4  # healthy
            current = (*report.force_n, *report.torque_n_m)
        row = sim.truth_row
        applied.append(tuple(row[i] for i in APPLIED))
        held.append(current)
        sim.k += 1  # the next frame, the plant where it was
    return sim, applied, held


def same(applied: tuple, held: tuple) -> bool:
    """Equal as float32 carries them (DEBUG_FLOAT_ARRAY's data)."""
    return all(abs(a - h) <= 1e-6 * max(1.0, abs(a)) for a, h in zip(applied, held, strict=True))


def test_holding_the_reports_gives_the_applied_disturbance(mixed_flight):
    sim, applied, held = mixed_flight
    hz = sim.control_hz
    frames_per_10ms = round(0.01 * hz)
    late = []
    for k, (a, h) in enumerate(zip(applied, held, strict=True)):
        if not same(a, h):
            # never more than 10 ms behind what was applied
            assert any(same(applied[j], h) for j in range(max(k - frames_per_10ms, 0), k + 1)), (k, a, h)
            late.append(k / hz)
    # and only while it changes: the torque ramp from 10 s to 15 s; steps are exact
    assert late and min(late) > 10.0 and max(late) < 15.0, (min(late), max(late))
    # the frames' signs and units: the held value is the paper's (world z up), not NED's
    assert max(h[2] for h in held) == 0.0 and min(h[2] for h in held) == pytest.approx(-0.5)
    assert max(h[5] for h in held) == pytest.approx(0.2)


def test_a_steady_stretch_costs_one_message_a_second():
    # before 5 s the mixed profile applies no force or torque (its turbulence is wind)
    setup = replace(SimulatorSetup.load(scenario="hover"), gusts=load_gust_profile("mixed"))
    again = SimulatorCore(setup)
    carried = 0
    for _ in range(round(again.control_hz * 5)):  # the first 5 s: zero throughout
        carried += DISTURBANCE_ID in dict(split_frames(again.begin_frame()))
        again.k += 1
    assert carried == math.ceil(5 / wire.DISTURBANCE_REPORT_EVERY_S)
