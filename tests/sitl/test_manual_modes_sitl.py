"""Each manual mode flown from MANUAL_CONTROL against a real two-process SITL (simulator and
autopilot started by the launcher, UDP on loopback), with pymavlink as a joystick would: POSCTL,
ALTCTL, STABILIZED, ACRO and MANUAL entered by DO_SET_MODE and answering their sticks (what the
telemetry shows), a manual mode refused without sticks, then the sticks lost: NAV_RCL_ACT returns
and lands. The in-process tests measure the same behaviour closely
(tests/autopilot/guidance/test_manual.py, tests/autopilot/mavlink/test_manual.py);
this one checks it holds across real processes and sockets.

It runs at ``--speed 2``; the
sticks are paced on the telemetry's simulation time, and COM_RC_LOSS_T is raised to 1 s so that a
loaded machine's scheduling (0.5 s of wall time) is not taken for a lost joystick."""

from __future__ import annotations

import math
import time

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import (
    MAIN_ACRO,
    MAIN_ALTCTL,
    MAIN_MANUAL,
    MAIN_POSCTL,
    MAIN_STABILIZED,
    FlightMode,
)
from autopilot.guidance.sticks import stick_tilt
from quadcommon import wire
from sitl.launcher import VehicleSpec

from .harness import UdpGcs, running

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

INSTANCE = 12
DEG = math.radians(1.0)
TILT_MAX = math.radians(35.0)  # MPC_MAN_TILT_MAX
WALL_S = 150.0  # a safety net only: the waits count simulation time (a loaded machine runs < 1x)


class Pilot(UdpGcs):
    """A ground station with a joystick: MANUAL_CONTROL every 50 ms of simulation time."""

    def fly(self, seconds: float, x=0, y=0, z=500, r=0, sample=None) -> None:
        """Hold the sticks for ``seconds`` of simulation time; ``sample(self)`` on each message."""
        start = self.sim_time
        next_send = start
        deadline = time.monotonic() + seconds * 10.0 + 15.0  # wall: a safety net
        while self.sim_time - start < seconds:
            if time.monotonic() > deadline:
                raise AssertionError(f"{seconds} s of simulation did not pass (sim t={self.sim_time:.2f})")
            if self.sim_time >= next_send:
                self.conn.mav.manual_control_send(self.system_id, x, y, z, r, 0)
                next_send = self.sim_time + 0.05
            msg = self.poll(0.01)
            if msg is not None and sample is not None:
                sample(self)

    def mode_is(self, mode: FlightMode) -> bool:
        return self.last["HEARTBEAT"].custom_mode == mode.custom_mode

    def enter(self, main: int) -> None:
        self.fly(0.5)
        ack = self.command(m.MAV_CMD_DO_SET_MODE, 1, main, 0)
        assert ack.result == m.MAV_RESULT_ACCEPTED, self.statustext[-3:]
        mode = FlightMode.from_px4(main, 0)
        self.fly(1.1)  # the 1 Hz heartbeat shows it
        assert self.mode_is(mode), (mode, self.last["HEARTBEAT"].custom_mode)


def texts(gcs) -> str:
    return "".join(gcs.statustext)


@pytest.mark.timeout(420)
def test_each_manual_mode_answers_its_sticks_across_real_processes():
    spec = VehicleSpec(instance=INSTANCE, speed="2")
    with running(spec):
        gcs = Pilot(spec.ports().api_remote, wire.system_id(INSTANCE))
        try:
            gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and "HEARTBEAT" in g.last, what="telemetry")
            for message in (m.MAVLINK_MSG_ID_ATTITUDE, m.MAVLINK_MSG_ID_LOCAL_POSITION_NED):  # at 50 Hz
                assert gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, message, 20_000).result == 0
            param = m.MAVLink_param_set_message(gcs.system_id, 1, b"COM_RC_LOSS_T", 1.0,
                                                m.MAV_PARAM_TYPE_REAL32)  # fmt: skip
            gcs.conn.mav.send(param)

            # Without a stream a manual mode is refused, with the reason.
            ack = gcs.command(m.MAV_CMD_DO_SET_MODE, 1, MAIN_POSCTL, 0)
            assert ack.result == m.MAV_RESULT_DENIED
            assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
            ack = gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + 4.0)
            assert ack.result == m.MAV_RESULT_ACCEPTED
            gcs.wait(lambda g: g.position()[2] > 3.95, sim_timeout=20, wall_timeout=WALL_S, what="takeoff")

            # POSCTL: full pitch forward flies north, centred it holds.
            gcs.enter(MAIN_POSCTL)
            x0 = gcs.position()[0]
            gcs.fly(2.0, x=1000)
            gcs.fly(2.0)
            assert gcs.position()[0] - x0 > 1.5

            # ALTCTL: throttle 80 % climbs at (0.6 - 0.1) / 0.9 of MPC_Z_VEL_MAX_UP; pitch tilts.
            gcs.enter(MAIN_ALTCTL)
            z0 = gcs.position()[2]
            climb = []
            gcs.fly(2.5, z=800, sample=lambda g: climb.append(-g.last["LOCAL_POSITION_NED"].vz))
            assert abs(climb[-1] - 0.5 / 0.9 * 1.5) < 0.05 and gcs.position()[2] - z0 > 1.2
            pitch = []
            gcs.fly(1.5, x=500, sample=lambda g: pitch.append(g.last["ATTITUDE"].pitch))
            assert abs(pitch[-1] + stick_tilt(0.5, 0.0, TILT_MAX)[1]) < DEG  # NED pitch: nose down < 0
            gcs.fly(1.5, x=-500)

            # STABILIZED: the roll stick is a roll angle (the throttle a thrust: centred, the hover
            # thrust, a little more while tilted).
            gcs.enter(MAIN_STABILIZED)
            roll = []
            gcs.fly(1.0, y=400, z=520, sample=lambda g: roll.append(g.last["ATTITUDE"].roll))
            assert abs(roll[-1] - stick_tilt(0.0, -0.4, TILT_MAX)[0]) < DEG  # right stick: right wing down
            gcs.fly(1.0, y=-400, z=520)

            # ACRO: the yaw stick is a body rate (clockwise, positive in FRD), 50 % of MC_ACRO_Y_MAX.
            gcs.enter(MAIN_ACRO)
            rate = []
            gcs.fly(1.0, r=500, sample=lambda g: rate.append(g.last["ATTITUDE"].yawspeed))
            assert abs(rate[-1] - 0.5 * math.radians(100.0)) < 2.0 * DEG

            # MANUAL flies as STABILIZED; then POSCTL again, and the sticks stop.
            gcs.enter(MAIN_MANUAL)
            gcs.enter(MAIN_POSCTL)
            gcs.fly(2.0)
            assert gcs.position()[2] > 2.0
            gcs.wait(lambda g: g.mode_is(FlightMode.AUTO_RTL), sim_timeout=3.0, wall_timeout=WALL_S,
                     what="RTL on the lost sticks")  # fmt: skip
            gcs.wait(lambda g: g.last["HEARTBEAT"].base_mode & m.MAV_MODE_FLAG_SAFETY_ARMED == 0,
                     sim_timeout=60, wall_timeout=WALL_S, what="landed and disarmed")  # fmt: skip
            assert "Manual control lost" in texts(gcs)
            assert "manual control lost in POSCTL: returning to launch (NAV_RCL_ACT 2)" in texts(gcs)
            assert math.hypot(*gcs.position()[:2]) < 0.3  # back home
        finally:
            gcs.close()
