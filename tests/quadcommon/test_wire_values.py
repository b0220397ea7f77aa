"""What the lockstep frame's messages carry: each encoder gives the message's own values (float32
fields, scaled and saturated integers, NED/FRD), and the decoder reads them back into the paper's
frames. Checked against pymavlink packing the same values (lossless) and against the fields' units."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from quadcommon import wire_values as w
from quadcommon.mavlink_fast import record_dtype

pytestmark = pytest.mark.timeout(60)

HOME = (47.397742, 8.545594, 488.0)


def test_float_fields_are_float32_and_pack_losslessly():
    x = 0.1
    f = w.float_field(x)
    assert f != x and f == float(np.float32(x))
    msg = mavlink.MAVLink_odometry_message(0, 1, 1, f, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0, [0] * 21,
                                           [0] * 21, 0, 0, 0)  # fmt: skip
    packed = msg.pack(mavlink.MAVLink(None, 1, 1))
    assert mavlink.MAVLink(None).decode(bytearray(packed)).x == f


def test_vectors_cross_in_ned_and_come_back_in_the_paper_frames():
    v = (1.0, 2.0, 3.0)
    field = w.vector_field(v)
    assert field == (1.0, -2.0, -3.0)
    assert w.vector_from_field(field) == v


@pytest.mark.parametrize(
    "sat, x, expected",
    [(w.sat_i16, 40000.0, 32767), (w.sat_i16, -40000.0, -32767), (w.sat_i16, math.nan, 0),
     (w.sat_i16, 2.5, 2), (w.sat_i32, 3e9, 2147483647), (w.sat_i32, math.nan, 0), (w.sat_u16, -3.0, 0),
     (w.sat_u16, 7e4, 65534), (w.sat_u16, math.nan, 65535)],
)  # fmt: skip
def test_integer_fields_saturate_and_take_nan_as_mavlink_has_it(sat, x, expected):
    assert sat(x) == expected


def test_a_gps_fix_crosses_in_its_units_and_comes_back_within_their_resolution():
    position, velocity = (120.0, -35.0, 12.0), (3.0, -4.0, 0.5)
    lat, lon, alt, eph, epv, vel, vn, ve, vd, cog = w.gps_values(position, velocity, 0.8, 1.234, HOME)
    assert (eph, epv, vel) == (80, 123, 500)  # cm, ground speed cm/s
    assert (vn, ve, vd) == (300, 400, -50)  # NED cm/s: y left is east negative, z up is down negative
    assert cog == round(math.degrees(math.atan2(400, 300)) * 100)
    assert alt == round((HOME[2] + 12.0) * 1000)
    back, v_back, eph_m, epv_m = w.gps_fix(lat, lon, alt, vn, ve, vd, eph, epv, HOME)
    assert max(abs(a - b) for a, b in zip(back, position, strict=True)) < 0.01  # 1e-7 deg ~ 1 cm
    assert v_back == pytest.approx(velocity, abs=0.005)
    assert (eph_m, epv_m) == (0.8, 1.23)


def test_an_unknown_gps_accuracy_reads_as_the_autopilots_unknown():
    *_, eph, epv = w.gps_fix(0, 0, 0, 0, 0, 0, 65535, 65535, HOME)
    assert eph == epv == w.GPS_ACCURACY_UNKNOWN_M


def test_odometry_carries_the_truth_as_the_autopilot_flies_it():
    yaw = 0.7
    q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    fields = w.odometry_values((1.0, 2.0, 3.0), (0.5, -0.5, 0.25), q, (0.0, 0.0, 0.2))
    position_ned, velocity_ned, q_ned, rates_frd = fields
    assert position_ned == (1.0, -2.0, -3.0) and q_ned[3] == pytest.approx(-math.sin(yaw / 2))
    position, velocity, euler, euler_rates = w.odometry_state(*fields)
    assert position == (1.0, 2.0, 3.0) and velocity == (0.5, -0.5, 0.25)
    assert euler == pytest.approx((0.0, 0.0, yaw), abs=1e-7)
    assert euler_rates == pytest.approx((0.0, 0.0, 0.2), abs=1e-7)


def test_a_vision_pose_carries_variances_and_reads_back_standard_deviations():
    (n, e, d), yaw, p_var, yaw_var = w.vision_values((1.0, 2.0, 3.0), 0.3, 0.01, 0.02)
    assert (n, e, d) == (1.0, -2.0, -3.0) and yaw == w.float_field(-0.3)
    position, yaw_back, p_std, yaw_std = w.vision_pose((n, e, d), yaw, p_var, yaw_var)
    assert position == (1.0, 2.0, 3.0) and yaw_back == pytest.approx(0.3, abs=1e-7)
    assert p_std == pytest.approx(0.01, rel=1e-6) and yaw_std == pytest.approx(0.02, rel=1e-6)
    assert w.vision_pose((0.0, 0.0, 0.0), 0.0, -1.0, math.nan)[2:] == (0.0, 0.0)


# frame_records' arguments after the records, time and flags: the truth (position ... specific
# force, wind, home) and the sensors' readings (specific force, rates, field).
FRAME_TRUTH = (
    (1.5, -2.25, 3.0), (0.4, -0.3, 0.2), (0.9, 0.1, -0.2, 0.3), (0.01, -0.02, 0.3), (0.1, 0.2, 9.7),
    (1.0, -1.0, 0.5), HOME, (0.11, 0.19, 9.69), (0.012, -0.018, 0.29), (0.2, 0.01, -0.4),
)  # fmt: skip


def test_the_frames_compiled_entries_give_the_python_kernels_values_exactly():
    arguments = {
        w.odometry_state: ((1.5, -2.25, -3.0), (0.4, 0.3, -0.2), (0.9, 0.1, 0.2, -0.3), (0.01, 0.02, -0.3)),
        w.vision_values: ((1.5, -2.25, 3.0), 0.7, 0.01, 0.02),
        w.vision_pose: ((1.5, 2.25, -3.0), -0.7, 1e-4, 4e-4),
        w.gps_values: ((1.5, -2.25, 3.0), (0.4, -0.3, 0.2), 0.8, 1.2, HOME),
        w.gps_fix: (473977540, 85455700, 491000, 40, -30, -20, 80, 120, HOME),
    }
    assert set(arguments) | {w.frame_records} == set(w.FRAME_ENTRIES)
    for fn, args in arguments.items():
        assert w.entry(fn)(*args) == fn(*args), fn.__name__
    # The records of a frame: the same bytes filled by the compiled entry and by the Python kernel.
    truth = FRAME_TRUTH
    filled = []
    for fill in (w.entry(w.frame_records), w.frame_records):
        records = [np.zeros(record_dtype(c).itemsize, np.uint8) for c in w.FRAME_RECORD_MESSAGES]
        assert fill(*records, 123_456_789, 0x1FFF, *truth, 963.25, 490.123, 11.8) is True
        filled.append([r.tobytes() for r in records])
    assert filled[0] == filled[1]


def test_hil_state_fields_scale_and_saturate_the_truth():
    lat, lon, alt, vx, vy, vz, airspeed, xacc, yacc, zacc = w.hil_state_values(
        (0.0, 0.0, 2.0), (1.0, -2.0, 400.0), (0.0, 0.0, 9.80665), (1.0, 0.0, 0.0), HOME
    )
    assert (lat, lon, alt) == (473977420, 85455940, 490000)  # 1e-7 deg, mm
    assert (vx, vy, vz) == (100, 200, -32767)  # cm/s NED, saturated at int16
    assert airspeed == round(100.0 * math.hypot(2.0, 400.0))  # through the air: the wind taken off
    assert (xacc, yacc, zacc) == (0, 0, -1000)  # mG, FRD: 1 g up is -1000 down


def test_a_frames_records_carry_frame_fields_values_as_pymavlink_reads_them():
    """frame_records writes what frame_fields computes, each value in its field: pymavlink's
    decoder reads the records' bytes back as those values (float fields as float32)."""
    truth = FRAME_TRUTH
    records = [np.zeros(record_dtype(c).itemsize, np.uint8) for c in w.FRAME_RECORD_MESSAGES]
    assert w.entry(w.frame_records)(*records, 123_456_789, 0x1C0, *truth, 963.25, 490.123, 11.8)
    sensor, state, odometry = (
        dict(zip(c.ordered_fieldnames, _grouped(c, c.unpacker.unpack(r.tobytes())), strict=True))
        for c, r in zip(w.FRAME_RECORD_MESSAGES, records, strict=True)
    )
    force, rate, field, altitude, (p, v, q, rates), hil = w.frame_fields(*truth, 490.123)
    f32 = w.float_field
    assert sensor["time_usec"] == state["time_usec"] == odometry["time_usec"] == 123_456_789
    assert (sensor["xacc"], sensor["yacc"], sensor["zacc"]) == force
    assert (sensor["xgyro"], sensor["ygyro"], sensor["zgyro"]) == rate
    assert (sensor["xmag"], sensor["ymag"], sensor["zmag"]) == field
    assert sensor["pressure_alt"] == altitude and sensor["fields_updated"] == 0x1C0
    assert (sensor["abs_pressure"], sensor["temperature"]) == (f32(963.25), f32(11.8))
    assert tuple(state["attitude_quaternion"]) == q == tuple(odometry["q"])
    assert (state["rollspeed"], state["pitchspeed"], state["yawspeed"]) == rates
    assert (odometry["rollspeed"], odometry["pitchspeed"], odometry["yawspeed"]) == rates
    assert (odometry["x"], odometry["y"], odometry["z"]) == p
    assert (odometry["vx"], odometry["vy"], odometry["vz"]) == v
    names = ("lat", "lon", "alt", "vx", "vy", "vz", "ind_airspeed", "xacc", "yacc", "zacc")
    assert tuple(state[n] for n in names) == hil and state["true_airspeed"] == hil[6]
    # A state past float32's range: refused, nothing written.
    before = [r.tobytes() for r in records]
    far = ((1e39, 0.0, 0.0), *truth[1:])
    assert not w.entry(w.frame_records)(*records, 1, 0, *far, 963.25, 490.123, 11.8)
    assert not w.entry(w.frame_records)(*records, 1, 0, *truth, 1e39, 490.123, 11.8)
    assert [r.tobytes() for r in records] == before


def _grouped(message_class, flat: tuple) -> list:
    """A struct's flat values grouped per field (array fields as tuples)."""
    out, at = [], 0
    for length in (message_class.lengths[message_class.ordered_fieldnames.index(n)]
                   for n in message_class.ordered_fieldnames):  # fmt: skip
        out.append(flat[at] if length == 1 else tuple(flat[at : at + length]))
        at += length
    return out


def test_a_frame_entry_is_warmed_then_frozen_it_refuses_a_new_type_instead_of_compiling():
    from quadcommon.kernel import compiling

    if not compiling():
        pytest.skip("nothing compiles (QUADSITL_PURE_PYTHON=1): the entries are the Python kernels")
    fix = w.entry(w.gps_fix)
    assert fix(473977540, 85455700, 491000, 40, -30, -20, 80, 120, HOME) == w.gps_fix(
        473977540, 85455700, 491000, 40, -30, -20, 80, 120, HOME
    )
    with pytest.raises(TypeError):
        fix(np.zeros(2), 85455700, 491000, 40, -30, -20, 80, 120, HOME)  # an array where an int was
