"""The vehicle's MAV_CMDs (arming, takeoff, land, RTL, modes, message requests, failure injection):
wire -> commander.

Each handler reads a :class:`~.commands.CommandRequest` as PX4 does, its parameters already
validated (:mod:`.validation`), and returns ``(MAV_RESULT, reason)``; the dispatcher answers every
command with a COMMAND_ACK. A message a command asks for (REQUEST_MESSAGE, GET_HOME_POSITION,
AUTOPILOT_CAPABILITIES) is left in :attr:`VehicleCommands.after_ack` for the core to pack and send
right after the ACK, as PX4 does (packed after it: signed frames carry increasing timestamps, and a
signing ground station refuses one older than the frame before).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from quadcommon import frames
from quadcommon.build_info import BuildInfo

from ..commander.commander import Commander
from ..commander.modes import FlightMode
from ..guidance.orbit import OrbitRequest
from ..params.store import ParameterStore
from . import telemetry
from .codec import mavlink as m
from .commands import CommandDispatcher, CommandRequest
from .failure_injection import FailureInjection
from .validation import FORCE_MAGIC, INT32_MAX, reference_problem

REPOSITION_FRAMES = {  # COMMAND_INT frame -> altitude relative to home?
    m.MAV_FRAME_GLOBAL: False,
    m.MAV_FRAME_GLOBAL_INT: False,
    m.MAV_FRAME_GLOBAL_RELATIVE_ALT: True,
    m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: True,
}
UNDERGROUND_MARGIN_M = 10.0  # a takeoff "AMSL" this far below home is read as a height above home
CAPABILITIES = (
    m.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | m.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | m.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | m.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | m.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | m.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | m.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | m.MAV_PROTOCOL_CAPABILITY_FTP  # as PX4: MAVLink FTP is served (.ftp)
)

Result = tuple[int, str]


@dataclass(frozen=True)
class CommandContext:
    """What the vehicle's commands reach: the commander and the few things beside it they read,
    not the core that holds them."""

    commander: Commander
    now: Callable[[], float]  # simulation time (s)
    status: Callable[[], telemetry.VehicleStatus]  # the vehicle's state as telemetry reports it
    params: ParameterStore
    refuse: Callable[[str], None]  # a refusal's STATUSTEXT (rate-limited per reason)
    failure_injection: FailureInjection
    home: tuple[float, float, float]  # geodetic home (lat deg, lon deg, alt m AMSL)
    build: BuildInfo
    system_id: int


class VehicleCommands:
    """The vehicle's MAV_CMD handlers (module docstring), on a :class:`CommandContext`."""

    def __init__(self, context: CommandContext) -> None:
        self.context = context
        self.after_ack = None  # the message a command asked for (pymavlink), sent after its ACK

    def register(self, commands: CommandDispatcher) -> None:
        """Each of the vehicle's MAV_CMDs on ``commands``, with its handler."""
        # (bound methods, not lambdas: a deep copy of the vehicle rebinds them to the copy)
        commands.register(m.MAV_CMD_COMPONENT_ARM_DISARM, self.arm_disarm)
        commands.register(m.MAV_CMD_NAV_TAKEOFF, self.takeoff)
        commands.register(m.MAV_CMD_NAV_LAND, self.land)
        commands.register(m.MAV_CMD_NAV_RETURN_TO_LAUNCH, self.return_to_launch)
        commands.register(m.MAV_CMD_DO_SET_MODE, self.set_mode)
        commands.register(m.MAV_CMD_DO_REPOSITION, self.reposition)
        commands.register(m.MAV_CMD_DO_ORBIT, self.orbit)
        commands.register(m.MAV_CMD_SET_MESSAGE_INTERVAL, self.message_interval)
        commands.register(m.MAV_CMD_GET_MESSAGE_INTERVAL, self.get_message_interval)
        commands.register(m.MAV_CMD_REQUEST_MESSAGE, self.request_message)
        commands.register(m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, self.request_autopilot_version)
        commands.register(m.MAV_CMD_GET_HOME_POSITION, self.request_home_position)
        commands.register(m.MAV_CMD_INJECT_FAILURE, self.inject_failure)

    def land(self, r: CommandRequest) -> Result:
        """MAV_CMD_NAV_LAND: land where the vehicle is (the commander's Land)."""
        return self.context.commander.land(self.context.now())

    def return_to_launch(self, r: CommandRequest) -> Result:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH: the commander's RTL."""
        return self.context.commander.return_to_launch(self.context.now())

    def request_message(self, r: CommandRequest) -> Result:
        """MAV_CMD_REQUEST_MESSAGE: the message whose id is param1."""
        return self.send_requested(r, int(r.params[0]))

    def request_autopilot_version(self, r: CommandRequest) -> Result:
        """MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: AUTOPILOT_VERSION."""
        return self.send_requested(r, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def request_home_position(self, r: CommandRequest) -> Result:
        """MAV_CMD_GET_HOME_POSITION: HOME_POSITION."""
        return self.send_requested(r, m.MAVLINK_MSG_ID_HOME_POSITION)

    def inject_failure(self, r: CommandRequest) -> Result:
        """MAV_CMD_INJECT_FAILURE (PX4's): param1 FAILURE_UNIT, param2 FAILURE_TYPE, param3 the
        instance (0 or NaN: all), validated as bytes; param4 (this vehicle's) the effectiveness a
        motor's ``wrong`` leaves it; :mod:`.failure_injection` answers it."""
        return self.context.failure_injection.command(int(r.params[0]), int(r.params[1]), r.params[2],
                                                   r.params[3])  # fmt: skip

    def arm_disarm(self, r: CommandRequest) -> Result:
        """MAV_CMD_COMPONENT_ARM_DISARM: param1 1 arms, 0 disarms; param2 21196 forces (MAVSDK
        sends NaN, "unset", with a plain arm)."""
        force = r.params[1] == FORCE_MAGIC
        commander, t = self.context.commander, self.context.now()
        if r.params[0] == 1.0:  # MAV_BOOL, validated: 0 or 1
            return commander.arm(t, force)
        return commander.disarm(t, force)

    def takeoff(self, r: CommandRequest) -> Result:
        """param7 is the altitude AMSL (PX4); NaN or 0 means MIS_TAKEOFF_ALT above home.

        A value that would lie underground as AMSL (below the home altitude minus 10 m) is read as
        a height above home instead: that is what ArduPilot-style clients (MAVProxy's ``takeoff
        5``) send.
        """
        ctx = self.context
        commander, t = ctx.commander, ctx.now()
        altitude = r.params[6]
        if not math.isfinite(altitude) or altitude == 0.0:
            return commander.takeoff(t, None)
        home_z = commander.home[2] if commander.home else 0.0
        home_amsl = ctx.home[2] + home_z
        if altitude >= home_amsl - UNDERGROUND_MARGIN_M:
            return commander.takeoff(t, altitude - home_amsl)
        return commander.takeoff(t, altitude)

    def reposition(self, r: CommandRequest) -> Result:
        """MAV_CMD_DO_REPOSITION (PX4's reading): param1 ground speed (-1/NaN: default), param2 bit 0
        switch to hold, param4 yaw (deg, NaN: keep), param5/6 latitude/longitude (NaN, or INT32_MAX in
        COMMAND_INT: keep), param7 altitude (NaN: keep). COMMAND_LONG and COMMAND_INT in the global
        frames (AMSL or relative to home); anything else, out of range, too far (NAV_REF_MAX_DIST) or
        outside the geofence is DENIED with the reason."""
        ctx = self.context
        commander = ctx.commander
        p = r.params
        if r.frame is None:
            relative, lat, lon = False, p[4], p[5]
        elif r.frame in REPOSITION_FRAMES:
            relative = REPOSITION_FRAMES[r.frame]
            lat = math.nan if p[4] == INT32_MAX else p[4] * 1e-7
            lon = math.nan if p[5] == INT32_MAX else p[5] * 1e-7
        else:
            return self._refuse(f"reposition refused: frame {r.frame} (global frames only)")
        if math.isnan(lat) != math.isnan(lon):
            return self._refuse("reposition refused: latitude and longitude must both be given")
        if not (math.isnan(lat) or -90.0 <= lat <= 90.0) or not (math.isnan(lon) or -180.0 <= lon <= 180.0):
            return self._refuse(f"reposition refused: latitude {lat:g}, longitude {lon:g} invalid")
        state = commander.state
        if state is None or commander.home is None:
            return self._refuse("reposition refused: no position")
        ref = commander.last_reference
        here = ref.position_m if ref is not None else state.position_m
        origin = ctx.home
        if math.isnan(lat):
            x, y = here[0], here[1]
        else:
            x, y, _ = frames.vector_from_ned(frames.geodetic_to_ned(lat, lon, origin[2], origin))
        altitude = p[6]
        if math.isnan(altitude):
            z = here[2]
        else:
            z = commander.home[2] + altitude if relative else altitude - origin[2]
        target = (x, y, z)
        problem = reference_problem(target, commander.home, ctx.params.values)
        problem = problem or commander.target_problem(target)
        if problem:
            return self._refuse(f"reposition refused: {problem}")
        speed = None if math.isnan(p[0]) or p[0] <= 0.0 else p[0]
        yaw = None if math.isnan(p[3]) else frames.wrap_pi(frames.yaw_from_ned(math.radians(p[3])))
        change_mode = not math.isnan(p[1]) and bool(int(p[1]) & m.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)
        return commander.reposition(ctx.now(), target, speed, yaw, change_mode)

    def orbit(self, r: CommandRequest) -> Result:
        """MAV_CMD_DO_ORBIT (PX4's reading): param1 radius (sign: > 0 clockwise), param2 tangential
        speed, param3 ORBIT_YAW_BEHAVIOUR, param5/6 the centre's latitude/longitude, param7 its
        altitude AMSL (NaN, or INT32_MAX in COMMAND_INT's x/y: keep, entering the mode: where the
        vehicle is). COMMAND_LONG, or COMMAND_INT in a global frame (param7 AMSL whatever the frame,
        as PX4 reads it); a centre out of range, too far (NAV_REF_MAX_DIST) or outside the geofence
        is DENIED with the reason; the radius's and the speed's limits are the commander's."""
        ctx = self.context
        commander = ctx.commander
        p = r.params
        if r.frame is None:
            lat, lon = p[4], p[5]
        elif r.frame in REPOSITION_FRAMES:
            lat = math.nan if p[4] == INT32_MAX else p[4] * 1e-7
            lon = math.nan if p[5] == INT32_MAX else p[5] * 1e-7
        else:
            return self._refuse(f"orbit refused: frame {r.frame} (global frames only)")
        if math.isnan(lat) != math.isnan(lon):
            return self._refuse("orbit refused: the centre's latitude and longitude must both be given")
        if not (math.isnan(lat) or -90.0 <= lat <= 90.0) or not (math.isnan(lon) or -180.0 <= lon <= 180.0):
            return self._refuse(f"orbit refused: centre latitude {lat:g}, longitude {lon:g} invalid")
        if commander.state is None or commander.home is None:
            return self._refuse("orbit refused: no position")
        origin = ctx.home
        centre_xy = centre_z = None
        if not math.isnan(lat):
            x, y, _ = frames.vector_from_ned(frames.geodetic_to_ned(lat, lon, origin[2], origin))
            centre_xy = (x, y)
        if not math.isnan(p[6]):
            centre_z = p[6] - origin[2]
        if centre_xy is not None or centre_z is not None:
            here = commander.state.position_m
            centre = (*(centre_xy or here[:2]), here[2] if centre_z is None else centre_z)
            problem = reference_problem(centre, commander.home, ctx.params.values)
            problem = problem or commander.target_problem(centre)
            if problem:
                return self._refuse(f"orbit refused: centre {problem}")
        request = OrbitRequest(
            None if math.isnan(p[0]) else p[0],
            None if math.isnan(p[1]) else p[1],
            None if math.isnan(p[2]) else int(p[2]),
            centre_xy,
            centre_z,
        )
        return commander.orbit_command(ctx.now(), request)

    def _refuse(self, reason: str) -> Result:
        """DENIED, with the reason as a STATUSTEXT too (rate-limited per reason)."""
        self.context.refuse(reason)
        return m.MAV_RESULT_DENIED, reason

    def set_mode(self, r: CommandRequest) -> Result:
        """MAV_CMD_DO_SET_MODE: param2 PX4's main mode, param3 its sub mode (NaN: 0); an unknown
        pair is DENIED. (Validated: the base mode has MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.)"""
        main, sub = int(r.params[1]), 0 if math.isnan(r.params[2]) else int(r.params[2])
        mode = FlightMode.from_px4(main, sub)
        if mode is None:
            return m.MAV_RESULT_DENIED, f"mode main={main} sub={sub} not available"
        return self.context.commander.set_mode(self.context.now(), mode)

    def message_interval(self, r: CommandRequest) -> Result:
        """SET_MESSAGE_INTERVAL for one of the link's streams (telemetry.STREAMS): granted at the
        interval asked for, or at the control frames' period if that is shorter (one message a
        frame; GET_MESSAGE_INTERVAL says what was granted); DENIED with the reason for a message
        the vehicle does not send or cannot build here (telemetry.stream_refusal)."""
        msg_id = int(r.params[0])
        refusal = telemetry.stream_refusal(msg_id, self.context.status()) if r.params[1] >= 0 else None
        if refusal is None and r.link.streams.set_interval_us(msg_id, r.params[1], self.context.now()):
            return m.MAV_RESULT_ACCEPTED, ""
        return m.MAV_RESULT_DENIED, refusal or telemetry.stream_refusal(msg_id, self.context.status()) or ""

    def get_message_interval(self, r: CommandRequest) -> Result:
        """MESSAGE_INTERVAL after the ACK: the interval granted on this link (µs), -1 off, 0 a
        message the vehicle does not stream or cannot build as configured (ESTIMATOR_STATUS on the
        truth)."""
        msg_id = int(r.params[0])
        refused = telemetry.stream_refusal(msg_id, self.context.status()) is not None
        interval = 0 if refused else r.link.streams.interval_us(msg_id)
        self.after_ack = m.MAVLink_message_interval_message(msg_id, interval)
        return m.MAV_RESULT_ACCEPTED, ""

    def send_requested(self, r: CommandRequest, msg_id: int) -> Result:
        """REQUEST_MESSAGE (and the older requests for one message): the message after the ACK;
        UNSUPPORTED for one the vehicle does not send, DENIED with the reason for one it cannot
        build here (telemetry.stream_refusal) and, as PX4, for one it has nothing for yet (no state
        yet, no battery report yet...)."""
        ctx = self.context
        if msg_id == m.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            msg = self.autopilot_version()
        else:
            status = ctx.status()
            if msg_id not in telemetry.STREAMS:
                return m.MAV_RESULT_UNSUPPORTED, telemetry.stream_refusal(msg_id, status) or ""
            refusal = telemetry.stream_refusal(msg_id, status)
            if refusal is not None:
                return m.MAV_RESULT_DENIED, refusal
            msg = telemetry.build(msg_id, status)
        if msg is None:
            return m.MAV_RESULT_DENIED, f"{m.mavlink_map[msg_id].msgname}: nothing to report yet"
        self.after_ack = msg
        return m.MAV_RESULT_ACCEPTED, ""

    def autopilot_version(self):
        """AUTOPILOT_VERSION as PX4 fills it: the build's version and git commit
        (:mod:`quadcommon.build_info`) as the flight software's and the middleware's, no OS or
        board version, a unique id per vehicle."""
        build = self.context.build
        uid = 0x5153000000000000 | self.context.system_id
        version, commit = build.flight_sw_version, build.custom_version
        return m.MAVLink_autopilot_version_message(
            CAPABILITIES, version, version, 0, 0, commit, commit, [0] * 8, 0, 0, uid, [0] * 18
        )
