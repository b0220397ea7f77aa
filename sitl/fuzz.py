"""The project's own fuzzer: seeded, reproducible hostile input against the cores in-process
(``python -m sitl.spray`` sends hostile traffic to running processes over UDP).

``python -m sitl.fuzz --inputs 100000 --seed 1`` flies a vehicle in-process (simulator core and
autopilot core in lockstep, real MAVLink bytes; ``--controller NAME``, ``--sensors PROFILE`` to fly
on the EKF), takes off, uploads a mission, then, while it hovers, delivers the inputs to its
ground-station links from up to 2,000 source addresses, a few per frame. The kinds
(:data:`AUTOPILOT_KINDS`):

* ``random bytes``: 0-300 random bytes, some starting with a MAVLink 1 or 2 marker;
* ``corrupted frame`` / ``truncated frame``: a valid frame with bytes flipped / cut short;
* ``mavlink1 frame``: a valid message of the dialect in a MAVLink 1 frame;
* ``dialect message``: a message of any id of the dialect, every field random (edge values of
  its type, NaN, +-inf, 1e30, denormals, random strings);
* ``handled message``: the same for the messages the autopilot handles, mostly addressed to it
  (parameter names real half the time, so some PARAM_SETs are valid and must take effect);
* ``command``: COMMAND_LONG / COMMAND_INT for every command the autopilot handles, parameters
  random as above, or plausible for the command half the time (small integers and NaN, the
  slots its MAVLink definition leaves unused unset: 0 or NaN, x/y 0 or INT32_MAX);
* ``hil frame``: a corrupted or random lockstep frame to the autopilot's HIL entry point.

What is checked (:func:`fuzz_autopilot` raises :class:`FuzzFailure` naming the seed and input):

* no exception escapes an entry point of the core, and none is caught inside it (the core's
  fault counters stay at zero);
* nothing the vehicle sends has a NaN or infinite float field (MAVLink's "unset" NaN in mission
  item parameters excepted);
* parameters change only to a value a PARAM_SET asked for and the parameter's rules allow, or
  to defaults after an accepted PREFLIGHT_STORAGE reset; the mission changes only after an
  accepted upload or clear;
* the reference stays finite, within ``NAV_REF_MAX_DIST`` of home, and no faster than the
  largest ``MPC_*`` limit in force;
* afterwards, a clean ground station lands the vehicle: on the ground and disarmed.

:func:`fuzz_simulator` does the same to the simulator core's HIL side (answers of any shape,
NaN/inf/huge controls, wrong flags, stale times; would-be autopilot hellos; gust uploads of any
bytes): no exception, the plant stays finite, the controls it applies stay in range.

(One module: the input generators, the checks after every frame and the report are one tool
with one seed; they change together.)
"""

from __future__ import annotations

import argparse
import json
import math
import random
import struct
import sys
import time
from collections import Counter
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as m

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from autopilot.mavlink.params import float32_shortest
from autopilot.mavlink.validation import INT32_MAX, slots
from autopilot.params.store import INT32
from gcs_scripts.upload_mission import MissionLink, make_item
from quadcommon import wire
from quadcommon.wire import new_parser, parse_datagram
from simulator.core import SimulatorCore, SimulatorSetup

from .inprocess import API_LINK, GCS_LINK, Lockstep, StackConnection

AUTOPILOT_KINDS = (
    "random bytes", "corrupted frame", "truncated frame", "mavlink1 frame", "dialect message",
    "handled message", "command", "hil frame",
)  # fmt: skip
SIMULATOR_KINDS = (
    "random bytes",
    "corrupted answer",
    "random answer",
    "stale answer",
    "hello",
    "gust upload",
)
INPUTS_PER_FRAME = 20  # a flood: ~10,000 datagrams per simulated second on the GCS links
SOURCE_PORTS = 2000
EKF_ALIGN_S = 12.0  # on the EKF: at rest this long before arming (the filter aligns and converges)
NAN_ALLOWED = {"MISSION_ITEM_INT": {"param1", "param2", "param3", "param4"},
               "MISSION_ITEM": {"param1", "param2", "param3", "param4"}}  # fmt: skip

_FLOAT_EDGES = (math.nan, math.inf, -math.inf, 1e30, -1e30, 3.4e38, -3.4e38, 1e-45, -0.0, 0.0, 1.0, -1.0)
_INT_RANGES = {
    "int8_t": (-(2**7), 2**7 - 1), "uint8_t": (0, 2**8 - 1), "int16_t": (-(2**15), 2**15 - 1),
    "uint16_t": (0, 2**16 - 1), "int32_t": (-(2**31), 2**31 - 1), "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1), "uint64_t": (0, 2**64 - 1),
}  # fmt: skip


class FuzzFailure(AssertionError):
    """An invariant broke; the message names the seed and the input number to replay."""


@dataclass
class FuzzReport:
    seed: int
    inputs: Counter = field(default_factory=Counter)  # by kind
    refusals: Counter = field(default_factory=Counter)  # by reason (the core's RefusalNotices)
    results: Counter = field(default_factory=Counter)  # COMMAND_ACK / MISSION_ACK results, dropped
    seconds: float = 0.0  # wall time of the fuzzing (process time)
    sim_seconds: float = 0.0

    @property
    def total(self) -> int:
        """How many inputs were fed, over all kinds."""
        return sum(self.inputs.values())

    def lines(self) -> list[str]:
        """The report as text lines: inputs by kind, the answers and drops, refusals by reason."""
        rate = self.total / max(self.seconds, 1e-9)
        out = [f"seed {self.seed}: {self.total} inputs in {self.seconds:.1f} s CPU "
               f"({rate:.0f} inputs/s), {self.sim_seconds:.1f} s simulated"]  # fmt: skip
        out += [f"  {kind:18s} {count:8d}" for kind, count in sorted(self.inputs.items())]
        if self.results:
            out.append("answers and drops:")
            out += [f"  {what:44s} {count:8d}" for what, count in self.results.most_common()]
        if self.refusals:
            out.append("refusals by reason (numbers as #):")
            out += [f"  {count:8d}  {reason}" for reason, count in self.refusals.most_common(25)]
        return out


# -- values -------------------------------------------------------------------------------------------
class Values:
    """Random field values of a MAVLink type, edges and specials weighted in."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng

    def float_(self) -> float:
        """A float field: an edge value (NaN, inf, limits), a moderate or a huge value, or any 32 bits
        read as a float."""
        r = self.rng.random()
        if r < 0.35:
            return self.rng.choice(_FLOAT_EDGES)
        if r < 0.7:
            return self.rng.uniform(-1e3, 1e3)
        if r < 0.85:
            return self.rng.uniform(-1e9, 1e9)
        return struct.unpack("<f", self.rng.getrandbits(32).to_bytes(4, "little"))[0]  # any bits

    def int_(self, kind: str) -> int:
        """An integer field of MAVLink type ``kind``: an edge of its range, a small value or any in range."""
        lo, hi = _INT_RANGES[kind]
        r = self.rng.random()
        if r < 0.4:
            return self.rng.choice((lo, hi, 0, 1, min(max(-1, lo), hi), hi // 2))
        if r < 0.7:
            return self.rng.randint(lo, min(hi, lo + 300) if lo >= 0 else min(hi, 300))
        return self.rng.randint(lo, hi)

    def text(self, length: int, words: list[str]) -> bytes:
        """A char field of at most ``length`` bytes: one of ``words`` or random bytes without NUL."""
        if words and self.rng.random() < 0.5:
            return self.rng.choice(words).encode()[:length]
        n = self.rng.randint(0, length)
        return bytes(self.rng.randint(0, 255) for _ in range(n)).replace(b"\0", b"")

    def field(self, kind: str, length: int, words: list[str]):
        """A value for a MAVLink field of type ``kind`` (an array of ``length`` values when non-zero)."""
        if kind == "char":
            return self.text(length or 1, words)
        one = self.float_ if kind in ("float", "double") else (lambda: self.int_(kind))
        return [one() for _ in range(length)] if length else one()


# -- the autopilot side -------------------------------------------------------------------------------
class AutopilotInputs:
    """Seeded hostile datagrams for the autopilot, by kind."""

    def __init__(self, seed: int, system_id: int, handled: list[int], commands: list[int], specs: dict):
        self.seed = seed
        self.rng = random.Random(seed)
        self.values = Values(self.rng)
        self.system_id = system_id
        self.handled = [i for i in handled if i in m.mavlink_map]
        self.commands = commands
        self.specs = specs  # parameter name -> ParamSpec: some PARAM_SETs are made valid
        self.names = list(specs)
        self.dialect = sorted(m.mavlink_map)
        self.encoder = m.MAVLink(None, srcSystem=255, srcComponent=190)
        self.param_sets: list[tuple[str, float]] = []  # every PARAM_SET sent (name, value)

    def next(self) -> tuple[str, bytes]:
        """The next input: its kind (one of :data:`AUTOPILOT_KINDS`, weighted) and the datagram."""
        kind = self.rng.choices(AUTOPILOT_KINDS, (8, 10, 8, 6, 16, 26, 22, 4))[0]
        rng = self.rng
        if kind == "random bytes":
            data = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 300)))
            if data and rng.random() < 0.5:
                data = bytes([rng.choice((0xFD, 0xFE))]) + data[1:]
            return kind, data
        if kind in ("corrupted frame", "truncated frame", "hil frame"):
            frame = self.message(rng.choice(self.handled) if rng.random() < 0.5 else None)
            if kind == "truncated frame":
                return kind, frame[: rng.randint(0, max(len(frame) - 1, 0))]
            data = bytearray(frame)
            for _ in range(rng.randint(1, 4)):
                data[rng.randrange(len(data))] = rng.getrandbits(8)
            return kind, bytes(data)
        if kind == "mavlink1 frame":
            ids = [i for i in self.dialect if i < 256]
            return kind, self.message(rng.choice(ids), mavlink1=True)
        if kind == "dialect message":
            return kind, self.message(rng.choice(self.dialect))
        if kind == "handled message":
            return kind, self.message(rng.choice(self.handled))
        return kind, self.command()

    def message(self, msg_id: int | None = None, mavlink1: bool = False) -> bytes:
        """A MAVLink 2 (or 1) frame of message ``msg_id`` (random from the dialect when None) with
        hostile field values, mostly addressed to this vehicle."""
        msg_id = self.rng.choice(self.dialect) if msg_id is None else msg_id
        cls = m.mavlink_map[msg_id]
        args = []
        lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))  # in wire order
        for name, kind in zip(cls.fieldnames, cls.fieldtypes, strict=True):
            length = lengths[name]
            value = self.values.field(kind, length, self.names if name == "param_id" else [])
            if name == "target_system" and self.rng.random() < 0.8:
                value = self.system_id
            elif name == "target_component" and self.rng.random() < 0.8:
                value = self.rng.choice((0, wire.AUTOPILOT_COMPONENT_ID))
            args.append(value)
        msg = cls(*args)
        if msg_id == m.MAVLINK_MSG_ID_PARAM_SET:
            self._plausible_param_set(msg)
            self.param_sets.append((_text(msg.param_id), msg.param_value))
        return self._pack(msg, mavlink1)

    def _plausible_param_set(self, msg) -> None:
        """Half the time the right MAV_PARAM_TYPE for a real name, and a value in its range."""
        spec = self.specs.get(_text(msg.param_id))
        if spec is None or self.rng.random() < 0.5:
            return
        integer = spec.kind == INT32
        msg.param_type = m.MAV_PARAM_TYPE_INT32 if integer else m.MAV_PARAM_TYPE_REAL32
        if self.rng.random() < 0.5:
            lo, hi = max(spec.lo, -1e6), min(spec.hi, 1e6)
            if integer:  # an INT32 travels as its four bytes in the float field
                number = self.rng.randint(math.ceil(lo), math.floor(hi))
                msg.param_value = struct.unpack("<f", struct.pack("<i", number))[0]
            else:
                msg.param_value = self.rng.uniform(lo, hi)

    def command(self) -> bytes:
        """A COMMAND_LONG with a handled command: half the time plausible parameters (unused slots
        unset), else hostile values."""
        rng, values = self.rng, self.values
        command = rng.choice(self.commands)
        if rng.random() < 0.5:  # plausible parameters: small integers, NaN where "unset", unused slots unset
            unused = slots(command).unused
            params = [
                rng.choice((0.0, math.nan)) if slot in unused
                else rng.choice((0.0, 1.0, 2.0, 6.0, math.nan, float(rng.randint(0, 300))))
                for slot in range(1, 8)
            ]  # fmt: skip
        else:
            params = [values.float_() for _ in range(7)]
        target = self.system_id if rng.random() < 0.9 else values.int_("uint8_t")
        if rng.random() < 0.5:
            msg = m.MAVLink_command_long_message(target, 1, command, 0, *params)
        else:  # x/y not an int32 (NaN, inf, huge): COMMAND_INT's "unset", 0 or INT32_MAX
            unset = (0, INT32_MAX)
            x, y = (int(v) if math.isfinite(v) and abs(v) < 2**31 else rng.choice(unset) for v in params[4:6])
            msg = m.MAVLink_command_int_message(
                target, 1, rng.choice((0, 1, 3, 6)), command, 0, 0, *params[:4], x, y, params[6]
            )
        return self._pack(msg)

    def _pack(self, msg, mavlink1: bool = False) -> bytes:
        try:
            data = msg.pack(self.encoder, force_mavlink1=mavlink1)
        except (struct.error, OverflowError, ValueError, TypeError):
            data = bytes(self.rng.getrandbits(8) for _ in range(20))  # unpackable values: noise
        self.encoder.seq = (self.encoder.seq + 1) % 256
        return data


def _text(value) -> str:
    if isinstance(value, bytes):
        value = value.decode("ascii", "replace")
    return value.split("\0", 1)[0]


class Watch:
    """Checks every datagram the vehicle sends: no non-finite float field; tallies answers."""

    def __init__(self, report: FuzzReport, fuzz_addresses: set) -> None:
        self.parser = new_parser()
        self.report = report
        self.fuzz_addresses = fuzz_addresses
        self._checked: set[bytes] = set()
        self.mission_changes = 0  # accepted uploads / clears answered to the fuzzer
        self.storage_resets = 0

    def __call__(self, link: int, address, data: bytes, context: str) -> None:
        if data in self._checked:  # the same telemetry bytes to every peer: checked once
            return
        if len(self._checked) > 4096:
            self._checked.clear()
        self._checked.add(data)
        for msg in parse_datagram(self.parser, data):
            if msg.get_msgId() < 0:
                raise FuzzFailure(f"{context}: the vehicle sent an unparseable frame")
            kind = msg.get_type()
            allowed = NAN_ALLOWED.get(kind, ())
            if kind == "PARAM_VALUE" and msg.param_type != m.MAV_PARAM_TYPE_REAL32:
                # An integer parameter travels bytewise (PX4): -1 is 0xffffffff, a NaN as a float.
                allowed = ("param_value",)
            for name, ftype in zip(msg.fieldnames, msg.fieldtypes, strict=True):
                if ftype not in ("float", "double") or name in allowed:
                    continue
                value = getattr(msg, name)
                values = value if isinstance(value, list) else (value,)
                if not all(math.isfinite(v) for v in values):
                    raise FuzzFailure(f"{context}: the vehicle sent {kind}.{name} = {value}")
            if address in self.fuzz_addresses:
                if kind == "COMMAND_ACK":
                    self.report.results[f"COMMAND_ACK {_name('MAV_RESULT', msg.result)}"] += 1
                    if msg.command == m.MAV_CMD_PREFLIGHT_STORAGE and msg.result == m.MAV_RESULT_ACCEPTED:
                        self.storage_resets += 1
                elif kind == "MISSION_ACK":
                    self.report.results[f"MISSION_ACK {_name('MAV_MISSION_RESULT', msg.type)}"] += 1
                    if msg.type == m.MAV_MISSION_ACCEPTED:
                        self.mission_changes += 1


def _name(enum: str, value: int) -> str:
    entry = m.enums.get(enum, {}).get(value)
    return entry.name if entry is not None else str(value)


def _stack(log=lambda text: None, controller: str = "intbs_nlhinf", sensors: str | None = None) -> Lockstep:
    """The vehicle on the ground; with ``sensors``, flying on the EKF over that sensor profile (its
    estimator profile of the same name), aligned at rest before the flight starts."""
    sim = SimulatorSetup.load(scenario="hover", sensors=sensors)
    estimation = {} if sensors is None else {"estimator": "ekf", "estimator_profile": sensors}
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller(controller), default_remotes=False,
                        **estimation)  # fmt: skip
    stack = Lockstep(sim, ap, log=log)
    if sensors is not None:
        stack.run_for(EKF_ALIGN_S)
    return stack


class _Flight:
    """The vehicle in the air: taken off and holding, a mission stored, a clean ground station
    (GCS link) heartbeating; the fuzzer's traffic comes on top of that."""

    def __init__(self, log, controller: str = "intbs_nlhinf", sensors: str | None = None) -> None:
        self.stack = stack = _stack(log, controller, sensors)
        self.ap = ap = stack.autopilot
        self.pilot = stack.ground_station(GCS_LINK)
        stack.run_for(1.0)
        mission = MissionLink(StackConnection(stack, GCS_LINK), 0)
        waypoints = [(1.0, 0.0, -2.0), (1.0, 1.0, -2.0), (0.0, 0.0, -2.0)]
        mission.upload([make_item(m.MAV_FRAME_LOCAL_NED, m.MAV_CMD_NAV_WAYPOINT, (0.0, 0.0, 0.0, math.nan),
                                  round(n * 1e4), round(e * 1e4), d) for n, e, d in waypoints])  # fmt: skip
        mission.close()
        self.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        altitude = ap.setup.sitl.home[2] + 2.0
        self.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, altitude)
        if not stack.run_for(20.0, until=lambda s: s.autopilot.commander.state.position_m[2] > 1.9):
            raise FuzzFailure("set-up: the vehicle did not take off")
        stack.run_for(2.0)

    def command(self, command: int, *params: float) -> int:
        before = len(self.pilot.acks(command))
        self.pilot.command(command, *params)
        for _ in range(50):
            self.stack.step()
            acks = self.pilot.acks(command)
            if len(acks) > before:
                return acks[-1].result
        raise FuzzFailure(f"no COMMAND_ACK for command {command}")

    def mission(self) -> list:
        return list(self.ap.missions.protocol.mission.items)


def _bounds(ap) -> tuple[float, float, float]:
    """NAV_REF_MAX_DIST, the fastest horizontal and vertical MPC_* limits in force."""
    p = ap.params
    return (p["NAV_REF_MAX_DIST"], p["MPC_XY_VEL_MAX"], max(p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"]))


def fuzz_autopilot(
    inputs: int = 100_000,
    seed: int = 1,
    log=lambda text: None,
    controller: str = "intbs_nlhinf",
    sensors: str | None = None,
) -> FuzzReport:
    """``inputs`` hostile datagrams against a flying vehicle in-process (see the module), then
    a clean landing, then a twentieth as many hostile HIL frames; a :class:`FuzzReport`. The
    vehicle flies ``controller`` on the truth, or on the EKF over the ``sensors`` profile."""
    texts: list[str] = []
    flight = _Flight(lambda text: (texts.append(text), log(text)), controller, sensors)
    stack, ap = flight.stack, flight.ap
    report = FuzzReport(seed)
    ports = [("127.0.0.1", 40000 + k) for k in range(SOURCE_PORTS)]
    watch = Watch(report, set(ports))
    context = ["set-up"]
    stack.observers.append(lambda out: watch(out.link, out.address, out.data, context[0]))
    handled = sorted(ap.dispatcher.handlers)
    gen = AutopilotInputs(seed, ap.system_id, handled, sorted(ap.commands.handlers), dict(ap.params.specs))
    params_before = dict(ap.params.values)
    mission_before = flight.mission()
    limits = _bounds(ap)
    rng = gen.rng
    hil_budget = inputs // 20
    gcs_inputs = inputs - hil_budget
    start = time.process_time()
    sim_start = stack.t
    sent = 0
    while sent < gcs_inputs:
        context[0] = f"seed {seed}, inputs {sent}-{sent + INPUTS_PER_FRAME}"
        for _ in range(min(INPUTS_PER_FRAME, gcs_inputs - sent)):
            kind, data = gen.next()
            if kind == "hil frame":
                kind, data = "corrupted frame", data  # the HIL link gets its own phase below
            report.inputs[kind] += 1
            stack.deliver(rng.choice((GCS_LINK, API_LINK)), rng.choice(ports), data)
            sent += 1
        if stack.frames % 250 == 0:
            flight.pilot.heartbeat()
        try:
            stack.step()
        except FuzzFailure:
            raise
        except Exception as exc:
            raise FuzzFailure(f"{context[0]}: {type(exc).__name__} escaped the core: {exc}") from exc
        _check_frame(ap, context[0], texts)
        limits = tuple(max(a, b) for a, b in zip(limits, _bounds(ap), strict=True))
        _check_reference(ap, limits, context[0])
    report.seconds = time.process_time() - start
    report.sim_seconds = stack.t - sim_start
    context[0] = f"seed {seed}, after the fuzzing"
    _check_params(ap, params_before, gen.param_sets, watch.storage_resets, context[0])
    if watch.mission_changes == 0 and flight.mission() != mission_before:
        raise FuzzFailure(f"{context[0]}: the mission changed without an accepted upload or clear")
    _land(flight, context[0])
    report.inputs.update(_fuzz_hil(flight, gen, hil_budget, watch, context, texts))
    report.refusals.update(ap.refusals.by_reason)
    report.results.update({f"dropped: {what}": n for what, n in ap.dispatcher.received.items()})
    return report


def _check_frame(ap, context: str, texts: list[str]) -> None:
    if ap.faults.counts:
        detail = next((t for t in texts if "internal error" in t), "")
        raise FuzzFailure(f"{context}: the core caught {dict(ap.faults.counts)}\n{detail}")


def _check_reference(ap, limits: tuple[float, float, float], context: str) -> None:
    ref = ap.commander.last_reference
    if ref is None:
        return
    values = (*ref.position_m, *ref.velocity_m_s, *ref.acceleration_m_s2)
    if not all(math.isfinite(v) for v in values):
        raise FuzzFailure(f"{context}: reference not finite: {ref}")
    home = ap.commander.home or (0.0, 0.0, 0.0)
    if math.dist(ref.position_m, home) > limits[0] + 1.0:
        raise FuzzFailure(f"{context}: reference {ref.position_m} beyond NAV_REF_MAX_DIST {limits[0]:g} m")
    vx, vy, vz = ref.velocity_m_s
    if math.hypot(vx, vy) > 1.1 * limits[1] + 0.1 or abs(vz) > 1.1 * limits[2] + 0.1:
        raise FuzzFailure(
            f"{context}: reference velocity {ref.velocity_m_s} beyond the MPC_* limits {limits[1:]}"
        )


def _check_params(ap, before: dict, param_sets: list[tuple[str, float]], resets: int, context: str) -> None:
    asked: dict[str, set[float]] = {}
    for name, value in param_sets:
        as_int = struct.unpack("<i", struct.pack("<f", value))[0]  # an INT32 parameter's bytes
        asked.setdefault(name, set()).update((value, float(as_int), float32_shortest(value)))
    store = ap.params
    for name, value in store.values.items():
        if value == before[name] or (math.isnan(value) and math.isnan(before[name])):
            continue
        spec = store.specs[name]
        if resets and value == float(spec.default):
            continue
        if value not in asked.get(name, ()):
            raise FuzzFailure(f"{context}: {name} changed {before[name]!r} -> {value!r}; nobody asked for it")
        if spec.check(value) is not None:
            raise FuzzFailure(
                f"{context}: {name} took {value!r}, which its rules refuse: {spec.check(value)}"
            )


def _land(flight: _Flight, context: str) -> None:
    """A clean ground station lands the vehicle after the hostile traffic: on the ground, disarmed."""
    stack, ap = flight.stack, flight.ap
    if ap.commander.armed:
        result = flight.command(m.MAV_CMD_NAV_LAND)
        if result != m.MAV_RESULT_ACCEPTED:
            raise FuzzFailure(f"{context}: NAV_LAND refused ({result}) after the fuzzing")

    def landed(s: Lockstep) -> bool:
        truth = s.sim.plant.truth()
        return (
            not s.autopilot.commander.armed
            and truth.position_m[2] < 0.05
            and abs(truth.velocity_m_s[2]) < 0.05
        )

    for _ in range(90):  # up to 90 s, the pilot heartbeating
        flight.pilot.heartbeat()
        if stack.run_for(1.0, until=landed):
            return
    raise FuzzFailure(f"{context}: not landed and disarmed 90 s after NAV_LAND (z={ap.commander.state})")


def _fuzz_hil(flight: _Flight, gen: AutopilotInputs, count: int, watch: Watch, context, texts) -> Counter:
    """Hostile lockstep frames to the autopilot's HIL entry point (after the landing): random and
    corrupted HIL messages with valid checksums, NaN and huge states, times going backwards."""
    ap, rng = flight.ap, gen.rng
    sim_ids = m.MAVLink(None, srcSystem=ap.system_id, srcComponent=wire.SIMULATOR_COMPONENT_ID)
    hil_ids = (m.MAVLINK_MSG_ID_HIL_SENSOR, m.MAVLINK_MSG_ID_HIL_STATE_QUATERNION,
               m.MAVLINK_MSG_ID_ODOMETRY, m.MAVLINK_MSG_ID_HIL_GPS)  # fmt: skip
    kinds: Counter = Counter()
    t = flight.stack.t
    for k in range(count):
        context[0] = f"seed {gen.seed}, HIL input {k}"
        gen.encoder, saved = sim_ids, gen.encoder
        try:
            frame = b"".join(gen.message(i) for i in hil_ids if rng.random() < 0.8)
        finally:
            gen.encoder = saved
        if rng.random() < 0.3:
            data = bytearray(frame or b"\0")
            data[rng.randrange(len(data))] = rng.getrandbits(8)
            frame = bytes(data)
        kinds["hil frame"] += 1
        t += 0.002
        answer = ap.on_hil_datagram(frame, t)
        if answer is not None:
            watch(2, None, answer, context[0])
        for out in ap.after_frame() + ap.tick(t):
            watch(out.link, out.address, out.data, context[0])
        _check_frame(ap, context[0], texts)
    return kinds


# -- the simulator side -------------------------------------------------------------------------------
def _gust_payload(rng: random.Random, values: Values) -> bytes:
    r = rng.random()
    if r < 0.2:
        return bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 200)))
    profile: dict = {}
    for kind in ("step", "ramp", "one_minus_cosine"):
        if rng.random() < 0.5:
            element = {
                key: _json_value(rng, values)
                for key in rng.sample(
                    ["start_s", "duration_s", "force_n", "torque_n_m", "wind_m_s", "axis", "amplitude", "x"],
                    3,
                )
            }
            profile[kind] = [element]
    if rng.random() < 0.3:
        profile["dryden"] = {"w20_m_s": _json_value(rng, values), "seed": _json_value(rng, values)}
    request: dict = {"profile": profile}
    if rng.random() < 0.7:
        request["start"] = rng.choice(
            ["now", {"at_s": _json_value(rng, values)}, {"after_s": _json_value(rng, values)}, 5]
        )
    if rng.random() < 0.1:
        request[rng.choice(["mode", "extra"])] = _json_value(rng, values)
    return json.dumps(request, allow_nan=True).encode()


def _json_value(rng: random.Random, values: Values):
    r = rng.random()
    if r < 0.5:
        return values.float_()
    if r < 0.7:
        return [values.float_() for _ in range(rng.randint(0, 4))]
    if r < 0.85:
        return rng.choice(["x", "", "now", "nan", None, True])
    return {"k": values.float_()}


def fuzz_simulator(inputs: int = 20_000, seed: int = 1) -> FuzzReport:
    """``inputs`` hostile datagrams and uploads against the simulator core's HIL side."""
    rng = random.Random(seed)
    values = Values(rng)
    setup = SimulatorSetup.load(scenario="hover")
    sim = SimulatorCore(setup)
    report = FuzzReport(seed)
    ap_ids = m.MAVLink(
        None, srcSystem=wire.system_id(setup.instance), srcComponent=wire.AUTOPILOT_COMPONENT_ID
    )
    thrust_max = setup.vehicle.actuation.thrust_max_n
    start = time.process_time()
    for k in range(inputs):
        context = f"seed {seed}, simulator input {k}"
        kind = rng.choice(SIMULATOR_KINDS)
        report.inputs[kind] += 1
        sim.begin_frame()
        answer = None
        try:
            if kind == "gust upload":
                ok, reply = sim.upload_gusts(_gust_payload(rng, values))
                json.loads(reply)  # always a JSON reply
                report.results["gust upload accepted" if ok else "gust upload refused"] += 1
            elif kind == "hello":
                ids = (rng.choice((wire.system_id(setup.instance), values.int_("uint8_t"))),
                       rng.choice((wire.AUTOPILOT_COMPONENT_ID, values.int_("uint8_t"))))  # fmt: skip
                hb = m.MAVLink_heartbeat_message(values.int_("uint8_t"), values.int_("uint8_t"), 0, 0, 0, 3)
                data = hb.pack(m.MAVLink(None, srcSystem=ids[0], srcComponent=ids[1]))
                expected = ids == (wire.system_id(setup.instance), wire.AUTOPILOT_COMPONENT_ID)
                if sim.is_autopilot(data) != expected:
                    raise FuzzFailure(f"{context}: is_autopilot wrong for ids {ids}")
            else:
                data = _actuator_input(kind, rng, values, sim.time_usec, ap_ids)
                answer = sim.answer_to_frame(data)
                report.results["answer applied" if answer is not None else "answer dropped"] += 1
                if kind == "stale answer" and answer is not None:
                    raise FuzzFailure(f"{context}: an answer for another frame was taken")
                if rng.random() < 0.01:
                    sim.autopilot_lost()
                if sim.emergency:
                    sim.answers_again(data)
            sim.end_frame(answer)
        except FuzzFailure:
            raise
        except Exception as exc:
            raise FuzzFailure(
                f"{context} ({kind}): {type(exc).__name__} escaped the simulator core: {exc}"
            ) from exc
        truth = sim.plant.truth()
        if not all(math.isfinite(v) for v in (*truth.position_m, *truth.velocity_m_s, *truth.quaternion)):
            raise FuzzFailure(f"{context}: the plant is no longer finite")
        plant = sim.plant
        if hasattr(plant, "thrust_cmd") and not 0.0 <= plant.thrust_cmd <= thrust_max:
            raise FuzzFailure(f"{context}: thrust command {plant.thrust_cmd} out of [0, {thrust_max}]")
        if truth.position_m[2] > 500.0 or k % 2000 == 0:  # full thrust for long flies away: start over
            sim = SimulatorCore(setup)
    report.seconds = time.process_time() - start
    report.sim_seconds = inputs * sim.dt_control
    return report


def _actuator_input(kind: str, rng: random.Random, values: Values, time_usec: int, ids) -> bytes:
    if kind == "random bytes":
        return bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 120)))
    flags = rng.choice((1, 3, values.int_("uint64_t")))
    mode = rng.choice((128, 0, values.int_("uint8_t")))
    controls = [values.float_() if rng.random() < 0.5 else rng.uniform(-0.2, 1.2) for _ in range(16)]
    stamp = time_usec
    if kind == "stale answer":
        stamp = time_usec + rng.choice((-1, 1, -(10**6), 10**9))
        stamp = stamp if stamp >= 0 else time_usec + 1
    msg = m.MAVLink_hil_actuator_controls_message(stamp, controls, mode, flags)
    try:
        data = msg.pack(ids)
    except (struct.error, OverflowError):
        return b""
    if kind == "corrupted answer":
        buf = bytearray(data)
        for _ in range(rng.randint(1, 3)):
            buf[rng.randrange(len(buf))] = rng.getrandbits(8)
        data = bytes(buf)
    return data


def main(argv: list[str] | None = None) -> int:
    """``python -m sitl.fuzz``: feed seeded hostile inputs to the autopilot core, then to the simulator
    core, and print the reports; 1 on a failure (an exception or a broken invariant)."""
    parser = argparse.ArgumentParser(prog="python -m sitl.fuzz", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--inputs", type=int, default=100_000, help="inputs against the autopilot core")
    parser.add_argument("--sim-inputs", type=int, default=20_000, help="inputs against the simulator core")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--controller", default="intbs_nlhinf", help="the cascade the vehicle flies")
    parser.add_argument("--sensors", default=None, metavar="PROFILE",
                        help="fly on the EKF over this sensor profile (gps, mocap, ...); default: truth")
    args = parser.parse_args(argv)
    try:
        report = fuzz_autopilot(args.inputs, args.seed, controller=args.controller, sensors=args.sensors)
        print("autopilot core:", *report.lines(), sep="\n")
        sim_report = fuzz_simulator(args.sim_inputs, args.seed)
        print("simulator core:", *sim_report.lines(), sep="\n")
    except FuzzFailure as exc:
        print(f"FUZZ FAILURE: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
