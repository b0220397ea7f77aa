"""MAV_CMD_DO_REPOSITION (MAVSDK's goto_location, QGC's "go to location") on the wire, in simulation
time: the whole stack in-process, a pymavlink ground station sending COMMAND_INT / COMMAND_LONG."""

from __future__ import annotations

import math
import struct

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from quadcommon import frames

from ..stack import Gcs
from .test_params_failsafes import param_set, take_off, texts, wait_sim

HOME = (47.397742, 8.545594, 488.0)  # config/sitl.toml [home]
LOITER = FlightMode.AUTO_LOITER.custom_mode
NAN = math.nan
INT32_MAX = 2**31 - 1


def latlon(north: float, east: float) -> tuple[float, float]:
    lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, HOME)
    return lat, lon


def command_int(gcs: Gcs, frame: int, params, x: int, y: int, z: float, sim_timeout: float = 0.5):
    gcs.acks.clear()
    gcs.conn.mav.command_int_send(gcs.system_id, 1, frame, m.MAV_CMD_DO_REPOSITION, 0, 0, *params, x, y, z)
    cmd = m.MAV_CMD_DO_REPOSITION
    gcs.wait(lambda g: any(a.command == cmd for a in g.acks), sim_timeout, "COMMAND_ACK 192")
    return next(a for a in gcs.acks if a.command == cmd)


def wait_at(gcs: Gcs, target, within: float, sim_timeout: float):
    gcs.wait(lambda g: math.dist(g.position(), target) < within, sim_timeout, f"at {target}")


@pytest.mark.timeout(120)
def test_reposition_flies_to_the_point_and_holds_there(vehicle):
    stack, gcs = vehicle
    # On the ground: refused with a reason.
    lat, lon = latlon(6.0, 3.0)
    x, y = round(lat * 1e7), round(lon * 1e7)
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, NAN), x, y, 493.0)
    assert ack.result == m.MAV_RESULT_DENIED
    take_off(gcs, 2.0)
    # MAVSDK goto_location: COMMAND_INT, GLOBAL_INT, AMSL altitude, param2 bit 0, yaw 90 deg (east).
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, 90.0), x, y, 491.0)
    assert ack.result == m.MAV_RESULT_ACCEPTED
    target = frames.vector_from_ned((6.0, 3.0, -3.0))  # paper frame: y left
    wait_at(gcs, target, 0.1, sim_timeout=20.0)
    assert gcs.custom_mode == LOITER
    yaw_ned = gcs.last["ATTITUDE"].yaw
    assert math.degrees(yaw_ned) == pytest.approx(90.0, abs=3.0)
    wait_sim(gcs, 2.0)
    assert math.dist(gcs.position(), target) < 0.1  # holds there
    # COMMAND_LONG, relative altitude, altitude NaN keeps it; at 1 m/s; no mode flag while holding.
    lat2, lon2 = latlon(0.0, 0.0)
    ack = gcs.command(m.MAV_CMD_DO_REPOSITION, 1.0, 0, 0, NAN, lat2, lon2, NAN)
    assert ack.result == m.MAV_RESULT_ACCEPTED
    t0 = gcs.sim_time
    # COMMAND_LONG carries latitude/longitude as float32: ~0.5 m of resolution here (COMMAND_INT: 1 cm).
    f32 = [struct.unpack("<f", struct.pack("<f", v))[0] for v in (lat2, lon2)]
    home_target = (*frames.vector_from_ned(frames.geodetic_to_ned(*f32, 0.0, HOME))[:2], 3.0)
    speeds = []
    gcs.wait(
        lambda g: speeds.append(math.hypot(g.last["LOCAL_POSITION_NED"].vx, g.last["LOCAL_POSITION_NED"].vy))
        or math.dist(g.position(), home_target) < 0.1,
        sim_timeout=20.0,
        what="back above home",
    )
    assert max(speeds) < 1.1 and gcs.sim_time - t0 > 6.0  # 6.7 m at 1 m/s
    # Relative frame: 4 m above home, position unchanged (INT32_MAX = unset).
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, (-1, 1, 0, NAN), INT32_MAX, INT32_MAX, 4.0)
    assert ack.result == m.MAV_RESULT_ACCEPTED
    wait_at(gcs, (*home_target[:2], 4.0), 0.1, sim_timeout=10.0)


@pytest.mark.timeout(120)
def test_reposition_refusals_say_why(vehicle):
    stack, gcs = vehicle
    take_off(gcs, 2.0)
    lat, lon = latlon(5.0, 0.0)
    x, y = round(lat * 1e7), round(lon * 1e7)
    cases = [
        ((m.MAV_FRAME_LOCAL_NED, (-1, 1, 0, NAN), x, y, 490.0), "frame 1"),
        ((m.MAV_FRAME_GLOBAL_INT, (math.inf, 1, 0, NAN), x, y, 490.0), "infinite"),
        ((m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, 500.0), x, y, 490.0), "yaw"),
        ((m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, NAN), 950_000_000, y, 490.0), "latitude"),
        ((m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, NAN), x, INT32_MAX, 490.0), "both"),
        ((m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, NAN), *(round(v * 1e7) for v in latlon(2000.0, 0.0)), 490.0),
         "NAV_REF_MAX_DIST"),
    ]  # fmt: skip
    for (frame, params, cx, cy, cz), why in cases:
        ack = command_int(gcs, frame, params, cx, cy, cz)
        assert ack.result == m.MAV_RESULT_DENIED, why
        wait_sim(gcs, 0.1)
        assert why in texts(gcs), (why, texts(gcs)[-300:])
    ack = gcs.command(m.MAV_CMD_DO_REPOSITION, -1, 1, 0, NAN, lat, NAN, 490.0)
    assert ack.result == m.MAV_RESULT_DENIED
    # Outside the geofence (GF_MAX_HOR_DIST): refused before flying there.
    param_set(gcs, "GF_MAX_HOR_DIST", 4.0)
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, NAN), x, y, 490.0)
    assert ack.result == m.MAV_RESULT_DENIED
    wait_sim(gcs, 0.1)
    assert "geofence" in texts(gcs)
    # Not holding and no change-mode flag: refused; the vehicle stays where it was.
    param_set(gcs, "GF_MAX_HOR_DIST", 0.0)
    assert gcs.command(m.MAV_CMD_NAV_LAND).result == m.MAV_RESULT_ACCEPTED
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 0, 0, NAN), x, y, 490.0)
    assert ack.result == m.MAV_RESULT_DENIED
    wait_sim(gcs, 0.1)
    assert "not hold" in texts(gcs)
    assert math.hypot(*gcs.position()[:2]) < 0.2


@pytest.mark.timeout(120)
def test_armed_on_the_ground_it_takes_off_first_then_flies_there_and_holds(vehicle):
    stack, gcs = vehicle
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    lat, lon = latlon(4.0, -2.0)
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, (-1, 1, 0, NAN), round(lat * 1e7),
                      round(lon * 1e7), 3.0)  # fmt: skip
    assert ack.result == m.MAV_RESULT_ACCEPTED
    # straight up first (PX4: a reposition while landed takes off to its altitude)
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > 2.0, sim_timeout=10.0,
             what="climbing")  # fmt: skip
    north, east, _ = frames.vector_to_ned(gcs.position())
    assert math.hypot(north, east) < 0.3
    target = frames.vector_from_ned((4.0, -2.0, -3.0))
    wait_at(gcs, target, 0.1, sim_timeout=20.0)
    wait_sim(gcs, 2.0)
    assert math.dist(gcs.position(), target) < 0.1 and gcs.custom_mode == LOITER
    assert "taking off to 3.00 m, then repositioning" in texts(gcs)
    # landed, armed again: altitude NaN (keep) means the takeoff altitude
    gcs.command(m.MAV_CMD_NAV_LAND, 0, 0, 0, NAN, NAN, NAN, NAN)
    gcs.wait(lambda g: not g.armed, sim_timeout=30.0, what="landed and disarmed")
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    lat, lon = latlon(0.0, 0.0)
    ack = command_int(gcs, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, (-1, 1, 0, NAN), round(lat * 1e7),
                      round(lon * 1e7), NAN)  # fmt: skip
    assert ack.result == m.MAV_RESULT_ACCEPTED
    param = stack.autopilot.params["MIS_TAKEOFF_ALT"]
    wait_at(gcs, (0.0, 0.0, param), 0.1, sim_timeout=25.0)
