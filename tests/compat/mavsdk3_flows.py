"""MAVSDK-Python 3 (the gRPC API: ``from mavsdk import System``) flows, written as a PX4 user writes
them from MAVSDK-Python's examples, flown in sequence against one running quadsitl vehicle.

usage: .venv-mavsdk3/bin/python tests/compat/mavsdk3_flows.py [URL]   (default udpin://0.0.0.0:14540)

Runs under MAVSDK-Python 3.15.3 only (its own venv, ``make .venv-mavsdk3``): ``System()`` starts
the bundled ``mavsdk_server``, which listens for gRPC on every interface, so the caller runs this
script and the vehicle inside a loopback-only network namespace (test_mavsdk3.py). The script has
no quadsitl import: it is what a user's script would be, unchanged against PX4 SITL.

One JSON object per line on stdout (``{"event": ..., "t": wall s, ...}``), the last ``done`` or
``error``; steps: telemetry, params, geofence_example, geofence, plan_import (QGC .plan with rally
points), mission (gimbal and camera items), goto, offboard (position, velocity), mission_raw,
manual_control, land, manual_control_example.

``geofence_example`` and ``manual_control_example`` are MAVSDK-Python's ``examples/geofence.py`` and
``examples/manual_control.py`` (tag 3.15.3), call for call with their values (the example files are
not copied here): the geofence of a polygon about home plus ``Circle(Point(0, 0), 0)``, the
example's way of saying "no circle"; one stick input, arm, takeoff, 5 s, one input,
``start_position_control``, then the example's random inputs at 10 Hz (seeded here, so a failure
can be replayed; the example loops forever, this runs it for 6 s), after which the sticks stop.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import random
import sys
import time
import traceback

from mavsdk import System
from mavsdk.geofence import Circle, FenceType, GeofenceData, Point, Polygon
from mavsdk.mission import MissionItem, MissionPlan
from mavsdk.mission_raw import MissionItem as RawItem
from mavsdk.offboard import PositionNedYaw, VelocityNedYaw

T0 = time.monotonic()
HOME_LAT, HOME_LON = 47.397742, 8.545594  # PX4 SITL's default home (quadsitl's too)
M_PER_DEG_LAT = 111_195.0


def emit(event: str, **data) -> None:
    print(json.dumps({"event": event, "t": round(time.monotonic() - T0, 3), **data}), flush=True)


def offset(north_m: float, east_m: float) -> tuple[float, float]:
    """Latitude, longitude of a point north/east of home (small offsets)."""
    lat = HOME_LAT + north_m / M_PER_DEG_LAT
    lon = HOME_LON + east_m / (M_PER_DEG_LAT * math.cos(math.radians(HOME_LAT)))
    return lat, lon


async def first(generator, predicate=lambda _: True, timeout_s: float = 30.0):
    async def scan():
        async for value in generator:
            if predicate(value):
                return value

    return await asyncio.wait_for(scan(), timeout_s)


async def wait_near(drone: System, north: float, east: float, down: float, within: float, timeout_s: float):
    def near(pv) -> bool:
        p = pv.position
        return math.dist((p.north_m, p.east_m, p.down_m), (north, east, down)) < within

    return await first(drone.telemetry.position_velocity_ned(), near, timeout_s)


async def telemetry(drone: System) -> None:
    ready = lambda h: h.is_global_position_ok and h.is_home_position_ok  # noqa: E731
    health = await first(drone.telemetry.health(), ready)
    position = await first(drone.telemetry.position())
    battery = await first(drone.telemetry.battery())
    mode = await first(drone.telemetry.flight_mode())
    emit("telemetry", local_ok=health.is_local_position_ok, lat=position.latitude_deg,
         lon=position.longitude_deg, abs_alt=position.absolute_altitude_m, battery=battery.remaining_percent,
         mode=str(mode))  # fmt: skip


async def params(drone: System) -> None:
    all_params = await drone.param.get_all_params()
    names = [p.name for p in all_params.int_params] + [p.name for p in all_params.float_params]
    wanted = ("MPC_XY_VEL_MAX", "GF_ACTION", "NAV_ACC_RAD")
    emit("params", count=len(names), has=[n for n in wanted if n in names])


async def geofence_example(drone: System) -> None:
    """examples/geofence.py: a polygon 0.0001 deg about home and the "no circle" circle."""
    async for terrain_info in drone.telemetry.home():
        latitude = terrain_info.latitude_deg
        longitude = terrain_info.longitude_deg
        break
    await asyncio.sleep(1)
    p1 = Point(latitude - 0.0001, longitude - 0.0001)
    p2 = Point(latitude + 0.0001, longitude - 0.0001)
    p3 = Point(latitude + 0.0001, longitude + 0.0001)
    p4 = Point(latitude - 0.0001, longitude + 0.0001)
    polygon = Polygon([p1, p2, p3, p4], FenceType.INCLUSION)
    circle = Circle(Point(0, 0), 0, FenceType.INCLUSION)
    geofenceData = GeofenceData([polygon], [circle])  # noqa: N806 (the example's name)
    await drone.geofence.upload_geofence(geofenceData)
    downloaded = await drone.mission_raw.download_geofence()
    emit("geofence_example", uploaded=True, downloaded=len(downloaded),
         commands=[i.command for i in downloaded], radii=[i.param1 for i in downloaded])  # fmt: skip


# The example's stick inputs: [roll, pitch, throttle, yaw].
MANUAL_INPUTS = [[0, 0, 0.5, 0], [-1, 0, 0.5, 0], [1, 0, 0.5, 0], [0, -1, 0.5, 0], [0, 1, 0.5, 0],
                 [0, 0, 0.5, -1], [0, 0, 0.5, 1], [0, 0, 1, 0], [0, 0, 0, 0]]  # fmt: skip
EXAMPLE_INPUTS_S = 6.0


async def manual_control_example(drone: System) -> None:
    """examples/manual_control.py on the landed, disarmed vehicle (COM_RC_LOSS_T 2 s: see
    manual_control); then the sticks stop."""
    await drone.manual_control.set_manual_control_input(float(0), float(0), 0.5, float(0))
    await drone.action.arm()
    await drone.action.takeoff()
    await asyncio.sleep(5)
    await drone.manual_control.set_manual_control_input(float(0), float(0), 0.5, float(0))
    await drone.manual_control.start_position_control()
    modes, in_air = set(), set()

    async def watch(stream, seen: set, shown=str) -> None:
        async for value in stream:
            seen.add(shown(value))

    watchers = [asyncio.create_task(watch(drone.telemetry.flight_mode(), modes)),
                asyncio.create_task(watch(drone.telemetry.in_air(), in_air, bool))]  # fmt: skip
    rng = random.Random(3)  # the example draws unseeded
    end = time.monotonic() + EXAMPLE_INPUTS_S
    while time.monotonic() < end:
        input_list = MANUAL_INPUTS[rng.randint(0, len(MANUAL_INPUTS) - 1)]
        roll, pitch, throttle, yaw = (float(v) for v in input_list)
        await drone.manual_control.set_manual_control_input(pitch, roll, throttle, yaw)
        await asyncio.sleep(0.1)
    for task in watchers:
        task.cancel()
    emit("manual_control_example", modes=sorted(modes), in_air=sorted(in_air))
    # The sticks stop: manual control lost in POSCTL -> NAV_RCL_ACT (2, return), and it lands.
    returned = await first(drone.telemetry.flight_mode(), lambda m: str(m) == "RETURN_TO_LAUNCH", 10.0)
    await first(drone.telemetry.armed(), lambda armed: not armed, 90.0)
    emit("manual_control_lost", mode=str(returned), disarmed=True)


async def geofence(drone: System) -> None:
    corners = [offset(-100.0, -100.0), offset(100.0, -100.0), offset(100.0, 100.0), offset(-100.0, 100.0)]
    polygon = Polygon([Point(lat, lon) for lat, lon in corners], FenceType.INCLUSION)
    circle = Circle(Point(*offset(80.0, 80.0)), 5.0, FenceType.EXCLUSION)
    await drone.geofence.upload_geofence(GeofenceData([polygon], [circle]))
    downloaded = await drone.mission_raw.download_geofence()
    emit("geofence", uploaded=5, downloaded=len(downloaded), commands=[i.command for i in downloaded])


def qgc_plan() -> str:
    """A QGroundControl .plan with two waypoints and two rally points (as QGC writes one)."""
    def simple(seq, command, lat, lon, alt, params):
        return {"type": "SimpleItem", "autoContinue": True, "command": command, "doJumpId": seq + 1,
                "frame": 3, "params": [*params, lat, lon, alt], "AMSLAltAboveTerrain": None,
                "Altitude": alt, "AltitudeMode": 1}  # fmt: skip

    a, b = offset(4.0, 0.0), offset(4.0, 4.0)
    items = [simple(0, 16, *a, 5.0, [0, 0, 0, None]), simple(1, 16, *b, 5.0, [0, 0, 0, None])]
    rally = [[*offset(30.0, 0.0), 10.0], [*offset(-30.0, 10.0), 10.0]]
    plan = {
        "fileType": "Plan", "groundStation": "QGroundControl", "version": 1,
        "mission": {"cruiseSpeed": 15, "firmwareType": 12, "hoverSpeed": 5, "items": items,
                    "plannedHomePosition": [HOME_LAT, HOME_LON, 488.0], "vehicleType": 2, "version": 2},
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "rallyPoints": {"points": rally, "version": 2},
    }  # fmt: skip
    return json.dumps(plan)


async def plan_import(drone: System) -> None:
    data = await drone.mission_raw.import_qgroundcontrol_mission_from_string(qgc_plan())
    await drone.mission_raw.upload_mission(data.mission_items)
    await drone.mission_raw.upload_rally_points(data.rally_items)
    rally = await drone.mission_raw.download_rallypoints()
    emit("plan_import", mission=len(data.mission_items), rally=len(data.rally_items),
         rally_downloaded=len(rally))  # fmt: skip


async def takeoff(drone: System) -> None:
    await drone.action.set_takeoff_altitude(3.0)
    await drone.action.arm()
    await drone.action.takeoff()
    await first(drone.telemetry.position(), lambda p: p.relative_altitude_m > 2.8, 30.0)
    emit("takeoff", ok=True)


async def mission(drone: System) -> None:
    nan = float("nan")
    cam, act = MissionItem.CameraAction, MissionItem.VehicleAction
    spots = [
        (5.0, 0.0, -45.0, cam.TAKE_PHOTO),
        (5.0, 5.0, -90.0, cam.START_VIDEO),
        (0.0, 5.0, 0.0, cam.STOP_VIDEO),
    ]
    items = [
        MissionItem(*offset(n, e), 3.0, 3.0, False, pitch, 0.0, action, nan, nan, 1.0, nan, nan, act.NONE)
        for n, e, pitch, action in spots
    ]
    await drone.mission.set_return_to_launch_after_mission(False)
    await drone.mission.upload_mission(MissionPlan(items))
    await drone.mission.start_mission()
    progress = await first(drone.mission.mission_progress(), lambda p: p.current == p.total, 90.0)
    finished = await drone.mission.is_mission_finished()
    downloaded = await drone.mission_raw.download_mission()
    emit("mission", total=progress.total, finished=finished, raw_items=len(downloaded),
         commands=sorted({i.command for i in downloaded}))  # fmt: skip


async def goto(drone: System) -> None:
    position = await first(drone.telemetry.position())
    lat, lon = offset(-4.0, 2.0)
    await drone.action.goto_location(lat, lon, position.absolute_altitude_m, 90.0)
    await wait_near(drone, -4.0, 2.0, -position.relative_altitude_m, 0.3, 30.0)
    emit("goto", ok=True)


async def offboard(drone: System) -> None:
    pv = await first(drone.telemetry.position_velocity_ned())
    p = pv.position
    await drone.offboard.set_position_ned(PositionNedYaw(p.north_m, p.east_m, p.down_m, 0.0))
    await drone.offboard.start()
    await drone.offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -3.0, 0.0))
    await wait_near(drone, 0.0, 0.0, -3.0, 0.2, 30.0)
    await drone.offboard.set_velocity_ned(VelocityNedYaw(1.0, 0.0, 0.0, 0.0))
    moving = await first(drone.telemetry.position_velocity_ned(), lambda v: v.velocity.north_m_s > 0.9, 10.0)
    await drone.offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
    await asyncio.sleep(1.0)
    await drone.offboard.stop()
    emit("offboard", position_ok=True, velocity_north=moving.velocity.north_m_s)


async def mission_raw(drone: System) -> None:
    def waypoint(seq, north, east):
        lat, lon = offset(north, east)
        return RawItem(seq, 6, 16, int(seq == 0), 1, 0.0, 1.0, 0.0, float("nan"),
                       round(lat * 1e7), round(lon * 1e7), 3.0, 0)  # fmt: skip

    await drone.mission_raw.upload_mission([waypoint(0, 2.0, 0.0), waypoint(1, 2.0, 2.0)])
    await drone.mission_raw.start_mission()
    progress = await first(drone.mission_raw.mission_progress(), lambda p: p.current == p.total, 60.0)
    emit("mission_raw", total=progress.total)


async def manual_control(drone: System) -> None:
    # The vehicle runs at --speed 2: a 10 Hz (wall) joystick is 5 Hz of simulation time. The flow
    # sends no sticks while it awaits start_position_control's answer (a script would send them
    # from a task of its own), which on a loaded machine can take half a second of wall time: the
    # loss timeout is 2 s of simulation time (1 s of wall time; PX4's default is 0.5 s).
    await drone.param.set_param_float("COM_RC_LOSS_T", 2.0)
    for _ in range(5):
        await drone.manual_control.set_manual_control_input(0.0, 0.0, 0.5, 0.0)
        await asyncio.sleep(0.1)
    try:
        await drone.manual_control.start_position_control()
        outcome = "accepted"
    except Exception as exc:  # noqa: BLE001 (reported, the test decides)
        outcome = f"{type(exc).__name__}: {exc}"
    mode = await first(drone.telemetry.flight_mode())
    # The example's inputs: (pitch, roll, throttle, yaw) at 10 Hz; full pitch forward flies north.
    start = (await first(drone.telemetry.position_velocity_ned())).position
    for _ in range(20):
        await drone.manual_control.set_manual_control_input(1.0, 0.0, 0.5, 0.0)
        await asyncio.sleep(0.1)
    for _ in range(20):
        await drone.manual_control.set_manual_control_input(0.0, 0.0, 0.5, 0.0)
        await asyncio.sleep(0.1)
    end = (await first(drone.telemetry.position_velocity_ned())).position
    emit("manual_control", outcome=outcome, mode=str(mode), north_moved=end.north_m - start.north_m,
         east_moved=end.east_m - start.east_m)  # fmt: skip


async def land(drone: System) -> None:
    await drone.action.land()
    await first(drone.telemetry.armed(), lambda armed: not armed, 60.0)
    emit("land", disarmed=True)


async def main(url: str) -> None:
    drone = System()
    await drone.connect(system_address=url)
    await first(drone.core.connection_state(), lambda s: s.is_connected, 20.0)
    emit("connected")
    for step in (telemetry, params, geofence_example, geofence, plan_import, takeoff, mission, goto, offboard,
                 mission_raw, manual_control, land, manual_control_example):  # fmt: skip
        started = time.monotonic()
        try:
            await step(drone)
        except Exception as exc:  # noqa: BLE001 (reported as an event; the test decides)
            emit("step_error", step=step.__name__, error=f"{type(exc).__name__}: {exc}",
                 trace=traceback.format_exc()[-1500:])  # fmt: skip
            if step.__name__ in ("takeoff",):
                raise
        emit("step_time", step=step.__name__, wall_s=round(time.monotonic() - started, 2))
    emit("done")


if __name__ == "__main__":
    try:
        url = sys.argv[1] if len(sys.argv) > 1 else "udpin://0.0.0.0:14540"
        asyncio.run(asyncio.wait_for(main(url), 400))
    except BaseException as exc:  # noqa: BLE001
        emit("error", error=f"{type(exc).__name__}: {exc}")
        sys.stdout.flush()
        os._exit(1)
    sys.stdout.flush()
    os._exit(0)  # the gRPC server and its threads: no teardown wait
