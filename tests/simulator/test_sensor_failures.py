"""Injected sensor failures in the frame kernel, from the table (quadcommon.failures): every sensor
unit x type changes the readings as the table says, from the frame it is injected at, and a
recovery (ok) gives back exactly the readings of a twin suite that never failed.

The sensors are noise-free (a seed draws the same numbers either way, but the failures' own draws,
garbage and intermittent, shift the stream: without noise the twin comparison stays exact) and
the truth moves, so a stuck value is not the truth's."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from quadcommon.failures import FAILURES, SLOW_DIVISOR, Type, Unit, Where
from quadcommon.rigid_body import quaternion_from_euler
from simulator.dynamics.plant import TruthState
from simulator.sensors import EXACT, SensorFault, SensorSuite, load_sensors
from simulator.sensors import frame as sf
from simulator.sensors.config import VisionModel

pytestmark = pytest.mark.timeout(120)

DT = 0.002
START, END = 1.0, 2.0  # the failure's window (s); ok at END
FRAMES = 1700  # 3.4 s: long enough for a 0.5 s delay to drain after END
CONFIG = replace(
    EXACT,
    magnetometer=replace(EXACT.magnetometer, rate_hz=50.0),
    barometer=replace(EXACT.barometer, rate_hz=50.0),
    vision=VisionModel(True, 100.0, 0.0, 0.0, 0.0),
)
SENSOR_PAIRS = [(m.unit.name, t) for m in FAILURES.values() if m.where is Where.SENSORS for t in m.effects]
PAIR_IDS = [f"{unit}-{t.name}" for unit, t in SENSOR_PAIRS]


def truth_at(t: float) -> TruthState:
    yaw = 0.3 * t
    q = quaternion_from_euler(0.05 * math.sin(t), 0.03, yaw)
    position = (math.cos(0.3 * t), math.sin(0.3 * t), 1.0 + 0.2 * t)
    velocity = (-0.3 * math.sin(0.3 * t), 0.3 * math.cos(0.3 * t), 0.2)
    rates = (0.01 * t, -0.02, 0.3)
    z3 = (0.0, 0.0, 0.0)
    return TruthState(position, velocity, z3, q, (0.0, 0.03, yaw), rates, z3, (0.1 * t, -0.05, 9.81),
                      (0.0, 0.0, 0.0, 0.0), 0.0, z3, False)  # fmt: skip


def sample(frame, unit: str) -> tuple[bool, tuple[float, ...]]:
    """(the unit delivered a sample this frame, the values the frame carries for it)."""
    r = frame.readings
    if unit == "accel":
        return r.accel_fresh, r.imu.specific_force_m_s2
    if unit == "gyro":
        return r.gyro_fresh, r.imu.angular_rate_rad_s
    if unit == "mag":
        return frame.mag is not None, r.magnetic_field_gauss
    if unit == "baro":
        return frame.baro is not None, (r.baro.pressure_hpa, r.baro.pressure_altitude_m)
    if unit == "gps":
        g = frame.gps
        return g is not None, () if g is None else (*g.position_m, *g.velocity_m_s)
    v = frame.vision
    return v is not None, () if v is None else (*v.position_m, v.yaw_rad)


def fly(unit: str | None, failure_type: int) -> list:
    """Every frame of a suite whose ``unit`` ("accel" ... "vio") fails by ``failure_type`` over
    [START, END) (ok at END); None: the twin, which never fails."""
    suite = SensorSuite(CONFIG, 488.0, imu_rate_hz=1.0 / DT)
    rows = []
    for k in range(FRAMES):
        t = k * DT
        if unit is not None and k == round(START / DT):
            suite.inject_failure(unit, failure_type, t)
        if unit is not None and k == round(END / DT):
            suite.inject_failure(unit, Type.ok, t)
        rows.append(suite.step(t, truth_at(t)))
    return rows


@pytest.fixture(scope="module")
def twin():
    return fly(None, Type.ok)


def window(rows, unit, lo, hi):
    return [sample(f, unit) for f in rows[round(lo / DT) : round(hi / DT)]]


@pytest.mark.parametrize(("unit", "failure_type"), SENSOR_PAIRS, ids=PAIR_IDS)
def test_each_sensor_failure_changes_the_readings_as_the_table_says(unit, failure_type, twin):
    effect = FAILURES[Unit[unit]].effects[failure_type]
    rows = fly(unit, failure_type)
    before = window(rows, unit, 0.0, START)
    assert before == window(twin, unit, 0.0, START)  # nothing changes before the failure
    during, clean = window(rows, unit, START, END), window(twin, unit, START, END)
    fresh = [values for ok, values in during if ok]
    clean_fresh = [values for ok, values in clean if ok]
    last_good = [values for ok, values in before if ok][-1]
    if failure_type == Type.off:
        assert fresh == []
        if unit in ("accel", "gyro"):  # HIL_SENSOR repeats the last sample, its bits cleared
            assert {values for _, values in during} == {last_good}
    elif failure_type == Type.stuck:
        assert len(fresh) == len(clean_fresh) and set(fresh) == {last_good}
    elif failure_type == Type.garbage:
        assert len(fresh) == len(clean_fresh) and len(set(fresh)) == len(fresh)  # a new draw each time
        low, high = effect.value[0], effect.value[1]
        for got, true in zip(fresh, clean_fresh, strict=True):
            if unit == "baro":
                assert low <= got[0] <= high
            elif unit == "gps":
                assert max(abs(a - b) for a, b in zip(got[:3], true[:3], strict=True)) <= low
                assert max(abs(a - b) for a, b in zip(got[3:], true[3:], strict=True)) <= high
            elif unit == "vio":
                assert max(abs(a - b) for a, b in zip(got[:3], true[:3], strict=True)) <= low
                assert abs(got[3]) <= math.pi
            else:
                assert max(abs(x) for x in got) <= low
    elif failure_type == Type.wrong:
        assert len(fresh) == len(clean_fresh)
        for got, true in zip(fresh, clean_fresh, strict=True):
            offset = np.subtract(got, true)
            if unit == "baro":
                assert offset[0] == pytest.approx(effect.value[0]) and offset[1] > 5.0  # reads high
            else:
                assert offset[:3] == pytest.approx(effect.value, abs=1e-12)
                assert np.all(offset[3:] == 0.0)
    elif failure_type == Type.slow:
        assert len(fresh) == pytest.approx(len(clean_fresh) / SLOW_DIVISOR, abs=1)
        assert set(fresh) <= set(clean_fresh)
    elif failure_type == Type.delayed:  # the twin's samples, the extra latency later
        lag, k0 = round(effect.value[0] / DT), round(START / DT)
        assert not any(ok for ok, _ in during[:lag])
        for k in range(k0 + lag, round(END / DT)):
            got, true = sample(rows[k], unit), sample(twin[k - lag], unit)
            assert got[0] == true[0] and (not got[0] or got[1] == true[1]), k
    elif failure_type == Type.intermittent:
        assert 0.3 * len(clean_fresh) < len(fresh) < 0.7 * len(clean_fresh)
        kept = [(i, v) for i, (ok, v) in enumerate(during) if ok]
        assert all(clean[i] == (True, v) for i, v in kept)  # dropped or true, never changed
    # ok: from END (plus what is still in flight of a delay) the readings are the twin's again
    settled = END + 0.6
    assert window(rows, unit, settled, FRAMES * DT) == window(twin, unit, settled, FRAMES * DT)


def test_a_failure_in_a_profile_is_the_same_row_as_one_injected():
    """``[[faults]]`` kind "baro_stuck" from START: the readings of an injected baro stuck."""
    config = replace(CONFIG, faults=(SensorFault("baro_stuck", START, END - START),))
    suite = SensorSuite(config, 488.0, imu_rate_hz=1.0 / DT)
    profile = [sample(suite.step(k * DT, truth_at(k * DT)), "baro") for k in range(FRAMES)]
    assert profile == [sample(f, "baro") for f in fly("baro", Type.stuck)]
    assert sf.fault_code("baro_stuck") == sf.FAILURE_BASE + 8 * sf.FAILING.index("baro") + Type.stuck


def test_a_recovery_ends_a_profiles_faults_of_the_unit_too():
    suite = SensorSuite(replace(load_sensors("gps"), faults=(SensorFault("gps_outage", 0.5),)), 488.0)
    suite.inject_failure("gps", Type.ok, 1.5)
    (outage,) = suite.faults
    assert (outage.start_s, outage.duration_s) == (0.5, 1.0)
    suite.inject_failure("mag", Type.off, 2.0)
    suite.inject_failure("mag", Type.stuck, 3.0)  # one failure of a unit at a time: off ends
    assert [(f.kind, f.start_s, f.duration_s) for f in suite.faults[1:]] == [
        ("mag_off", 2.0, 1.0), ("mag_stuck", 3.0, math.inf)]  # fmt: skip
