"""Orbit (MAV_CMD_DO_ORBIT) and follow-me (FOLLOW_TARGET, AUTO.FOLLOW_TARGET) on the wire, in
simulation time: the whole stack in-process, a pymavlink ground station."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from quadcommon import frames

from ..stack import Gcs
from .test_params_failsafes import param_set, take_off, texts, wait_sim

HOME = (47.397742, 8.545594, 488.0)  # config/sitl.toml [home]
ORBIT = FlightMode.ORBIT.custom_mode
FOLLOW = FlightMode.AUTO_FOLLOW_TARGET.custom_mode
LOITER = FlightMode.AUTO_LOITER.custom_mode
NAN = math.nan
INT32_MAX = 2**31 - 1
CUSTOM = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


def latlon_e7(north: float, east: float) -> tuple[int, int]:
    lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, HOME)
    return round(lat * 1e7), round(lon * 1e7)


def orbit_int(gcs: Gcs, radius, speed, yaw, x=INT32_MAX, y=INT32_MAX, z=NAN, frame=m.MAV_FRAME_GLOBAL_INT):
    """DO_ORBIT as MAVSDK sends it (COMMAND_INT; param4 NaN)."""
    gcs.acks.clear()
    gcs.conn.mav.command_int_send(gcs.system_id, 1, frame, m.MAV_CMD_DO_ORBIT, 0, 0, radius, speed, yaw, NAN,
                                  x, y, z)  # fmt: skip
    gcs.wait(lambda g: any(a.command == m.MAV_CMD_DO_ORBIT for a in g.acks), 0.5, "COMMAND_ACK 34")
    return next(a for a in gcs.acks if a.command == m.MAV_CMD_DO_ORBIT)


def said(gcs: Gcs, text: str) -> None:
    gcs.wait(lambda g: text in texts(g), 1.0, f"STATUSTEXT {text!r}")


def velocity(gcs: Gcs) -> tuple[float, float]:
    lp = gcs.last["LOCAL_POSITION_NED"]
    return lp.vx, -lp.vy  # paper frame x, y


def heading(gcs: Gcs) -> float:
    """The vehicle's yaw in the paper frame (rad, z up)."""
    return frames.yaw_from_ned(gcs.last["ATTITUDE"].yaw)


def angle_between(a: float, b: float) -> float:
    return abs(frames.wrap_pi(a - b))


def sample_orbit(gcs: Gcs, centre, seconds: float):
    """(radius, speed, turn sign, yaw error to the centre, yaw, velocity direction) every frame."""
    rows = []
    t0 = gcs.sim_time

    def record(g: Gcs) -> bool:
        x, y, z = g.position()
        vx, vy = velocity(g)
        dx, dy = x - centre[0], y - centre[1]
        to_centre = math.atan2(-dy, -dx)
        rows.append((math.hypot(dx, dy), math.hypot(vx, vy), dx * vy - dy * vx, to_centre, heading(g),
                     math.atan2(vy, vx), z))  # fmt: skip
        return g.sim_time > t0 + seconds

    gcs.wait(record, sim_timeout=seconds + 2.0, what="orbit samples")
    return rows


@pytest.mark.timeout(240)
def test_orbit_flies_the_circle_each_way_and_yaw_behaviour(vehicle):
    stack, gcs = vehicle
    cx, cy = latlon_e7(10.0, 0.0)  # 10 m north of home
    # Disarmed, as PX4: the mode is selected, and it prevents arming.
    assert orbit_int(gcs, 5.0, 2.0, 0, cx, cy, 492.0).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: g.custom_mode == ORBIT, 2.0, "ORBIT selected")
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_DENIED
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, CUSTOM, 4, 3).result == m.MAV_RESULT_ACCEPTED
    take_off(gcs, 3.0)
    # Refused as PX4 refuses them, the mode unchanged: a radius beyond MC_ORBIT_RAD_MAX or under 1 m,
    # a yaw behaviour outside ORBIT_YAW_BEHAVIOUR, half a centre, an infinite slot.
    assert orbit_int(gcs, 2000.0, 2.0, 0).result == m.MAV_RESULT_DENIED
    said(gcs, "Orbit radius limit exceeded")
    assert orbit_int(gcs, -0.5, 2.0, 0).result == m.MAV_RESULT_DENIED
    assert orbit_int(gcs, 5.0, 2.0, 7).result == m.MAV_RESULT_DENIED
    assert orbit_int(gcs, 5.0, 2.0, 0, cx, INT32_MAX).result == m.MAV_RESULT_DENIED
    assert gcs.command(m.MAV_CMD_DO_ORBIT, 5.0, math.inf).result == m.MAV_RESULT_DENIED
    far = latlon_e7(5000.0, 0.0)  # beyond NAV_REF_MAX_DIST (1000 m)
    assert orbit_int(gcs, 5.0, 2.0, 0, *far).result == m.MAV_RESULT_DENIED
    assert gcs.custom_mode == LOITER
    # MAVSDK's do_orbit: 5 m clockwise at 2 m/s around a point 10 m north, 4 m up, facing the centre.
    assert orbit_int(gcs, 5.0, 2.0, 0, cx, cy, 492.0).result == m.MAV_RESULT_ACCEPTED
    centre = (10.0, 0.0, 4.0)
    gcs.wait(lambda g: g.custom_mode == ORBIT, 2.0, "ORBIT in HEARTBEAT")
    wait_sim(gcs, 15.0)  # the approach, and the speed reached
    rows = sample_orbit(gcs, centre, 8.0)
    assert all(abs(r - 5.0) < 0.3 for r, *_ in rows)
    assert all(abs(v - 2.0) < 0.2 for _, v, *_ in rows)
    assert all(turn < 0.0 for _, _, turn, *_ in rows)  # clockwise seen from above (z up)
    assert all(angle_between(to_centre, yaw) < math.radians(8.0) for _, _, _, to_centre, yaw, _, _ in rows)
    assert all(abs(z - 4.0) < 0.2 for *_, z in rows)
    status = gcs.last["ORBIT_EXECUTION_STATUS"]
    assert status.radius == pytest.approx(5.0) and (status.x, status.y) == (cx, cy)
    assert status.z == pytest.approx(492.0, abs=0.01) and status.frame == m.MAV_FRAME_GLOBAL
    # Counter-clockwise, holding the initial heading, the centre kept (NaN); 5 m/s on 2 m is more
    # than PX4's 2 m/s^2 of centripetal acceleration allows: sqrt(2 x 2) = 2 m/s.
    yaw0 = heading(gcs)
    assert orbit_int(gcs, -2.0, 5.0, 1).result == m.MAV_RESULT_ACCEPTED
    said(gcs, "limited")
    wait_sim(gcs, 12.0)
    rows = sample_orbit(gcs, centre, 6.0)
    assert all(abs(r - 2.0) < 0.3 for r, *_ in rows)
    assert all(abs(v - 2.0) < 0.25 for _, v, *_ in rows)
    assert all(turn > 0.0 for _, _, turn, *_ in rows)
    assert all(angle_between(yaw, yaw0) < math.radians(5.0) for *_, yaw, _, _ in rows)
    assert gcs.last["ORBIT_EXECUTION_STATUS"].radius == pytest.approx(-2.0)
    # Front tangent to the circle (COMMAND_LONG, NaN: the centre kept).
    assert gcs.command(m.MAV_CMD_DO_ORBIT, 4.0, 1.5, 3, NAN, NAN, NAN, NAN).result == m.MAV_RESULT_ACCEPTED
    wait_sim(gcs, 12.0)
    rows = sample_orbit(gcs, centre, 6.0)
    assert all(abs(r - 4.0) < 0.3 and abs(v - 1.5) < 0.2 and turn < 0.0 for r, v, turn, *_ in rows)
    assert all(angle_between(yaw, course) < math.radians(8.0) for *_, yaw, course, _ in rows)
    # A radius within 1 m of the circle flown: no new approach, the circle widens on the way.
    assert gcs.command(m.MAV_CMD_DO_ORBIT, 4.8, NAN, NAN, NAN, NAN, NAN, NAN).result == m.MAV_RESULT_ACCEPTED
    rows = sample_orbit(gcs, centre, 4.0)
    assert all(3.8 < r < 5.1 for r, *_ in rows)  # (the speed: 1.5 m/s around, 1 m/s outwards)
    assert all(abs(r - 4.8) < 0.15 and abs(v - 1.5) < 0.1 for r, v, *_ in rows[len(rows) // 2:])  # last 2 s
    # Uncontrolled: the heading stays where it was.
    assert gcs.command(m.MAV_CMD_DO_ORBIT, NAN, NAN, 2, NAN, NAN, NAN, NAN).result == m.MAV_RESULT_ACCEPTED
    yaw1 = heading(gcs)
    rows = sample_orbit(gcs, centre, 4.0)
    assert all(angle_between(yaw, yaw1) < math.radians(3.0) for *_, yaw, _, _ in rows)
    # Another mode ends the orbit: hold, where it is.
    ack = gcs.command(m.MAV_CMD_DO_SET_MODE, CUSTOM, 4, 3)
    assert ack.result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: g.custom_mode == LOITER, 2.0, "AUTO.LOITER")
    wait_sim(gcs, 3.0)
    here = gcs.position()
    wait_sim(gcs, 2.0)
    assert math.dist(here, gcs.position()) < 0.1
    seen = gcs.last["ORBIT_EXECUTION_STATUS"]
    wait_sim(gcs, 1.0)
    assert gcs.last["ORBIT_EXECUTION_STATUS"] is seen  # no more once out of Orbit


def send_target(gcs: Gcs, north: float, east: float, alt: float, vel_ned=None, lat_e7=None) -> None:
    """FOLLOW_TARGET as MAVSDK's follow_me sends it (position, and the velocity when given)."""
    lat, lon = latlon_e7(north, east)
    caps = 1 | (2 if vel_ned is not None else 0)
    lat = lat if lat_e7 is None else lat_e7
    gcs.conn.mav.follow_target_send(int(gcs.sim_time * 1000), caps, lat, lon, alt,
                                    list(vel_ned or (0.0, 0.0, 0.0)), [0.0] * 3, [1.0, 0.0, 0.0, 0.0],
                                    [0.0] * 3, [0.0] * 3, 0)  # fmt: skip


def refused(stack, what: str) -> int:
    return sum(n for reason, n in stack.autopilot.refusals.by_reason.items() if what in reason)


@pytest.mark.timeout(240)
def test_follow_me_follows_a_moving_target_and_holds_when_it_is_lost(vehicle):
    stack, gcs = vehicle
    take_off(gcs, 3.0)
    assert param_set(gcs, "FLW_TGT_DST", 5.0).param_value == pytest.approx(5.0)
    assert param_set(gcs, "FLW_TGT_HT", 7.0).param_value == pytest.approx(8.0)  # below PX4's 8 m: refused
    # Hostile reports are refused at the edge and counted: latitude out of range, NaN altitude, a
    # target 5 km away (NAV_REF_MAX_DIST), a NaN velocity.
    send_target(gcs, 5.0, 0.0, 488.0, lat_e7=95 * 10**7)
    send_target(gcs, 5.0, 0.0, NAN)
    send_target(gcs, 5000.0, 0.0, 488.0)
    send_target(gcs, 5.0, 0.0, 488.0, vel_ned=(NAN, 0.0, 0.0))
    wait_sim(gcs, 0.1)
    assert refused(stack, "FOLLOW_TARGET refused") == 4
    # AUTO.FOLLOW_TARGET (MAVSDK's follow_me.start); without a target it holds where it is.
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, CUSTOM, 4, 8).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: g.custom_mode == FOLLOW, 2.0, "AUTO.FOLLOW_TARGET")
    here = gcs.position()
    wait_sim(gcs, 2.0)
    assert math.dist(here, gcs.position()) < 0.1
    # A target 5 m north walking east at 1 m/s, reported at 5 Hz with its velocity.
    t0 = gcs.sim_time
    sent = {"t": -1.0}

    def target_east(t: float) -> float:
        return 1.0 * (t - t0)

    def feed(g: Gcs) -> None:
        if g.sim_time - sent["t"] >= 0.2:
            send_target(g, 5.0, target_east(g.sim_time), 488.0, vel_ned=(0.0, 1.0, 0.0))
            sent["t"] = g.sim_time

    wait_sim(gcs, 25.0, feed=feed)
    said(gcs, "target found")
    errors = []

    def check(g: Gcs) -> None:
        feed(g)
        x, y, z = g.position()
        behind = frames.vector_from_ned((5.0, target_east(g.sim_time) - 5.0, -8.0))  # FLW_TGT_FA 180
        errors.append((math.hypot(x - behind[0], y - behind[1]), abs(z - 8.0),
                       angle_between(heading(g), frames.yaw_from_ned(math.pi / 2))))  # fmt: skip

    wait_sim(gcs, 5.0, feed=check)
    assert max(e[0] for e in errors) < 0.6  # FLW_TGT_DST behind the target
    assert max(e[1] for e in errors) < 0.3  # FLW_TGT_HT above home (FLW_TGT_ALT_M 0)
    assert max(e[2] for e in errors) < math.radians(10.0)  # facing the target
    # A hostile report amid the stream changes nothing.
    send_target(gcs, 5.0, 0.0, 488.0, lat_e7=-91 * 10**7)
    wait_sim(gcs, 1.0, feed=check)
    assert refused(stack, "FOLLOW_TARGET refused") == 5 and max(e[0] for e in errors[-400:]) < 0.6
    # The reports stop: after 3 s the target is lost; the vehicle stops and holds, still following.
    wait_sim(gcs, 3.5)
    said(gcs, "no target")
    wait_sim(gcs, 2.0)
    here = gcs.position()
    wait_sim(gcs, 4.0)
    assert math.dist(here, gcs.position()) < 0.1 and gcs.custom_mode == FOLLOW
    # Another mode ends it.
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, CUSTOM, 4, 5).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: g.custom_mode == FlightMode.AUTO_RTL.custom_mode, 2.0, "AUTO.RTL")
