"""The contract on the wire between the processes: ports, ids, the HIL frame, zenoh keys.

Both processes and the ground-station scripts read this module; neither process imports the
other. Ports follow PX4 SITL's scheme (PX4's ``px4-rc.mavlink``) for instance ``N`` in [0, 249]
(MAVLink system id 1 + N, up to 250):

=====================  ==================  =======================================================
link                   port                who binds / who sends
=====================  ==================  =======================================================
HIL                    4560 + N            simulator binds 127.0.0.1; autopilot sends first
GCS (QGC, MAVProxy)    14550               ground station listens; autopilot N sends from 18570 + N
API (MAVSDK, scripts)  14540 + N, N <= 9   script listens; autopilot N sends from 14580 + N
                       14549, N >= 10
zenoh                  7447 + N            simulator's session listens on tcp/127.0.0.1
=====================  ==================  =======================================================

Every vehicle streams its GCS link to the one port 14550: one QGroundControl or MAVProxy there
sees the whole fleet, the vehicles told apart by system id. The API link goes to 14540 + N for the
first ten instances; from instance 10 on PX4 sends it to 14549 (all of them: 14540 + 10 would be
14550), and so do we. A script for one vehicle N >= 10 connects to that vehicle's own API link
instead, ``udpout://127.0.0.1:14580+N`` in MAVSDK (``udpout:127.0.0.1:14580+N`` in pymavlink):
the autopilot answers every address that talks to it, so the first message it hears there makes
the script a peer of that link alone (:func:`api_endpoint`, :func:`api_connect_url`). PX4's
onboard payload and gimbal links (14280 + N, 13030 + N) have no counterpart here.

:func:`port_roles` lists them by role: *own* ports are bound by our two processes (HIL, the two
autopilot links, zenoh), *client* ports are where ground stations listen (14550, 14540 + N or
14549); a ground station binding its client port is normal, and client ports are shared by design.
Own ports are distinct across all 250 instances, and no own port is any instance's client port
(:func:`port_collisions`, empty for the default bases; the ``[ports]`` bases of ``sitl.toml`` move
every link of one kind together; under bases that make ports meet, the launcher refuses the
instances that would share them, :func:`sitl.launcher.check_launch`).

HIL lockstep frame: the simulator sends ONE UDP datagram per control period holding
``HIL_SENSOR``, ``HIL_STATE_QUATERNION``, ``ODOMETRY`` and, at the GPS rate, ``HIL_GPS``, all
stamped with the same ``time_usec`` (simulation time since the simulator started, µs). The
autopilot answers with one ``HIL_ACTUATOR_CONTROLS`` carrying the same ``time_usec``; the
simulator steps the plant only after that answer.

``HIL_STATE_QUATERNION`` quantises position to 1e-7 deg (~1 cm) and velocity to 1 cm/s, too
coarse for the paper's millimetre results, so the frame also carries ``ODOMETRY`` (float32 local
NED position, FRD body, as a motion-capture system feeds PX4). The autopilot's state source
is ``ODOMETRY`` by default, ``HIL_STATE_QUATERNION`` on request (``[autopilot] state_source``).

The frame also carries the disturbance the simulator applies, as a ``DEBUG_FLOAT_ARRAY`` named
``DISTURB`` (``array_id`` 0; ``data[0:3]`` the force at the centre of mass, N, world NED;
``data[3:6]`` the torque on the Euler coordinates, N m, MAVLink's Euler convention; ``time_usec``
the sample's time, the frame's or, when a changing value settles, the frame it settled at), at
every change after a steady stretch, every 10 ms while it keeps changing, when it settles, and at
least every :data:`DISTURBANCE_REPORT_EVERY_S` of simulated time (an autopilot that starts late
learns it); a receiver holds the last report (``simulator.core.DisturbanceReport``). The same
array carries the rotors' health, what the simulator applies beyond the controls as well:
``data[6:10]`` each rotor's effectiveness (1 healthy, 0 off), ``data[10:14]`` its failure as
``FAILURE_TYPE`` (0 none, 1 off, 2 stuck, 4 wrong), rotors 1-4 in the plant's order (1 front,
2 right, 3 rear, 4 left); a change of health is an onset like a disturbance's. The flight log's
``sim_disturbance`` and ``sim_rotors`` come from it.

The frame carries the flight battery as a power module measures it, a ``BATTERY_STATUS`` from
the simulator's component at :data:`BATTERY_REPORT_HZ` (simulator.battery): ``voltages[0]`` the
pack's voltage in mV (above 65 534 mV, 65 534 there and the rest in ``voltages[1]``, MAVLink's
rule), the other cells ``UINT16_MAX``; ``current_battery`` in cA (-1: not measured); every other
field MAVLink's "unknown" (``current_consumed`` and ``energy_consumed`` -1, ``battery_remaining``
-1, ``temperature`` ``INT16_MAX``, ``charge_state`` UNDEFINED): the autopilot estimates the charge
itself (autopilot.battery). A reading that is not a number goes out as those unknowns; the
autopilot refuses a report without a voltage or with a current below -1 (counted), and a pack
that stops reporting for 5 s is unhealthy there.

``HIL_ACTUATOR_CONTROLS``: ``mode`` has ``MAV_MODE_FLAG_SAFETY_ARMED`` when armed;
``flags`` bit 0 = lockstep (always set), bit 1 = ``controls`` are a normalised wrench
(``actuation = "wrench"``: U1/U1_max, then tau_x, tau_y, tau_z / tau_max in FRD body axes),
clear = normalised rotor speeds Omega_i/Omega_max for rotors 1-4. The simulator refuses a frame
whose bit 1 disagrees with its own vehicle config.

Requests to the simulator: the autopilot is the one that hears the ground stations, and some of
what they ask is the simulator's to carry out (``MAV_CMD_INJECT_FAILURE``: a sensor, a rotor or the
battery fails, :mod:`quadcommon.failures`). The autopilot puts such a request into the answer
datagram, after the ``HIL_ACTUATOR_CONTROLS``, as a MAVLink 2 frame from itself (system 1 + N,
component :data:`AUTOPILOT_COMPONENT_ID`, never signed) addressed to the simulator
(``target_system`` 1 + N, ``target_component`` :data:`SIMULATOR_COMPONENT_ID`); at most
:data:`MAX_REQUESTS_PER_ANSWER` per answer (more wait for the next one). The requests:
``COMMAND_LONG`` ``MAV_CMD_INJECT_FAILURE`` (param1 unit, param2 type, param3 instance, as the
ground station sent them; param4 the effectiveness a motor's ``wrong`` leaves it, in [0, 1], as
the autopilot resolved it, 1 otherwise); ``PARAM_SET`` of a simulator parameter the autopilot declares (PX4's
``SIM_BAT_ENABLE``, ``SIM_BAT_DRAIN``, ``SIM_BAT_MIN_PCT``; ``param_value`` the plain value as a
float, whatever the parameter's type), sent when it changes and, at a simulator's first frame,
those that differ from the vehicle file's. The simulator takes requests only from the answer it
accepts for the current frame, once: an answer's ``time_usec`` applies its requests only if it is
later than the last one that did, so the copy of an answer that a resent frame brings back (the
autopilot answers a resent frame with the same bytes) never applies twice. They apply from the next
frame on (the frame after the answer that carried them), in both runners alike. Anything else after
the controls (a frame that fails its checksum, comes from another sender, is addressed elsewhere,
is not a request, has a non-finite parameter, or bytes that are not MAVLink 2) is refused and
counted (``quadsitl/<N>/info``: ``requests``), never applied.

Values on the wire: integer fields saturate at their type's range instead of failing to pack
(a vehicle 10 000 km away is still reported, at the edge), NaN goes out as the field's
"unknown" (0, or UINT16_MAX where MAVLink defines it) -- :func:`sat_i16`, :func:`sat_u16`,
:func:`sat_i32`. Parsers read one datagram at a time (:func:`new_parser`, :func:`restart_parser`):
a truncated frame cannot swallow the frames of the next datagram.
"""

from __future__ import annotations

import re
import select
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import NamedTuple

from pymavlink.dialects.v20 import common as mavlink

from .mavlink_fast import split_frames
from .wire_values import sat_i16, sat_i32, sat_u16  # noqa: F401 (the field types, defined with the fields)

LOOPBACK = "127.0.0.1"

HIL_PORT_BASE = 4560
GCS_REMOTE_BASE = 14550
GCS_LOCAL_BASE = 18570
API_REMOTE_BASE = 14540
API_LOCAL_BASE = 14580
ZENOH_PORT_BASE = 7447
INSTANCE_MIN, INSTANCE_MAX = 0, 249  # --instance N: system ids 1..250
API_OWN_REMOTES = 10  # instances 0-9 send the API link to 14540 + N; the rest to 14540 + 9 (PX4)

# MAVLink ids.
AUTOPILOT_COMPONENT_ID = 1  # MAV_COMP_ID_AUTOPILOT1
SIMULATOR_COMPONENT_ID = 51  # a component of the same system on the HIL link (not on GCS links)

# The applied disturbance in the lockstep frame (see the module's docstring).
DISTURBANCE_NAME = b"DISTURB"
DISTURBANCE_REPORT_EVERY_S = 1.0
DISTURB_SIZE = 14  # floats of data used: force (3), torque (3), rotor effectiveness (4), failure type (4)

# The flight battery's monitor in the lockstep frame (see the module's docstring).
BATTERY_REPORT_HZ = 20.0

HIL_FLAG_LOCKSTEP = 1
HIL_FLAG_WRENCH = 2

# Requests to the simulator in an answer (see the module's docstring).
MAX_REQUESTS_PER_ANSWER = 4


class LockstepAnswer:
    """The autopilot's answer to one lockstep frame: the HIL_ACTUATOR_CONTROLS payload
    (``controls``, every field in wire order) and the requests that ride after it (``requests``:
    MAVLink 2 frames, possibly none). ``frame`` frames a payload on the sender's sequence;
    :attr:`datagram` is the answer as it goes on the wire, framed once when first asked (so an
    answer sent again is the same bytes). The in-process runner hands the answer over unframed,
    and the simulator reads ``controls`` as it reads the payload of the datagram's frame."""

    __slots__ = ("controls", "requests", "_frame", "_datagram")

    def __init__(self, controls: bytes, requests: bytes, frame: Callable[[bytes], bytes]) -> None:
        self.controls = controls
        self.requests = requests
        self._frame = frame
        self._datagram: bytes | None = None

    @property
    def datagram(self) -> bytes:
        """The answer's bytes: the controls' frame, then the requests."""
        if self._datagram is None:
            self._datagram = self._frame(self.controls) + self.requests
        return self._datagram


def spin_until_readable(sock, seconds: float) -> bool:
    """Busy-wait up to ``seconds`` for ``sock`` to become readable; True if it did.

    Lockstep hands control back and forth every frame. A blocking wait lets the vCPU go idle and
    waking it costs tens of microseconds per hop on a virtual machine, more than a frame's
    compute; polling for a moment first keeps it awake (bounded: then the caller blocks).
    """
    if seconds <= 0.0:
        return False
    select_ = select.select
    end = time.perf_counter() + seconds
    while True:
        if select_((sock,), (), (), 0.0)[0]:
            return True
        if time.perf_counter() >= end:
            return False


FLOAT32_MAX = 3.4028234663852886e38
_INT_RANGES = {
    "int8_t": (-(2**7), 2**7 - 1), "uint8_t": (0, 2**8 - 1), "int16_t": (-(2**15), 2**15 - 1),
    "uint16_t": (0, 2**16 - 1), "int32_t": (-(2**31), 2**31 - 1), "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1), "uint64_t": (0, 2**64 - 1),
}  # fmt: skip


def _saturated(value, ftype: str):
    if ftype == "float":
        if value > FLOAT32_MAX:
            return FLOAT32_MAX
        return -FLOAT32_MAX if value < -FLOAT32_MAX else value
    bounds = _INT_RANGES.get(ftype)
    if bounds is None or not isinstance(value, int):
        return value
    return min(max(value, bounds[0]), bounds[1])


def saturate_fields(message) -> None:
    """Clamp every numeric field of a pymavlink message to its wire type's range, in place (the
    fallback when packing overflows: floats to +-FLT_MAX, integers to their type's bounds)."""
    for name, ftype in zip(message.fieldnames, message.fieldtypes, strict=True):
        value = getattr(message, name)
        if isinstance(value, list):
            setattr(message, name, [_saturated(v, ftype) for v in value])
        else:
            setattr(message, name, _saturated(value, ftype))


def new_parser() -> mavlink.MAVLink:
    """A MAVLink 2 parser for incoming datagrams (``parse_buffer``) that turns garbage between
    frames into BAD_DATA messages instead of raising."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    return parser


def parse_datagram(parser: mavlink.MAVLink, data: bytes) -> list:
    """The messages of one datagram *from our own vehicle* (a ground station's or a checker's view):
    frame by frame with pymavlink's ``decode`` when the datagram is whole MAVLink 2 frames (what the
    autopilot sends; the byte-stream parser costs ~2x more), else through ``parse_buffer`` from a
    restarted parser (garbage then comes out as BAD_DATA, a bad frame too)."""
    frames = split_frames(data)
    if sum(len(frame) for _, frame in frames) == len(data):
        try:
            return [parser.decode(bytearray(frame)) for _, frame in frames]
        except mavlink.MAVError:
            pass
    restart_parser(parser)
    return parser.parse_buffer(data) or []


def restart_parser(parser: mavlink.MAVLink) -> None:
    """Forget a partial frame, as at the start of a datagram; counters and signing are kept
    (pymavlink has no public reset: these are the fields its constructor sets)."""
    parser.buf = bytearray()
    parser.buf_index = 0
    parser.expected_length = mavlink.HEADER_LEN_V1 + 2
    parser.have_prefix_error = False


def system_id(instance: int) -> int:
    """MAVLink system id of vehicle ``instance`` (PX4: 1 + N)."""
    return 1 + instance


@dataclass(frozen=True)
class Ports:
    hil: int
    gcs_remote: int
    gcs_local: int
    api_remote: int
    api_local: int
    zenoh: int


_INSTANCE_PART = re.compile(r"^(\d+)(?:(?:-|\.\.)(\d+))?$")


def parse_instances(text: str) -> list[int]:
    """``--instance``'s value as a list: ``"3"`` -> [3]; ``"0-2"``/``"0..2"`` -> [0, 1, 2];
    ``"3,5,7-8"`` -> [3, 5, 7, 8] (sorted, each once). ValueError names the part that is not an
    instance or a range of them in [INSTANCE_MIN, INSTANCE_MAX]."""
    found: set[int] = set()
    for part in text.split(","):
        match = _INSTANCE_PART.match(part.strip())
        if match is None:
            raise ValueError(f"--instance {text!r}: {part!r} is not N, N-M or N..M")
        first = int(match.group(1))
        last = first if match.group(2) is None else int(match.group(2))
        if last < first or not INSTANCE_MIN <= first <= last <= INSTANCE_MAX:
            raise ValueError(f"--instance {text!r}: {part!r} must be within "
                             f"[{INSTANCE_MIN}, {INSTANCE_MAX}], first <= last")  # fmt: skip
        found.update(range(first, last + 1))
    return sorted(found)


def instance_ranges(instances) -> str:
    """Instances as a person reads them: [0, 1, 2, 5] -> ``"0..2, 5"`` (in the order given)."""
    runs: list[list[int]] = []
    for n in instances:
        if runs and n == runs[-1][1] + 1:
            runs[-1][1] = n
        else:
            runs.append([n, n])
    return ", ".join(f"{a}" if a == b else f"{a}..{b}" for a, b in runs)


def ports(
    instance: int,
    hil_base: int = HIL_PORT_BASE,
    gcs_base: int = GCS_REMOTE_BASE,
    api_base: int = API_REMOTE_BASE,
    zenoh_base: int = ZENOH_PORT_BASE,
) -> Ports:
    """Every port of vehicle ``instance`` (the table of the module's docstring): own ports base + N,
    the GCS client port ``gcs_base`` for every instance, the API client port ``api_base`` + N for
    N < :data:`API_OWN_REMOTES` and ``api_base`` + 9 beyond (PX4's 14549)."""
    if not INSTANCE_MIN <= instance <= INSTANCE_MAX:
        raise ValueError(f"--instance must be in [{INSTANCE_MIN}, {INSTANCE_MAX}], got {instance}")
    n = instance
    return Ports(
        hil=hil_base + n,
        gcs_remote=gcs_base,
        gcs_local=GCS_LOCAL_BASE + (gcs_base - GCS_REMOTE_BASE) + n,
        api_remote=api_base + min(n, API_OWN_REMOTES - 1),
        api_local=API_LOCAL_BASE + (api_base - API_REMOTE_BASE) + n,
        zenoh=zenoh_base + n,
    )


def api_endpoint(p: Ports, instance: int) -> tuple[str, int]:
    """Where a script for vehicle ``instance`` alone meets its API link: ("udpin", 14540 + N) for
    the first ten (it listens there, as PX4's docs say), else ("udpout", 14580 + N), the link's own
    port (the script talks first; the autopilot answers the address that talks to it). 14549 would
    bring every vehicle from 10 on, and a pymavlink ``udpin`` answers whichever sent last."""
    if instance < API_OWN_REMOTES:
        return "udpin", p.api_remote
    return "udpout", p.api_local


def api_connect_url(p: Ports, instance: int) -> str:
    """:func:`api_endpoint` as a MAVSDK connection URL: ``udpin://0.0.0.0:14540`` for instance 0,
    ``udpout://127.0.0.1:14617`` for instance 37."""
    kind, port = api_endpoint(p, instance)
    return f"udpin://0.0.0.0:{port}" if kind == "udpin" else f"udpout://{LOOPBACK}:{port}"


class PortRole(NamedTuple):
    """One port of one instance: ``proto`` "UDP" or "TCP", who uses it (``role``), and whether our
    processes bind it (``own``) or a ground station listens there (a client port)."""

    proto: str
    port: int
    role: str
    own: bool
    field: str  # the Ports field it comes from


_ROLES = {  # Ports field -> (protocol, role, own)
    "hil": ("UDP", "simulator HIL link", True),
    "gcs_local": ("UDP", "autopilot GCS link", True),
    "api_local": ("UDP", "autopilot API link", True),
    "zenoh": ("TCP", "simulator zenoh endpoint", True),
    "gcs_remote": ("UDP", "GCS client port", False),
    "api_remote": ("UDP", "API client port", False),
}


def port_roles(p: Ports, zenoh_listener: bool = True) -> tuple[PortRole, ...]:
    """Every port of one instance by role: own ones first (bound by the simulator and the
    autopilot), then the client ones (where QGC / MAVProxy and MAVSDK / API scripts listen).
    ``zenoh_listener=False`` (a zenoh router is configured): the simulator binds no zenoh port."""
    roles = [PortRole(proto, getattr(p, name), role, own, name)
             for name, (proto, role, own) in _ROLES.items()]  # fmt: skip
    if not zenoh_listener:
        roles = [r for r in roles if r.field != "zenoh"]
    return tuple(r for r in roles if r.own) + tuple(r for r in roles if not r.own)


class PortCollision(NamedTuple):
    """One port two instances use in ways that cannot go together: two own ports, or one
    instance's own port that is another's client port (its stream would reach a process)."""

    proto: str
    port: int
    first: tuple[int, PortRole]  # (instance, its role)
    second: tuple[int, PortRole]


def port_collisions(
    roles_of: Callable[[int], tuple[PortRole, ...]], instances: Iterable[int]
) -> list[PortCollision]:
    """Every collision among ``instances`` (:class:`PortCollision`), ``roles_of(n)`` giving instance
    n's :func:`port_roles`. Client ports shared with client ports are not collisions: a ground
    station there hears every vehicle and tells them apart by system id."""
    seen: dict[tuple[str, int], list[tuple[int, PortRole]]] = {}
    for n in instances:
        for role in roles_of(n):
            seen.setdefault((role.proto, role.port), []).append((n, role))
    found = []
    for (proto, port), users in seen.items():
        owners = [u for u in users if u[1].own]
        if not owners or len(users) < 2:
            continue
        first = owners[0]
        found.extend(PortCollision(proto, port, first, other) for other in users if other is not first)
    return found


def zenoh_key(instance: int, leaf: str) -> str:
    """``quadsitl/<N>/<leaf>``: truth, controller, sim/gusts, info."""
    return f"quadsitl/{instance}/{leaf}"
