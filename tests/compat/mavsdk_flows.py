"""MAVSDK-Python 4 scripts, written as a PX4 user would, flown against a running quadsitl vehicle.

usage: python tests/compat/mavsdk_flows.py FLOW URL [--param-gain NAME]
FLOW is one of: action, offboard, mission, params, logs, examples. URL is a MAVSDK connection
string such as ``udpin://0.0.0.0:14540`` (the vehicle sends its API stream there).

Each run prints one JSON object per line on stdout (``{"event": ..., "t": wall s, ...}``); the
pytest side (test_mavsdk.py) asserts on them. The last event is ``done`` or ``error``. MAVSDK's
own log lines also go to stdout; they never start with ``{``.

Rules that keep MAVSDK from hanging (see the project's MAVSDK notes): no plugin call is ever cut
shorter than MAVSDK's own timeout (our waits wrap only our own polling of the latest telemetry);
on an error the process leaves with ``os._exit`` instead of tearing the C++ core down with a call
still pending; and a watchdog ends a teardown that takes longer than TEARDOWN_S. The caller runs
this script under a hard timeout anyway.

The vehicle runs at a wall-clock speed factor (``quadsitl up --speed``): a wall-clock client like
this one must take the simulation time from the telemetry's timestamps when it paces a moving
setpoint (see :meth:`Watch.sim_time`), as it would against PX4 SITL with a speed-up factor.

What a PX4 user's MAVSDK-Python script meets with ``pip install mavsdk`` (4.x, the native binding,
what these tests use) instead of the gRPC package (``mavsdk<4``); nothing here is specific to
quadsitl, the same script runs against PX4 SITL:

==============================================  ================================================
``mavsdk<4`` / ``mavsdk-grpc``                   ``mavsdk>=4`` (``mavsdk.asyncio``)
==============================================  ================================================
``drone = System()``                            ``async with Mavsdk(Configuration.create_with_``
``await drone.connect(system_address=URL)``     ``component_type(ComponentType.GROUND_STATION))``
                                                ``as m: await m.add_any_connection(URL)``
``async for s in drone.core.connection_state()``  ``system = await m.first_autopilot(timeout_s=10)``
                                                (``None`` on timeout)
``drone.action.arm()``, ``drone.telemetry`` ...  ``ActionAsync(system).arm()``, ``TelemetryAsync``,
                                                ``OffboardAsync``, ``MissionAsync``, ``ParamAsync``
                                                from ``mavsdk.asyncio.plugins.<name>``
``async for h in drone.telemetry.health()``      ``async for h in telemetry.subscribe_health()``
                                                (``await telemetry.health()`` = latest value once)
``from mavsdk.offboard import PositionNedYaw``   ``from mavsdk.asyncio.plugins.offboard import ...``
                                                (``mavsdk.offboard`` raises ``LegacyModuleError``)
``udp://:14540``                                ``udpin://0.0.0.0:14540`` (``udp://`` still works,
                                                with a deprecation warning)
==============================================  ================================================

``from mavsdk import System; System()`` fails with a ``TypeError`` saying the same. Scripts that
must stay unchanged install ``mavsdk-grpc`` and write ``import mavsdk_grpc as mavsdk``, or pin
``mavsdk<4``. Errors keep their names (``ActionError``, ``ParamError``, ...). A parameter value
the vehicle refuses (out of range; PX4 itself does not range-check PARAM_SET) comes back from
MAVSDK as ``ParamError: TIMEOUT`` within a second: the vehicle echoes the unchanged value (and
says why in a STATUSTEXT), MAVSDK resends until its retries run out.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import random
import threading
import time
import traceback

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.failure import FailureAsync, FailureError, FailureType, FailureUnit
from mavsdk.asyncio.plugins.ftp import FtpAsync, FtpError
from mavsdk.asyncio.plugins.geofence import Circle, FenceType, GeofenceAsync, GeofenceData, Point, Polygon
from mavsdk.asyncio.plugins.log_files import LogFilesAsync, LogFilesError
from mavsdk.asyncio.plugins.manual_control import ManualControlAsync
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan
from mavsdk.asyncio.plugins.mission_raw import MissionItem as MissionItemRaw
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.asyncio.plugins.mocap import AngleBody, Covariance, MocapAsync, PositionBody
from mavsdk.asyncio.plugins.mocap import VisionPositionEstimate as MocapPose
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw, VelocityNedYaw
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.shell import Device, ShellAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

from quadcommon import frames

T0 = time.monotonic()
TEARDOWN_S = 10.0
POSE_ATTEMPTS = 12  # a Mocap pose sent once a second until the vehicle answers it (12 s of wall time)


class FlowError(AssertionError):
    pass


def emit(event: str, **data) -> None:
    """One JSON line on stdout (NaN and enums made JSON-safe)."""
    data = {k: _plain(v) for k, v in data.items()}
    print(json.dumps({"event": event, "t": round(time.monotonic() - T0, 3), **data}), flush=True)


def _plain(value):
    if isinstance(value, float):
        return None if not math.isfinite(value) else round(value, 9)  # lat/lon need 1e-7 deg
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if hasattr(value, "name") and hasattr(value, "value"):  # enum
        return value.name
    return value


class Watch:
    """Telemetry subscriptions pumped in the background; the latest value of each, and the
    history of the discrete ones (armed, flight mode, in air, landed state)."""

    STREAMS = (
        "position_velocity_ned",
        "attitude_euler",
        "armed",
        "flight_mode",
        "in_air",
        "landed_state",
        "health",
        "status_text",
    )
    DISCRETE = ("armed", "flight_mode", "in_air", "landed_state")

    def __init__(self, telemetry: TelemetryAsync) -> None:
        self.telemetry = telemetry
        self.latest: dict[str, object] = {}
        self.counts = dict.fromkeys(self.STREAMS, 0)
        self.history: dict[str, list] = {k: [] for k in self.DISCRETE}
        self.positions: list[tuple[float, float, float, float]] = []  # (sim t, n, e, d)
        self.texts: list[str] = []  # STATUSTEXT, in order
        self._tasks: list[asyncio.Task] = []

    def start(self) -> None:
        for name in self.STREAMS:
            generator = getattr(self.telemetry, f"subscribe_{name}")()
            self._tasks.append(asyncio.create_task(self._pump(name, generator)))

    async def _pump(self, name: str, generator) -> None:
        async for value in generator:
            self.latest[name] = value
            self.counts[name] += 1
            if name in self.DISCRETE:
                shown = _plain(value)
                if not self.history[name] or self.history[name][-1][1] != shown:
                    self.history[name].append((round(time.monotonic() - T0, 3), shown))
            elif name == "status_text":
                self.texts.append(value.text)
            elif name == "position_velocity_ned":
                p = value.position
                self.positions.append((self.sim_time(), p.north_m, p.east_m, p.down_m))

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    # -- reading ---------------------------------------------------------------------------------------
    def sim_time(self) -> float:
        """The vehicle's clock (s): the newest ATTITUDE timestamp (time_boot_ms is simulation time)."""
        att = self.latest.get("attitude_euler")
        return att.timestamp_us * 1e-6 if att is not None else 0.0

    def ned(self) -> tuple[float, float, float]:
        p = self.latest["position_velocity_ned"].position
        return (p.north_m, p.east_m, p.down_m)

    def velocity(self) -> tuple[float, float, float]:
        v = self.latest["position_velocity_ned"].velocity
        return (v.north_m_s, v.east_m_s, v.down_m_s)

    def mode(self) -> str:
        return _plain(self.latest.get("flight_mode"))

    def snapshot(self) -> dict:
        out: dict[str, object] = {"counts": dict(self.counts), "sim_t": self.sim_time()}
        if "position_velocity_ned" in self.latest:
            out["ned"] = self.ned()
            out["vel"] = self.velocity()
        if "attitude_euler" in self.latest:
            a = self.latest["attitude_euler"]
            out["euler_deg"] = (a.roll_deg, a.pitch_deg, a.yaw_deg)
        for name in self.DISCRETE:
            if name in self.latest:
                out[name] = _plain(self.latest[name])
        if "health" in self.latest:
            out["health"] = _health(self.latest["health"])
        return out

    async def until(self, what: str, predicate, timeout_s: float) -> float:
        """Poll our own copy of the telemetry until ``predicate(self)``; returns the wall time taken."""
        start = time.monotonic()
        while time.monotonic() - start < timeout_s:
            try:
                if predicate(self):
                    return time.monotonic() - start
            except KeyError:
                pass  # that stream has not delivered yet
            await asyncio.sleep(0.02)
        raise FlowError(f"timed out after {timeout_s} s waiting for {what}; now {self.snapshot()}")

    async def sim_sleep(self, seconds: float, timeout_s: float = 30.0) -> None:
        """Wait ``seconds`` of simulation time."""
        end = self.sim_time() + seconds
        await self.until(f"{seconds} s of simulation time", lambda w: w.sim_time() >= end, timeout_s)


def _health(h) -> dict:
    names = (
        "is_gyrometer_calibration_ok",
        "is_accelerometer_calibration_ok",
        "is_magnetometer_calibration_ok",
        "is_local_position_ok",
        "is_global_position_ok",
        "is_home_position_ok",
        "is_armable",
    )
    return {n: bool(getattr(h, n)) for n in names}


def distance(a, b) -> float:
    return math.dist(a, b)


# -- the pieces every flow shares --------------------------------------------------------------------------
async def connect(mavsdk: Mavsdk, url: str):
    await mavsdk.add_any_connection(url)
    start = time.monotonic()
    system = await mavsdk.first_autopilot(timeout_s=10.0)
    if system is None:
        raise FlowError(f"no autopilot discovered on {url} within 10 s")
    emit(
        "discovered",
        after_s=time.monotonic() - start,
        sysid=await system.get_system_id(),
        autopilot=_plain(await system.autopilot_type()),
        vehicle=_plain(await system.vehicle_type()),
        components=await system.component_ids(),
    )
    return system


async def ready(watch: Watch) -> None:
    """Health all true (armable included), as a PX4 script checks before arming."""
    waited = await watch.until(
        "health all ok and armable",
        lambda w: all(_health(w.latest["health"]).values()) and "position_velocity_ned" in w.latest,
        15.0,
    )
    emit("healthy", after_s=waited, **watch.snapshot())


async def take_off(action: ActionAsync, watch: Watch, altitude_m: float) -> None:
    await action.arm()
    await watch.until("armed", lambda w: w.latest["armed"] is True, 5.0)
    emit("armed", **watch.snapshot())
    await action.takeoff()
    await watch.until("in air", lambda w: w.latest["in_air"] is True, 10.0)
    emit("in_air", **watch.snapshot())
    await watch.until(
        f"takeoff to {altitude_m} m done (HOLD)",
        lambda w: w.mode() == "HOLD" and abs(-w.ned()[2] - altitude_m) < 0.05,
        20.0,
    )
    await watch.sim_sleep(1.0)
    emit("took_off", **watch.snapshot())


async def land_and_disarm(action: ActionAsync, watch: Watch) -> None:
    await action.land()
    await watch.until("LAND mode", lambda w: w.mode() == "LAND", 5.0)
    emit("landing", **watch.snapshot())
    await watch.until("on the ground", lambda w: w.latest["in_air"] is False, 30.0)
    emit("landed", **watch.snapshot())
    try:
        await action.disarm()  # PX4 also disarms by itself after COM_DISARM_LAND: either is fine
    except Exception as exc:
        emit("disarm_refused", error=str(exc))
    await watch.until("disarmed", lambda w: w.latest["armed"] is False, 10.0)
    emit("disarmed", **watch.snapshot())


# -- flows ---------------------------------------------------------------------------------------------
async def flow_action(system, args) -> None:
    """Discovery, health, telemetry at rest; arm -> takeoff -> land -> disarm."""
    tel, action = TelemetryAsync(system), ActionAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        emit("home", home=_position(await tel.home()))
        await watch.sim_sleep(1.0)
        emit("at_rest", **watch.snapshot())
        await streams_on_request(system, tel, watch)
        await take_off(action, watch, 2.5)  # NaN altitude: the vehicle's MIS_TAKEOFF_ALT (2.5 m)
        emit("position", position=_position(await tel.position()))
        await land_and_disarm(action, watch)
        emit("history", **watch.history)
    finally:
        await watch.stop()


async def streams_on_request(system, tel: TelemetryAsync, watch: Watch) -> None:
    """What a PX4 user asks for beside the default streams: the ground truth and the IMU at a
    rate (set_rate_ground_truth 10 Hz, set_rate_imu 50 Hz; 2 s of each, on the vehicle's clock),
    and a Mocap pose (this vehicle flies on the simulator's truth, EKF2_EN 0: it refuses the pose
    and says why)."""
    await tel.set_rate_ground_truth(10.0)
    await tel.set_rate_imu(50.0)
    got: dict[str, list] = {"ground_truth": [], "imu": []}

    async def pump(name: str) -> None:
        async for value in getattr(tel, f"subscribe_{name}")():
            # The IMU carries its own stamp (HIGHRES_IMU.time_usec, the vehicle's clock); the ground
            # truth has none, so it is stamped at arrival, which a loaded machine can bunch.
            stamp = value.timestamp_us * 1e-6 if name == "imu" else watch.sim_time()
            got[name].append((stamp, value))

    tasks = [asyncio.create_task(pump(name)) for name in got]
    start = watch.sim_time()
    await watch.sim_sleep(2.0)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    window = (start + 0.5, start + 1.5)  # one second of simulation, away from the subscriptions' start
    counts = {name: sum(window[0] <= t < window[1] for t, _ in values) for name, values in got.items()}
    truth, imu = got["ground_truth"][-1][1], got["imu"][-1][1]
    pose = MocapPose(0, PositionBody(0.0, 0.0, 0.0), AngleBody(0.0, 0.0, 0.0), Covariance([math.nan]))
    # Sent again each second until answered: over a lossy link the pose or the answer can be lost,
    # and the vehicle says a refusal's reason again only after 10 s (vision_in.ANNOUNCE_EVERY_S).
    answered = lambda w: any("vision refused" in t for t in w.texts)  # noqa: E731
    for attempt in range(POSE_ATTEMPTS):
        await MocapAsync(system).set_vision_position_estimate(pose)
        try:
            await watch.until("the Mocap pose answered", answered, 1.0)
            break
        except FlowError:
            if attempt == POSE_ATTEMPTS - 1:
                raise
    a, g, mag = imu.acceleration_frd, imu.angular_velocity_frd, imu.magnetic_field_frd
    emit("streams", counts=counts,
         ground_truth=(truth.latitude_deg, truth.longitude_deg, truth.absolute_altitude_m),
         imu_acceleration=(a.forward_m_s2, a.right_m_s2, a.down_m_s2),
         imu_rates=(g.forward_rad_s, g.right_rad_s, g.down_rad_s),
         imu_field=(mag.forward_gauss, mag.right_gauss, mag.down_gauss),
         imu_temperature=imu.temperature_degc,
         vision=[t for t in watch.texts if "vision" in t])  # fmt: skip


async def flow_offboard(system, args) -> None:
    """Offboard position setpoints, then a position + velocity ramp; start and stop."""
    tel, action, offboard = TelemetryAsync(system), ActionAsync(system), OffboardAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        await take_off(action, watch, 2.5)
        n, e, d = watch.ned()
        await offboard.set_position_ned(PositionNedYaw(n, e, d, 0.0))  # PX4: a setpoint before start()
        await offboard.start()
        await watch.until("OFFBOARD", lambda w: w.mode() == "OFFBOARD", 5.0)
        emit("offboard_started", active=await offboard.is_active(), **watch.snapshot())

        target = (2.0, 1.0, -3.0)
        await offboard.set_position_ned(PositionNedYaw(*target, 30.0))
        took = await watch.until(f"position {target}", lambda w: distance(w.ned(), target) < 0.05, 20.0)
        await watch.sim_sleep(1.5)
        emit("reached_position", target=target, yaw_target_deg=30.0, after_s=took, **watch.snapshot())

        # A straight line at 1 m/s (simulation time) with the velocity as feed-forward.
        speed, length = 1.0, 3.0
        start_ned, t_start = watch.ned(), watch.sim_time()
        errors = []
        while True:
            s = min((watch.sim_time() - t_start) * speed, length)
            p = (target[0] - s, target[1], target[2])
            v = (-speed if s < length else 0.0, 0.0, 0.0)
            await offboard.set_position_velocity_ned(PositionNedYaw(*p, 30.0), VelocityNedYaw(*v, 30.0))
            if s > 0.5:
                errors.append(distance(watch.ned(), p))
            if s >= length:
                break
            await asyncio.sleep(0.05)
        line_end = (target[0] - length, target[1], target[2])
        await watch.until(
            "at rest at the end of the line",
            lambda w: distance(w.ned(), line_end) < 0.05 and math.hypot(*w.velocity()) < 0.05,
            10.0,
        )
        emit("line_done", start=start_ned, end=line_end, max_tracking_error_m=max(errors),
             samples=len(errors), **watch.snapshot())  # fmt: skip

        await offboard.stop()  # PX4: switches to Hold
        await watch.until("HOLD after offboard stop", lambda w: w.mode() == "HOLD", 5.0)
        held = watch.ned()
        await watch.sim_sleep(2.0)
        emit("offboard_stopped", active=await offboard.is_active(), held=held,
             drift_m=distance(watch.ned(), held), **watch.snapshot())  # fmt: skip
        await land_and_disarm(action, watch)
    finally:
        await watch.stop()


def _waypoints(home_lat: float, home_lon: float) -> list[tuple[float, float, float]]:
    """(north, east, relative altitude) of the mission's waypoints (m)."""
    return [(3.0, 0.0, 3.0), (3.0, 3.0, 3.0), (0.0, 3.0, 3.5)]


CAMERA_ACTIONS = (
    MissionItem.CameraAction.TAKE_PHOTO,
    MissionItem.CameraAction.START_VIDEO,
    MissionItem.CameraAction.STOP_VIDEO,
)


async def flow_mission(system, args) -> None:
    """Upload, download, start, progress to finished; then return to launch (lands, disarms)."""
    tel, action, mission = TelemetryAsync(system), ActionAsync(system), MissionAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        home = await tel.home()
        origin = (home.latitude_deg, home.longitude_deg, home.absolute_altitude_m)
        nan = float("nan")
        items, targets = [], []
        for k, (north, east, alt) in enumerate(_waypoints(*origin[:2])):
            lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, origin)
            items.append(
                MissionItem(
                    latitude_deg=lat,
                    longitude_deg=lon,
                    relative_altitude_m=alt,
                    speed_m_s=1.5 if k == 1 else nan,  # adds a DO_CHANGE_SPEED item
                    is_fly_through=False,
                    # MAVSDK's mission example: gimbal angles and camera actions (gimbal manager and
                    # capture items; the vehicle has neither and flies them as no-ops, as PX4)
                    gimbal_pitch_deg=-45.0 if k == 0 else nan,
                    gimbal_yaw_deg=0.0 if k == 0 else nan,
                    camera_action=CAMERA_ACTIONS[k],
                    loiter_time_s=1.0 if k == 2 else nan,  # adds a NAV_DELAY item
                    camera_photo_interval_s=nan,
                    acceptance_radius_m=0.3,
                    yaw_deg=nan,
                    camera_photo_distance_m=nan,
                    vehicle_action=MissionItem.VehicleAction.NONE,
                )
            )
            targets.append((north, east, -alt))
        await mission.upload_mission(MissionPlan(items))
        emit("uploaded", count=len(items))
        plan = await mission.download_mission()
        emit("downloaded", items=[_item(i) for i in plan.mission_items], sent=[_item(i) for i in items])

        await action.arm()
        await mission.start_mission()
        emit("started", **watch.snapshot())
        progress: list[tuple[int, int]] = []
        start = time.monotonic()
        finished = False
        while not finished and time.monotonic() - start < 40.0:
            # Ask "finished?" before reading the progress, so the last progress read comes after
            # the answer: the mission can finish between the two calls.
            finished = await mission.is_mission_finished()
            p = await mission.mission_progress()
            if not progress or progress[-1] != (p.current, p.total):
                progress.append((p.current, p.total))
            if not finished:
                await asyncio.sleep(0.1)
        closest = [
            min(distance(q[1:], t) for q in watch.positions) if watch.positions else None for t in targets
        ]
        emit("mission_end", finished=finished, progress=progress, targets=targets,
             closest_m=closest, **watch.snapshot())  # fmt: skip
        if not finished:
            raise FlowError(f"mission not finished after 40 s; progress {progress}")

        await action.return_to_launch()
        await watch.until("RTL", lambda w: w.mode() == "RETURN_TO_LAUNCH", 5.0)
        await watch.until("landed by RTL", lambda w: w.latest["in_air"] is False, 40.0)
        await watch.until("disarmed after RTL", lambda w: w.latest["armed"] is False, 15.0)
        emit("returned", **watch.snapshot())
        emit("history", **watch.history)
    finally:
        await watch.stop()


async def flow_params(system, args) -> None:
    """Get/set with PX4's encodings; MIS_TAKEOFF_ALT changes the takeoff, a gain changes the flight."""
    tel, action, param = TelemetryAsync(system), ActionAsync(system), ParamAsync(system)
    offboard = OffboardAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        emit("sysid_param", value=await param.get_param_int("MAV_SYS_ID"), sysid=await system.get_system_id())
        before = await param.get_param_float("MIS_TAKEOFF_ALT")
        await param.set_param_float("MIS_TAKEOFF_ALT", 4.0)
        after = await param.get_param_float("MIS_TAKEOFF_ALT")
        await action.set_takeoff_altitude(4.0)  # the Action plugin's way: the same parameter
        emit("takeoff_alt", before=before, after=after, action_reads=await action.get_takeoff_altitude())

        every = await param.get_all_params()
        names = sorted([p.name for p in every.float_params] + [p.name for p in every.int_params])
        emit("all_params", count=len(names), names=names,
             ints={p.name: p.value for p in every.int_params})  # fmt: skip

        # Refusals come back as errors, not silence.
        try:
            await param.set_param_float("MIS_TAKEOFF_ALT", 5000.0)
            emit("out_of_range", error=None)
        except Exception as exc:
            emit("out_of_range", error=str(exc), kept=await param.get_param_float("MIS_TAKEOFF_ALT"))

        await take_off(action, watch, 4.0)
        if args.param_gain:
            await step_with_gain(param, offboard, watch, args.param_gain, args.gain_factor)
        await land_and_disarm(action, watch)
    finally:
        await watch.stop()


async def step_with_gain(param, offboard, watch: Watch, name: str, factor: float) -> None:
    """A 1 m offboard step north with the gain as it is, then with the gain times ``factor``; the
    responses (position samples over 3 s of simulation time) go to the caller to compare."""
    n, e, d = watch.ned()
    await offboard.set_position_ned(PositionNedYaw(n, e, d, 0.0))
    await offboard.start()
    await watch.until("OFFBOARD", lambda w: w.mode() == "OFFBOARD", 5.0)
    original = await param.get_param_float(name)
    for label, value, goal in (("default", original, n + 1.0), ("changed", original * factor, n)):
        if value != original:
            await param.set_param_float(name, value)
            emit("gain_set", name=name, value=await param.get_param_float(name))
        start_n, t0 = watch.ned()[0], watch.sim_time()
        mark = len(watch.positions)
        await offboard.set_position_ned(PositionNedYaw(goal, e, d, 0.0))
        await watch.sim_sleep(3.0)
        response = [(t - t0, abs(q_n - start_n)) for t, q_n, _, _ in watch.positions[mark:] if t >= t0]
        emit("step", label=label, gain=value, start_n=start_n, goal_n=goal, t0=t0, t1=watch.sim_time(),
             response=response[::3])  # fmt: skip
    await offboard.stop()
    await watch.until("HOLD", lambda w: w.mode() == "HOLD", 5.0)


def _position(p) -> dict:
    return {k: getattr(p, k) for k in ("latitude_deg", "longitude_deg", "absolute_altitude_m",
                                       "relative_altitude_m")}  # fmt: skip


def _item(i: MissionItem) -> dict:
    return {
        "gimbal_pitch": i.gimbal_pitch_deg,
        "camera": i.camera_action.name,
        "lat": i.latitude_deg,
        "lon": i.longitude_deg,
        "alt": i.relative_altitude_m,
        "speed": i.speed_m_s,
        "fly_through": i.is_fly_through,
        "loiter_s": i.loiter_time_s,
        "acceptance_m": i.acceptance_radius_m,
    }


async def flow_logs(system, args) -> None:
    """A PX4 user's log download with the log_files plugin: list the vehicle's logs and download
    each; arm and disarm (one more log, from arming to disarming), list and download it; erase."""
    logs = LogFilesAsync(system)

    async def listing(event: str):
        entries = await logs.get_entries()
        emit(event, entries=[{"id": e.id, "date": e.date, "size": e.size_bytes} for e in entries])
        return entries

    async def download(entry) -> None:
        path = os.path.join(args.out, f"{entry.id}.ulg")
        progress = [data.progress async for _, data in logs.download_log_file(entry, path)]
        emit("downloaded", id=entry.id, path=path, updates=len(progress), last=progress[-1])

    for entry in await listing("entries"):
        await download(entry)
    tel, action = TelemetryAsync(system), ActionAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        await action.arm()
        await watch.sim_sleep(1.0)
        await action.disarm()
        await watch.until("disarmed", lambda w: w.latest["armed"] is False, 5.0)
    finally:
        await watch.stop()
    entries = await listing("entries_after_flight")
    await download(entries[-1])
    await ftp_files(system, args)
    await shell_commands(system)
    await logs.erase_all_log_files()  # LOG_ERASE has no answer: listing again shows what it did
    try:
        left = await logs.get_entries()
        emit("after_erase", entries=len(left))
    except LogFilesError as exc:
        emit("after_erase", error=exc.result.name)


async def ftp_files(system, args) -> None:
    """MAVSDK's Ftp plugin as against PX4 SITL: list the root and the log directory (PX4 SITL's
    layout, /log/DATE/TIME.ulg), download the newest log with bursts and with plain reads, compare
    it by CRC, and try a path outside the root."""
    ftp = FtpAsync(system)

    def described(data) -> list:
        return sorted([e.name, e.entry_type.name, e.size_bytes] for e in data.entries)

    root = await ftp.list_directory("/")
    emit("ftp_root", entries=described(root))
    days = await ftp.list_directory("/log")
    listing = {}
    for day in (e.name for e in days.entries if e.entry_type.name == "DIRECTORY"):
        listing[day] = described(await ftp.list_directory(f"/log/{day}"))
    emit("ftp_logs", days=listing)
    day = max(listing)
    newest = f"/log/{day}/{max(name for name, kind, _ in listing[day] if kind == 'FILE')}"
    for burst in (True, False):
        folder = os.path.join(args.out, "ftp_burst" if burst else "ftp_plain")
        os.makedirs(folder, exist_ok=True)
        started = time.monotonic()
        updates = [(result.name, data.bytes_transferred, data.total_bytes)
                   async for result, data in ftp.download(newest, folder, burst)]  # fmt: skip
        local = os.path.join(folder, os.path.basename(newest))
        identical = await ftp.are_files_identical(local, newest)  # CalcFileCRC32
        progress = max(((done, total) for _, done, total in updates), default=(0, 0))  # (the end: zeros)
        wall_s = round(time.monotonic() - started, 3)
        emit("ftp_download", remote=newest, local=local, burst=burst, result=updates[-1][0],
             progress=list(progress), identical=identical, wall_s=wall_s)  # fmt: skip
    try:
        await ftp.list_directory("/..")
        emit("ftp_outside", error=None)
    except FtpError as exc:
        emit("ftp_outside", error=exc.result.name)


SHELL_COMMANDS = ("ver all", "param show MPC_TKO_SPEED", "commander status", "listener vehicle_status")


async def shell_commands(system) -> None:
    """MAVSDK's Shell plugin (QGC's MAVLink Console does the same): subscribe, then send each
    command; what comes back up to the prompt after it."""
    shell = ShellAsync(system)
    received: list[str] = []

    async def collect() -> None:
        async for chunk in shell.subscribe_receive():
            received.append(chunk if isinstance(chunk, str) else getattr(chunk, "data", str(chunk)))

    task = asyncio.create_task(collect())
    await asyncio.sleep(0.2)
    outputs = {}
    try:
        for command in SHELL_COMMANDS:
            received.clear()
            await shell.send(command, Device.SHELL)
            end = time.monotonic() + 5.0
            while time.monotonic() < end and not "".join(received).rstrip().endswith("nsh>"):
                await asyncio.sleep(0.05)
            outputs[command] = "".join(received)
    finally:
        task.cancel()
    emit("shell", outputs=outputs)


# MAVSDK-Python's examples/manual_control.py stick inputs: [roll, pitch, throttle, yaw].
MANUAL_INPUTS = [[0, 0, 0.5, 0], [-1, 0, 0.5, 0], [1, 0, 0.5, 0], [0, -1, 0.5, 0], [0, 1, 0.5, 0],
                 [0, 0, 0.5, -1], [0, 0, 0.5, 1], [0, 0, 1, 0], [0, 0, 0, 0]]  # fmt: skip
EXAMPLE_INPUTS_S = 6.0


async def flow_examples(system, args) -> None:
    """MAVSDK-Python's examples/geofence.py and examples/manual_control.py, call for call in the
    native API (they exist for the gRPC API only): the polygon about home with the "no circle"
    Circle(Point(0, 0), 0); then one stick input, arm, takeoff, 5 s, one input,
    start_position_control and the example's random inputs at 10 Hz (seeded; 6 s of its endless
    loop), after which the sticks stop: manual control lost, NAV_RCL_ACT returns and lands.

    MAVSDK 4's Geofence plugin refuses a circle of radius <= 0 itself (GeofenceError
    INVALID_ARGUMENT; nothing is sent), so the example's upload cannot succeed with it whatever the
    vehicle; the same items (what MAVSDK-Python 3 sends) then go through MissionRaw."""
    tel, action, param = TelemetryAsync(system), ActionAsync(system), ParamAsync(system)
    geofence, manual = GeofenceAsync(system), ManualControlAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        async for terrain_info in tel.subscribe_home():  # the example reads the first home
            latitude, longitude = terrain_info.latitude_deg, terrain_info.longitude_deg
            break
        await asyncio.sleep(1)
        p1 = Point(latitude - 0.0001, longitude - 0.0001)
        p2 = Point(latitude + 0.0001, longitude - 0.0001)
        p3 = Point(latitude + 0.0001, longitude + 0.0001)
        p4 = Point(latitude - 0.0001, longitude + 0.0001)
        polygon = Polygon([p1, p2, p3, p4], FenceType.INCLUSION)
        circle = Circle(Point(0, 0), 0, FenceType.INCLUSION)
        try:
            await geofence.upload_geofence(GeofenceData([polygon], [circle]))
            refused_by_mavsdk = None
        except Exception as exc:  # noqa: BLE001 (reported; the test decides)
            refused_by_mavsdk = str(exc).split(";")[0]
            items = [
                MissionItemRaw(k, 5, 5001, int(k == 0), 0, 4.0, 0.0, 0.0, 0.0, round(p.latitude_deg * 1e7),
                               round(p.longitude_deg * 1e7), 0.0, 1)
                for k, p in enumerate((p1, p2, p3, p4))
            ]  # fmt: skip
            items.append(MissionItemRaw(4, 5, 5003, 0, 0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0, 1))
            await MissionRawAsync(system).upload_geofence(items)
        back = await geofence.download_geofence()
        await watch.sim_sleep(0.5)
        emit("geofence_example", refused_by_mavsdk=refused_by_mavsdk,
             polygons=[len(p.points) for p in back.polygons], circles=[c.radius for c in back.circles],
             texts=list(watch.texts))  # fmt: skip
        await geofence.clear_geofence()  # (the sticks below may wander past the example's 8 m)

        # The vehicle runs at --speed 2: the example's 10 Hz (wall) is 5 Hz of simulation time, so
        # the loss timeout is doubled to keep PX4's margin of a real-time vehicle (5 samples).
        await param.set_param_float("COM_RC_LOSS_T", 1.0)
        await manual.set_manual_control_input(0.0, 0.0, 0.5, 0.0)
        await action.arm()
        await action.takeoff()
        await asyncio.sleep(5)
        await manual.set_manual_control_input(0.0, 0.0, 0.5, 0.0)
        await manual.start_position_control()
        modes_from = len(watch.history["flight_mode"])
        rng = random.Random(3)  # the example draws unseeded
        end = time.monotonic() + EXAMPLE_INPUTS_S
        ground = False
        while time.monotonic() < end:
            input_list = MANUAL_INPUTS[rng.randint(0, len(MANUAL_INPUTS) - 1)]
            roll, pitch, throttle, yaw = (float(v) for v in input_list)
            await manual.set_manual_control_input(pitch, roll, throttle, yaw)
            await asyncio.sleep(0.1)
            ground = ground or watch.latest["in_air"] is False
        modes = sorted({m for _, m in watch.history["flight_mode"][modes_from:]} | {watch.mode()})
        emit("manual_control_example", modes=modes, touched_ground=ground, **watch.snapshot())
        await watch.until("RTL after the sticks stop", lambda w: w.mode() == "RETURN_TO_LAUNCH", 10.0)
        await watch.until("landed and disarmed", lambda w: w.latest["armed"] is False, 60.0)
        emit("manual_control_lost", texts=list(watch.texts), **watch.snapshot())
        emit("history", **watch.history)
    finally:
        await watch.stop()


async def flow_failure(system, args) -> None:
    """The Failure plugin as a PX4 user drives it: GPS off refused while SYS_FAILURE_EN is 0, then
    enabled, a one-waypoint mission, GPS off in it; the vehicle's answer until it is disarmed."""
    tel, action, mission = TelemetryAsync(system), ActionAsync(system), MissionAsync(system)
    failure, param = FailureAsync(system), ParamAsync(system)
    watch = Watch(tel)
    watch.start()
    try:
        await ready(watch)
        try:
            await failure.inject(FailureUnit.SENSOR_GPS, FailureType.OFF, 0)
            raise FlowError("GPS off accepted with SYS_FAILURE_EN 0")
        except FailureError as error:
            emit("refused", result=error.result.name)
        await param.set_param_int("SYS_FAILURE_EN", 1)
        home = await tel.home()
        lat, lon, _ = frames.ned_to_geodetic(30.0, 0.0, 0.0, (home.latitude_deg, home.longitude_deg, 0.0))
        nan = float("nan")
        item = MissionItem(
            latitude_deg=lat, longitude_deg=lon, relative_altitude_m=3.0, speed_m_s=nan, is_fly_through=False,
            gimbal_pitch_deg=nan, gimbal_yaw_deg=nan, camera_action=MissionItem.CameraAction.NONE,
            loiter_time_s=nan, camera_photo_interval_s=nan, acceptance_radius_m=1.0, yaw_deg=nan,
            camera_photo_distance_m=nan, vehicle_action=MissionItem.VehicleAction.NONE,
        )  # fmt: skip
        await mission.upload_mission(MissionPlan([item]))
        await action.arm()
        await mission.start_mission()
        await watch.until("in the mission at 2 m", lambda w: w.mode() == "MISSION"
                          and -w.latest["position_velocity_ned"].position.down_m > 2.0, 20.0)  # fmt: skip
        # MAVSDK's plugin reads SYS_FAILURE_EN when it starts: a new one sees the value just set
        await FailureAsync(system).inject(FailureUnit.SENSOR_GPS, FailureType.OFF, 0)
        emit("injected", **watch.snapshot())
        await watch.until("landed after the GPS loss", lambda w: w.latest["in_air"] is False, 40.0)
        await watch.until("disarmed after the GPS loss", lambda w: w.latest["armed"] is False, 15.0)
        emit("landed", texts=watch.texts, **watch.snapshot())
        emit("history", **watch.history)
    finally:
        await watch.stop()


FLOWS = {
    "action": flow_action,
    "offboard": flow_offboard,
    "mission": flow_mission,
    "params": flow_params,
    "logs": flow_logs,
    "examples": flow_examples,
    "failure": flow_failure,
}


async def main(args) -> None:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        try:
            system = await connect(mavsdk, args.url)
            await FLOWS[args.flow](system, args)
        except BaseException as exc:
            emit("error", kind=type(exc).__name__, message=str(exc), trace=traceback.format_exc()[-3000:])
            # Leave without destroying the core: a call may still be pending in its thread.
            os._exit(1)
        emit("done")
        threading.Timer(TEARDOWN_S, _teardown_hang).start()


def _teardown_hang() -> None:
    emit("teardown_hang", after_s=TEARDOWN_S)
    os._exit(3)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("flow", choices=sorted(FLOWS))
    parser.add_argument("url")
    parser.add_argument("--param-gain", default="", help="a controller gain parameter to retune in flight")
    parser.add_argument("--gain-factor", type=float, default=0.3)
    parser.add_argument("--out", default=".", help="logs: where the downloads go")
    asyncio.run(main(parser.parse_args()))
    os._exit(0)  # the watchdog timer thread must not keep us alive
