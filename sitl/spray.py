"""Real-socket traffic against a running autopilot: a hostile sprayer and a demanding ground station.

``python -m sitl.spray hostile --instance N [--datagrams 20000] [--sources 300] [--rate 2000]``
sends seeded datagrams that a correct autopilot must refuse or ignore, from ``--sources``
different UDP source ports, to the vehicle's GCS port: random bytes, truncated and corrupted
frames, MAVLink 1 frames and dialect messages it does not handle, valid commands addressed to
another system or component, and every handled request with a field it must refuse (ARM_DISARM
with param1 2, inf or NaN; NAV_LAND, RTL or AUTO.LAND with a value in a parameter slot MAVLink
leaves unused; a setpoint 10^9 m away or non-finite; a mode that does not exist; PARAM_SET to NaN
or inf; SET_MESSAGE_INTERVAL NaN; a 65,535-item mission). None of them, taken
alone, is a request a flight controller should honour, so a vehicle flown by another ground
station during the spray must fly exactly as without it.

``python -m sitl.spray load --instance N [--clients 8] [--seconds 20]`` starts ``--clients``
well-behaved ground stations, each heartbeating and asking for a dozen streams at the control
rate (SET_MESSAGE_INTERVAL 2000 µs), and reading everything (benchmarks/hostile_load.py).

Both are bounded (a datagram budget, a wall-clock limit) and use loopback only. Used by
``tests/sitl/test_hostile_udp.py`` and ``benchmarks/hostile_load.py``.
"""

from __future__ import annotations

import argparse
import math
import random
import signal
import struct
import sys
import threading
import time
from collections import Counter

from quadcommon import environment

environment.use_mavlink2()  # before pymavlink is imported (it reads them then)
from pymavlink.dialects.v20 import common as m  # noqa: E402

from autopilot.mavlink.validation import slots  # noqa: E402
from quadcommon import wire  # noqa: E402
from quadcommon.config import load_sitl  # noqa: E402
from quadcommon.udp import bind_udp  # noqa: E402

LOOPBACK = "127.0.0.1"
HOSTILE_KINDS = (
    "random bytes", "truncated frame", "corrupted frame", "mavlink1 frame", "unhandled message",
    "command to another system", "command to another component", "arm with an invalid bool",
    "value in an unused slot",
    "setpoint out of bounds", "setpoint non-finite", "invalid mode", "param set non-finite",
    "message interval NaN", "mission too large",
)  # fmt: skip
# Messages the autopilot handles (a frame of any other id must be dropped and counted).
HANDLED = {
    m.MAVLINK_MSG_ID_HEARTBEAT, m.MAVLINK_MSG_ID_COMMAND_LONG, m.MAVLINK_MSG_ID_COMMAND_INT,
    m.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED, m.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT,
    m.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET, m.MAVLINK_MSG_ID_MANUAL_CONTROL, m.MAVLINK_MSG_ID_PARAM_SET,
    m.MAVLINK_MSG_ID_PARAM_REQUEST_LIST, m.MAVLINK_MSG_ID_PARAM_REQUEST_READ, m.MAVLINK_MSG_ID_TIMESYNC,
    m.MAVLINK_MSG_ID_SYSTEM_TIME, m.MAVLINK_MSG_ID_SET_MODE, m.MAVLINK_MSG_ID_RC_CHANNELS_OVERRIDE,
    m.MAVLINK_MSG_ID_SETUP_SIGNING, m.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS,
    m.MAVLINK_MSG_ID_GPS_INPUT, m.MAVLINK_MSG_ID_VISION_POSITION_ESTIMATE,
    *(i for name, i in vars(m).items() if name.startswith("MAVLINK_MSG_ID_MISSION_")),
    *(i for name, i in vars(m).items() if name.startswith("MAVLINK_MSG_ID_LOG_")),
    *(i for name, i in vars(m).items() if name.startswith("MAVLINK_MSG_ID_HIL_")),
}  # fmt: skip
STOP = threading.Event()  # set by SIGTERM/SIGINT: the loops end and report what they sent
_POSITION_ONLY = 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048


class HostileTraffic:
    """Seeded datagrams for vehicle ``system_id`` that must each be refused or ignored."""

    def __init__(self, seed: int, system_id: int) -> None:
        self.rng = random.Random(seed)
        self.system_id = system_id
        self.mav = m.MAVLink(None, srcSystem=255, srcComponent=190)
        self.unhandled = sorted(i for i in m.mavlink_map if i not in HANDLED)
        self.sent: Counter[str] = Counter()

    def _pack(self, msg, mavlink1: bool = False) -> bytes:
        data = msg.pack(self.mav, force_mavlink1=mavlink1)
        self.mav.seq = (self.mav.seq + 1) % 256
        return data

    def _command(self, command: int, params, target: int | None = None, component: int = 1) -> bytes:
        target = self.system_id if target is None else target
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        return self._pack(m.MAVLink_command_long_message(target, component, command, 0, *p))

    def _random_message(self, msg_id: int) -> bytes:
        cls = m.mavlink_map[msg_id]
        rng = self.rng
        lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
        args = []
        for name, kind in zip(cls.fieldnames, cls.fieldtypes, strict=True):
            n = lengths[name]
            if kind == "char":
                value = bytes(rng.getrandbits(7) for _ in range(max(n, 1)))
            elif kind in ("float", "double"):
                pick = (math.nan, math.inf, -1e30)
                values = [rng.choice((*pick, rng.uniform(-1e6, 1e6))) for _ in range(max(n, 1))]
                value = values if n else values[0]
            else:
                bits = int("".join(c for c in kind if c.isdigit()) or 8)
                offset = 1 << (bits - 1) if kind.startswith("int") else 0
                values = [rng.getrandbits(bits) - offset for _ in range(max(n, 1))]
                value = values if n else values[0]
            args.append(value)
        try:
            return self._pack(cls(*args))
        except (struct.error, OverflowError, ValueError, TypeError):
            return bytes(rng.getrandbits(8) for _ in range(24))

    def next(self) -> tuple[str, bytes]:
        """The next hostile datagram and its kind (one of :data:`HOSTILE_KINDS`; counted in ``sent``)."""
        rng = self.rng
        kind = rng.choice(HOSTILE_KINDS)
        self.sent[kind] += 1
        bad = (math.inf, -math.inf, 1e30, math.nan)
        if kind == "random bytes":
            data = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 280)))
            return kind, (bytes([0xFD]) + data[1:]) if data and rng.random() < 0.5 else data
        if kind in ("truncated frame", "corrupted frame"):
            frame = self._command(m.MAV_CMD_COMPONENT_ARM_DISARM, [rng.choice((0.0, 1.0))])
            if kind == "truncated frame":
                return kind, frame[: rng.randint(0, len(frame) - 1)]
            data = bytearray(frame)
            position = rng.randrange(10, len(data) - 2)  # the payload: the checksum no longer matches
            data[position] ^= 1 + rng.randrange(255)
            return kind, bytes(data)
        if kind == "mavlink1 frame":
            other = (self.system_id + 1) % 256  # a valid request, but for another vehicle
            msg = m.MAVLink_command_long_message(other, 1, m.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
            return kind, self._pack(msg, mavlink1=True)
        if kind == "unhandled message":
            return kind, self._random_message(rng.choice(self.unhandled))
        if kind == "command to another system":
            other = (self.system_id + rng.randint(1, 200)) % 256 or 77
            command = rng.choice(
                (m.MAV_CMD_COMPONENT_ARM_DISARM, m.MAV_CMD_NAV_LAND, m.MAV_CMD_NAV_RETURN_TO_LAUNCH)
            )
            return kind, self._command(command, [0.0, 21196.0], target=other)
        if kind == "command to another component":
            return kind, self._command(m.MAV_CMD_NAV_LAND, [], component=rng.choice((2, 77, 154, 200)))
        if kind == "arm with an invalid bool":
            return kind, self._command(m.MAV_CMD_COMPONENT_ARM_DISARM, [rng.choice((2.0, -1.0, 0.5, *bad))])
        if kind == "value in an unused slot":  # honoured, each would land or return the vehicle
            auto_land = [1.0, 4.0, 6.0]  # DO_SET_MODE: custom mode, AUTO, LAND
            commands = ((m.MAV_CMD_NAV_LAND, []), (m.MAV_CMD_NAV_RETURN_TO_LAUNCH, []),
                        (m.MAV_CMD_DO_SET_MODE, auto_land))  # fmt: skip
            command, params = rng.choice(commands)
            params = params + [0.0] * (7 - len(params))
            params[rng.choice(slots(command).unused) - 1] = rng.choice((1.0, -1.0, 21196.0, math.inf, 1e30))
            return kind, self._command(command, params)
        if kind in ("setpoint out of bounds", "setpoint non-finite"):
            far = rng.choice((1e9, -1e9, 5e4)) if kind == "setpoint out of bounds" else rng.choice(bad)
            xyz = [rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-3, -1)]
            xyz[rng.randrange(3)] = far
            msg = m.MAVLink_set_position_target_local_ned_message(
                0, self.system_id, 1, m.MAV_FRAME_LOCAL_NED, _POSITION_ONLY, *xyz, 0, 0, 0, 0, 0, 0, 0, 0
            )
            return kind, self._pack(msg)
        if kind == "invalid mode":
            custom = rng.choice((99.0, 1e30, math.nan, math.inf))
            return kind, self._command(m.MAV_CMD_DO_SET_MODE, [1.0, custom, 0.0])
        if kind == "param set non-finite":
            name = rng.choice((b"MPC_XY_VEL_MAX", b"NAV_REF_MAX_DIST", b"COM_OF_LOSS_T", b"MIS_TAKEOFF_ALT"))
            value = rng.choice((math.nan, math.inf, -math.inf))
            msg = m.MAVLink_param_set_message(self.system_id, 1, name, value, m.MAV_PARAM_TYPE_REAL32)
            return kind, self._pack(msg)
        if kind == "message interval NaN":
            msg_id = rng.choice((m.MAVLINK_MSG_ID_HEARTBEAT, m.MAVLINK_MSG_ID_LOCAL_POSITION_NED))
            interval = rng.choice((math.nan, math.inf))
            return kind, self._command(m.MAV_CMD_SET_MESSAGE_INTERVAL, [msg_id, interval])
        # "mission too large"
        return kind, self._pack(m.MAVLink_mission_count_message(self.system_id, 1, 65535, 0))


def hostile(port: int, system_id: int, datagrams: int, sources: int, rate_hz: float, seed: int,
            seconds: float) -> Counter[str]:  # fmt: skip
    """Send ``datagrams`` hostile datagrams to ``127.0.0.1:port`` from ``sources`` source ports, at
    most ``rate_hz`` per second (0: as fast as possible), for at most ``seconds``; counts by kind."""
    traffic = HostileTraffic(seed, system_id)
    socks = [bind_udp(0, "spray source") for _ in range(sources)]  # non-blocking, 127.0.0.1
    start = time.monotonic()
    try:
        for k in range(datagrams):
            now = time.monotonic()
            if now - start > seconds or STOP.is_set():
                break
            if rate_hz > 0:
                due = start + k / rate_hz
                if due > now:
                    time.sleep(due - now)
            _, data = traffic.next()
            try:
                socks[k % sources].sendto(data, (LOOPBACK, port))
            except (BlockingIOError, ConnectionRefusedError):
                pass  # a full buffer or the port gone for a moment: the next one goes
    finally:
        for s in socks:
            s.close()
    return traffic.sent


STREAMS = (
    m.MAVLINK_MSG_ID_ATTITUDE, m.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, m.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, m.MAVLINK_MSG_ID_ODOMETRY, m.MAVLINK_MSG_ID_HIGHRES_IMU,
    m.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, m.MAVLINK_MSG_ID_VFR_HUD, m.MAVLINK_MSG_ID_SYS_STATUS,
    m.MAVLINK_MSG_ID_ALTITUDE, m.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, m.MAVLINK_MSG_ID_BATTERY_STATUS,
)  # fmt: skip


def load(port: int, system_id: int, clients: int, seconds: float, interval_us: float = 2000.0) -> int:
    """``clients`` ground stations on ``127.0.0.1:port``, each asking for :data:`STREAMS` every
    ``interval_us`` and reading everything for ``seconds``; returns the messages received."""
    mav = m.MAVLink(None, srcSystem=255, srcComponent=190)
    socks = [bind_udp(0, "load client") for _ in range(clients)]  # non-blocking, 127.0.0.1

    def send_all(data: bytes) -> None:
        for s in socks:
            try:
                s.sendto(data, (LOOPBACK, port))
            except (BlockingIOError, ConnectionRefusedError):
                pass

    received = 0
    start = last_beat = time.monotonic()
    try:
        send_all(m.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(mav))
        for msg_id in STREAMS:
            request = m.MAVLink_command_long_message(
                system_id, 1, m.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, interval_us, 0, 0, 0, 0, 0
            )
            send_all(request.pack(mav))
        while (now := time.monotonic()) - start < seconds and not STOP.is_set():
            if now - last_beat >= 1.0:
                send_all(m.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(mav))
                last_beat = now
            idle = True
            for s in socks:
                for _ in range(64):
                    try:
                        s.recv(4096)
                    except BlockingIOError:
                        break
                    received += 1
                    idle = False
            if idle:
                time.sleep(0.001)
    finally:
        for s in socks:
            s.close()
    return received


def main(argv: list[str] | None = None) -> int:
    """``python -m sitl.spray hostile|load``: spray a running autopilot with hostile datagrams, or load it
    as demanding ground stations; print what was sent and answered."""
    parser = argparse.ArgumentParser(prog="python -m sitl.spray", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    sub = parser.add_subparsers(dest="mode", required=True)
    h = sub.add_parser("hostile", help="datagrams the autopilot must refuse or ignore")
    h.add_argument("--instance", type=int, default=0)
    h.add_argument("--datagrams", type=int, default=20_000, help="how many (default %(default)s)")
    h.add_argument("--sources", type=int, default=300, help="distinct source ports (default %(default)s)")
    h.add_argument("--rate", type=float, default=2000.0, help="datagrams per wall second; 0: flat out")
    h.add_argument("--seconds", type=float, default=60.0, help="wall-clock limit (default %(default)s s)")
    h.add_argument("--seed", type=int, default=1)
    ld = sub.add_parser("load", help="well-behaved ground stations asking for 12 streams at the control rate")
    ld.add_argument("--instance", type=int, default=0)
    ld.add_argument("--clients", type=int, default=8)
    ld.add_argument("--seconds", type=float, default=20.0, help="wall-clock duration (default %(default)s s)")
    args = parser.parse_args(argv)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: STOP.set())
    if not 1 <= getattr(args, "sources", 1) <= 2000 or not 1 <= getattr(args, "clients", 1) <= 64:
        parser.error("--sources must be in [1, 2000] and --clients in [1, 64]")
    try:
        ports = load_sitl().ports(args.instance)  # sitl.toml's [ports] bases + N
    except ValueError as exc:
        parser.error(str(exc))
    system_id = wire.system_id(args.instance)
    if args.mode == "hostile":
        sent = hostile(
            ports.gcs_local, system_id, args.datagrams, args.sources, args.rate, args.seed, args.seconds
        )
        print(f"sent {sum(sent.values())} hostile datagrams from {args.sources} source ports:", flush=True)
        for kind, n in sorted(sent.items()):
            print(f"  {kind}: {n}")
    else:
        received = load(ports.gcs_local, system_id, args.clients, args.seconds)
        print(f"{args.clients} clients received {received} datagrams in {args.seconds:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
