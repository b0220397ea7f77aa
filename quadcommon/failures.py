"""What can fail, and how: ``MAV_CMD_INJECT_FAILURE`` as PX4 handles it, written down once.

PX4 users rehearse failures with its ``failure`` shell command or MAVSDK's Failure plugin: the
command ``MAV_CMD_INJECT_FAILURE`` (param1 ``FAILURE_UNIT``, param2 ``FAILURE_TYPE``, param3 the
instance, 0 = all), refused while ``SYS_FAILURE_EN`` is 0. :data:`FAILURES` is the table of the
(unit, type) pairs this vehicle models and what each one does; the autopilot's command handler
(:mod:`autopilot.mavlink.failure_injection`), the simulator that carries the failure out (its
sensor kernel :mod:`simulator.sensors.frame`, its plant, its battery), ``quadsitl fail``, the
documentation (:func:`markdown_table`) and the tests all read it. Every other pair is answered
``MAV_RESULT_UNSUPPORTED`` with the reason.

Where a failure acts (:class:`Where`):

* ``sensors``: the simulator's sensor models (the lockstep frame's ``HIL_SENSOR``, ``HIL_GPS``,
  ``VISION_POSITION_ESTIMATE``). The vehicle learns of the failure from its data only, as on PX4;
  these act on the EKF (``EKF2_EN`` 1, ``--estimator ekf``): on the simulator's state (the
  default) the vehicle does not fly on its sensors, and the autopilot refuses them;
* ``plant``: the simulator's rigid body: a rotor off, stuck at its speed, or at a loss of
  effectiveness (``wrong``: it gives a fraction of its thrust and reaction torque, the fraction in
  the command's param4 or :data:`MOTOR_EFFECTIVENESS_PARAMETER`); on the rotors vehicle the rotor
  itself, on the paper's ideal-wrench vehicle the rotor's share of the wrench through the
  allocation's equation (:mod:`quadcommon.rotor_geometry`);
* ``battery``: the simulator's battery model;
* ``autopilot``: the autopilot's own MAVLink links (as PX4's receiver): the existing data-link and
  RC-loss failsafes then act.

The failure types are PX4's (MAVLink ``FAILURE_TYPE``), with one meaning per unit in
:data:`FAILURES`: *off* the sensor delivers nothing, *stuck* it repeats the last sample it took
before the failure, *garbage* uniform noise over its measurement range, *wrong* a fixed offset
(plausible values, wrong), *slow* one sample in :data:`SLOW_DIVISOR`, *delayed* an extra latency,
*intermittent* each sample dropped with probability :data:`DROP_PROBABILITY`. Random draws come
from the simulator's seeded sensor stream, so a run with failures is repeatable. ``ok`` ends the
unit's failure. Each unit has one failure at a time: a new type replaces the active one.

Motors are numbered as PX4 numbers a quadrotor in + configuration (airframe geometry "4+",
:data:`PX4_MOTOR_POSITIONS`): 1 right, 2 left, 3 front, 4 rear; instance 0 is all of them.

The same rotor faults at a time rather than on command: a scenario's ``[[actuator_faults]]``
(:class:`ActuatorFault`, :func:`read_actuator_faults`) and a campaign's drawn ones.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink

Vector3 = tuple[float, float, float]


class Unit(enum.IntEnum):
    """MAVLink ``FAILURE_UNIT``; the names are PX4's ``failure`` command's keys."""

    gyro = mavlink.FAILURE_UNIT_SENSOR_GYRO
    accel = mavlink.FAILURE_UNIT_SENSOR_ACCEL
    mag = mavlink.FAILURE_UNIT_SENSOR_MAG
    baro = mavlink.FAILURE_UNIT_SENSOR_BARO
    gps = mavlink.FAILURE_UNIT_SENSOR_GPS
    optical_flow = mavlink.FAILURE_UNIT_SENSOR_OPTICAL_FLOW
    vio = mavlink.FAILURE_UNIT_SENSOR_VIO
    distance_sensor = mavlink.FAILURE_UNIT_SENSOR_DISTANCE_SENSOR
    airspeed = mavlink.FAILURE_UNIT_SENSOR_AIRSPEED
    battery = mavlink.FAILURE_UNIT_SYSTEM_BATTERY
    motor = mavlink.FAILURE_UNIT_SYSTEM_MOTOR
    servo = mavlink.FAILURE_UNIT_SYSTEM_SERVO
    avoidance = mavlink.FAILURE_UNIT_SYSTEM_AVOIDANCE
    rc_signal = mavlink.FAILURE_UNIT_SYSTEM_RC_SIGNAL
    mavlink_signal = mavlink.FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL


class Type(enum.IntEnum):
    """MAVLink ``FAILURE_TYPE``; the names are PX4's ``failure`` command's keys."""

    ok = mavlink.FAILURE_TYPE_OK
    off = mavlink.FAILURE_TYPE_OFF
    stuck = mavlink.FAILURE_TYPE_STUCK
    garbage = mavlink.FAILURE_TYPE_GARBAGE
    wrong = mavlink.FAILURE_TYPE_WRONG
    slow = mavlink.FAILURE_TYPE_SLOW
    delayed = mavlink.FAILURE_TYPE_DELAYED
    intermittent = mavlink.FAILURE_TYPE_INTERMITTENT


class Where(enum.Enum):
    """Where a unit's failures act (see the module's docstring)."""

    SENSORS = "sensors"
    PLANT = "plant"
    BATTERY = "battery"
    AUTOPILOT = "autopilot"


SLOW_DIVISOR = 5.0  # slow: one sample in this many
DROP_PROBABILITY = 0.5  # intermittent: each sample dropped with this probability
EXTRA_LATENCY_S = 0.2  # delayed: added to the sensor's latency (GPS: GPS_EXTRA_LATENCY_S)
GPS_EXTRA_LATENCY_S = 0.5
# PX4's quadrotor + geometry ("4+"): motor n (1-based) sits at PX4_MOTOR_POSITIONS[n - 1].
PX4_MOTOR_POSITIONS = ("right", "left", "front", "rear")
# A motor's "wrong": the effectiveness it keeps (in [0, 1]), param4 of the command when in (0, 1],
# else this autopilot parameter's value.
MOTOR_EFFECTIVENESS_PARAMETER = "SIM_MOT_EFF"
MOTOR_EFFECTIVENESS_DEFAULT = 0.5


@dataclass(frozen=True)
class Effect:
    """One modelled (unit, type): what it does, and the figure the simulator uses (its unit is in
    ``meaning``; the sensor kernel reads it as a fault row's value, :mod:`simulator.sensors.frame`)."""

    meaning: str
    value: Vector3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class UnitModel:
    """A unit this vehicle models: where it acts, how many instances it has, its failure types."""

    unit: Unit
    where: Where
    instances: int  # addressable instances 1..instances (0 in the command: all of them)
    effects: dict[Type, Effect] = field(default_factory=dict)  # every type but ok
    note: str = ""  # what the unit is here

    @property
    def types(self) -> tuple[Type, ...]:
        """The types the command accepts for this unit (``ok`` first)."""
        return (Type.ok, *self.effects)


def _slow(rate: str) -> Effect:
    return Effect(f"one sample in {SLOW_DIVISOR:g} ({rate})", (SLOW_DIVISOR, 0.0, 0.0))


_INTERMITTENT = Effect(
    f"each sample dropped with probability {DROP_PROBABILITY:g} (seeded)", (DROP_PROBABILITY, 0.0, 0.0)
)
_HIL_IMU_OFF = "its bits of `HIL_SENSOR.fields_updated` cleared (the fields repeat the last sample)"
GYRO_RANGE_RAD_S = math.radians(2000.0)  # PX4's simulated gyro (FIFO) range, +-2000 deg/s
ACCEL_RANGE_M_S2 = 16.0 * 9.80665  # PX4's simulated accelerometer range, +-16 g


def _imu(what: str, garbage: str, garbage_range: float, wrong: str, offset: float) -> dict[Type, Effect]:
    return {
        Type.off: Effect(_HIL_IMU_OFF),
        Type.stuck: Effect(f"the last {what} sample before the failure, at every frame"),
        Type.garbage: Effect(f"uniform noise over {garbage} per axis", (garbage_range, 0.0, 0.0)),
        Type.wrong: Effect(wrong, (offset, offset, offset)),
        Type.slow: _slow("the fields repeat it between, bits cleared"),
        Type.intermittent: _INTERMITTENT,
    }


FAILURES: dict[Unit, UnitModel] = {
    m.unit: m
    for m in (
        UnitModel(Unit.gyro, Where.SENSORS, 1, _imu(
            "gyro", f"±{GYRO_RANGE_RAD_S:.1f} rad/s (±2000 deg/s)", GYRO_RANGE_RAD_S,
            "+0.1 rad/s (5.7 deg/s) on each axis", 0.1), "the IMU's gyroscope (every frame)"),
        UnitModel(Unit.accel, Where.SENSORS, 1, _imu(
            "accelerometer", f"±{ACCEL_RANGE_M_S2:.0f} m/s^2 (±16 g)", ACCEL_RANGE_M_S2,
            "+0.5 m/s^2 on each axis", 0.5), "the IMU's accelerometer (every frame)"),
        UnitModel(Unit.mag, Where.SENSORS, 1, {
            Type.off: Effect("never fresh in `HIL_SENSOR.fields_updated` (bits 6-8)"),
            Type.stuck: Effect("the last sample before the failure, at its rate"),
            Type.garbage: Effect("uniform noise over ±4 gauss per axis", (4.0, 0.0, 0.0)),
            Type.wrong: Effect("+0.2 gauss on body x (a hard-iron change)", (0.2, 0.0, 0.0)),
            Type.slow: _slow("at a fifth of its rate"),
            Type.delayed: Effect(f"+{EXTRA_LATENCY_S:g} s latency", (EXTRA_LATENCY_S, 0.0, 0.0)),
            Type.intermittent: _INTERMITTENT,
        }, "the magnetometer"),
        UnitModel(Unit.baro, Where.SENSORS, 1, {
            Type.off: Effect("never fresh in `HIL_SENSOR.fields_updated` (bits 9, 11, 12)"),
            Type.stuck: Effect("the last pressure before the failure, at its rate"),
            Type.garbage: Effect("pressure uniform over 300-1100 hPa", (300.0, 1100.0, 0.0)),
            Type.wrong: Effect("-1.2 hPa (reads about 10 m high)", (-1.2, 0.0, 0.0)),
            Type.slow: _slow("at a fifth of its rate"),
            Type.delayed: Effect(f"+{EXTRA_LATENCY_S:g} s latency", (EXTRA_LATENCY_S, 0.0, 0.0)),
            Type.intermittent: _INTERMITTENT,
        }, "the barometer"),
        UnitModel(Unit.gps, Where.SENSORS, 1, {
            Type.off: Effect("no `HIL_GPS` at all"),
            Type.stuck: Effect("the last fix before the failure, at its rate"),
            Type.garbage: Effect("position ±1000 m and velocity ±50 m/s uniform per axis, accuracy "
                                 "as good", (1000.0, 50.0, 0.0)),
            Type.wrong: Effect("position 20 m north of the truth, fix and accuracy as good",
                               (20.0, 0.0, 0.0)),
            Type.slow: _slow("2 Hz at 10 Hz"),
            Type.delayed: Effect(f"+{GPS_EXTRA_LATENCY_S:g} s latency", (GPS_EXTRA_LATENCY_S, 0.0, 0.0)),
            Type.intermittent: _INTERMITTENT,
        }, "the GNSS receiver"),
        UnitModel(Unit.vio, Where.SENSORS, 1, {
            Type.off: Effect("no `VISION_POSITION_ESTIMATE` at all"),
            Type.stuck: Effect("the last pose before the failure, at its rate"),
            Type.garbage: Effect("position ±10 m per axis and yaw ±180 deg, uniform", (10.0, 0.0, 0.0)),
            Type.wrong: Effect("position 0.5 m north of the truth", (0.5, 0.0, 0.0)),
            Type.slow: _slow("at a fifth of its rate"),
            Type.delayed: Effect(f"+{EXTRA_LATENCY_S:g} s latency", (EXTRA_LATENCY_S, 0.0, 0.0)),
            Type.intermittent: _INTERMITTENT,
        }, "vision / motion capture (a sensor profile with `[vision]`, e.g. mocap)"),
        UnitModel(Unit.motor, Where.PLANT, 4, {
            Type.off: Effect("the motor unpowered: the rotor gives no thrust and no reaction torque and "
                             "spins down"),
            Type.stuck: Effect("the rotor held at the speed it had (the wrench vehicle: its share of the "
                               "wrench held)"),
            Type.wrong: Effect(f"a loss of effectiveness: the rotor gives a fraction of its thrust and "
                               f"reaction torque, param4 when in (0, 1], else "
                               f"{MOTOR_EFFECTIVENESS_PARAMETER} ({MOTOR_EFFECTIVENESS_DEFAULT:g})",
                               (MOTOR_EFFECTIVENESS_DEFAULT, 0.0, 0.0)),
        }, "a rotor, numbered as PX4's quadrotor + (1 right, 2 left, 3 front, 4 rear); on the paper's "
           "ideal-wrench vehicle, the rotor's share of the wrench (the allocation's equation)"),
        UnitModel(Unit.battery, Where.BATTERY, 1, {
            Type.off: Effect("the monitor reads the pack empty (the cells at their empty voltage), as PX4's "
                             "battery simulator takes off"),
            Type.stuck: Effect("the monitor repeats its last reading"),
            Type.garbage: Effect("readings that are not numbers (MAVLink's unknowns on the wire)"),
            Type.wrong: Effect("the voltage read 10 % high (a mis-calibrated divider)"),
        }, "the battery monitor (the pack itself is unchanged)"),
        UnitModel(Unit.rc_signal, Where.AUTOPILOT, 1, {
            Type.off: Effect("every `MANUAL_CONTROL` dropped: the manual-control loss failsafe "
                             "(NAV_RCL_ACT)"),
        }, "the sticks (MANUAL_CONTROL)"),
        UnitModel(Unit.mavlink_signal, Where.AUTOPILOT, 1, {
            Type.off: Effect("every message from the ground stations dropped but `MAV_CMD_INJECT_FAILURE` "
                             "(the recovery): the data-link loss failsafe (NAV_DLL_ACT)"),
        }, "the ground stations' MAVLink (the vehicle still sends)"),
    )
}  # fmt: skip

UNMODELLED: dict[Unit, str] = {
    Unit.optical_flow: "this vehicle has no optical flow sensor",
    Unit.distance_sensor: "this vehicle has no distance sensor",
    Unit.airspeed: "a multicopter without an airspeed sensor",
    Unit.servo: "this vehicle has no servos",
    Unit.avoidance: "this vehicle has no avoidance system",
}

ALL_INSTANCES = 0


def unit_name(unit: int) -> str:
    """PX4's key for ``unit`` ("unknown" for a number MAVLink does not define)."""
    try:
        return Unit(unit).name
    except ValueError:
        return "unknown"


def type_name(failure_type: int) -> str:
    """The name of a MAVLink ``FAILURE_TYPE`` value, ``unknown`` when it is none of them."""
    try:
        return Type(failure_type).name
    except ValueError:
        return "unknown"


class Refusal(enum.Enum):
    """Why a request is refused, as MAV_RESULT: UNSUPPORTED (not modelled) or DENIED (bad instance)."""

    UNSUPPORTED = "unsupported"
    DENIED = "denied"


def refusal(unit: int, failure_type: int, instance: int) -> tuple[Refusal, str] | None:
    """Why the table refuses ``(unit, type, instance)``, or None for a modelled pair. (The vehicle's
    own conditions, SYS_FAILURE_EN, the estimator and the actuation, are the handler's.)"""
    name = unit_name(unit)
    if unit not in FAILURES:
        why = UNMODELLED.get(unit, f"no failure unit {unit}")  # type: ignore[call-overload]
        return Refusal.UNSUPPORTED, f"failure {name} not supported: {why}"
    model = FAILURES[Unit(unit)]
    if failure_type not in model.types:
        modelled = ", ".join(t.name for t in model.types)
        return Refusal.UNSUPPORTED, (
            f"failure {name} {type_name(failure_type)} not supported (modelled: {modelled})"
        )
    if not 0 <= instance <= model.instances:
        return Refusal.DENIED, (
            f"failure {name}: no instance {instance} (1 to {model.instances}, 0 for all)"
        )
    return None


def instance_phrase(instance: int) -> str:
    """PX4's wording: 0 is "all instances", n is "instances n"."""
    return "all instances" if instance == ALL_INSTANCES else f"instances {instance}"


def announcement(unit: int, failure_type: int, instance: int) -> str:
    """The STATUSTEXT an accepted request is announced with, as PX4's failure injection words it:
    ``Injected: gps off, all instances`` and ``Cleared: gps, all instances``."""
    if failure_type == Type.ok:
        return f"Cleared: {unit_name(unit)}, {instance_phrase(instance)}"
    return f"Injected: {unit_name(unit)} {type_name(failure_type)}, {instance_phrase(instance)}"


def keep_active(active: dict[str, str], unit: int, failure_type: int, instance: int) -> None:
    """Note an applied request in ``active`` (unit, and ``"motor 2"`` for a unit of several
    instances -> type name): ``ok`` removes the addressed instances, any other type sets them."""
    model = FAILURES[Unit(unit)]
    if model.instances == 1:
        keys = [model.unit.name]
    else:
        numbers = range(1, model.instances + 1) if instance == ALL_INSTANCES else (instance,)
        keys = [f"{model.unit.name} {n}" for n in numbers]
    for key in keys:
        if failure_type == Type.ok:
            active.pop(key, None)
        else:
            active[key] = Type(failure_type).name


def motor_effectiveness(failure_type: int, param4: float, parameter: float) -> float | None:
    """The effectiveness a motor keeps: for ``wrong``, param4 when it is in (0, 1] (0 and NaN are
    MAVLink's "unset"), else ``parameter`` (:data:`MOTOR_EFFECTIVENESS_PARAMETER`); None for a
    param4 outside [0, 1]. Other types: 1 (``stuck``, ``ok``) or 0 (``off``)."""
    if failure_type != Type.wrong:
        return 0.0 if failure_type == Type.off else 1.0
    if math.isnan(param4) or param4 == 0.0:
        return parameter
    return float(param4) if 0.0 < param4 <= 1.0 else None


# -- rotor faults at a time (a scenario's [[actuator_faults]], a campaign's drawn ones) -----------
ACTUATOR_FAULT_TYPES = ("off", "stuck", "wrong", "ok")  # the motor's types, and ok (the recovery)


@dataclass(frozen=True)
class ActuatorFault:
    """A motor's failure from a time on: PX4's ``motor`` number (1 right, 2 left, 3 front, 4 rear;
    0 all), the failure ``type`` (``off``, ``stuck``, ``wrong``, ``ok``), the ``effectiveness`` a
    ``wrong`` motor keeps (in [0, 1]; 1 otherwise, 0 for ``off``), and ``start_s`` (s of simulation
    time: from the first frame at or after it, as a commanded failure applies from a frame)."""

    motor: int
    type: str
    effectiveness: float
    start_s: float

    @property
    def failure_type(self) -> Type:
        """The fault's ``FAILURE_TYPE`` (:class:`Type`)."""
        return Type[self.type]

    def describe(self) -> str:
        """The fault in words, e.g. ``motor 2 off from 3 s``."""
        what = f"wrong ({self.effectiveness:.3g} effectiveness)" if self.type == "wrong" else self.type
        motors = "all motors" if self.motor == ALL_INSTANCES else f"motor {self.motor}"
        return f"{motors} {what} from {self.start_s:.3g} s"


def read_actuator_faults(items, source: str, prefix: str, duration_s: float) -> tuple[ActuatorFault, ...]:
    """A scenario's ``[[actuator_faults]]`` (a list of tables: ``motor``, ``type``, ``effectiveness``
    for ``wrong``, ``start_s`` within the run), validated; errors name the file and the key."""
    from .schema import ConfigError, Section

    if not isinstance(items, list) or not all(isinstance(item, dict) for item in items):
        raise ConfigError(f"{source}: key '{prefix}actuator_faults' = {items!r} is invalid; allowed: a "
                          "list of tables ([[actuator_faults]] with motor, type, start_s)")  # fmt: skip
    faults = []
    for i, item in enumerate(items):
        sec = Section(item, source, f"{prefix}actuator_faults[{i}].")
        motor = sec.integer("motor", lo=0, hi=FAILURES[Unit.motor].instances)
        kind = sec.choice("type", ACTUATOR_FAULT_TYPES)
        start = sec.number("start_s", lo=0.0, hi=duration_s, unit="s")
        if kind == "wrong":
            effectiveness = sec.number("effectiveness", MOTOR_EFFECTIVENESS_DEFAULT, lo=0.0, hi=1.0)
        elif sec.has("effectiveness"):
            raise sec.error("effectiveness", sec.data["effectiveness"], "only with type = \"wrong\"")
        else:
            effectiveness = 0.0 if kind == "off" else 1.0
        sec.finish()
        faults.append(ActuatorFault(motor, kind, effectiveness, start))
    return tuple(faults)


def sensor_fault_kinds() -> tuple[str, ...]:
    """The sensor failures as fault kinds of a sensor profile's ``[[faults]]`` (``gps_off``,
    ``baro_stuck``, ...; :data:`simulator.sensors.config.FAULT_KINDS`), in the table's order."""
    return tuple(
        f"{m.unit.name}_{t.name}" for m in FAILURES.values() if m.where is Where.SENSORS for t in m.effects
    )


def effect_of_kind(kind: str) -> tuple[Unit, Type, Effect] | None:
    """The (unit, type, effect) of a fault kind of :func:`sensor_fault_kinds`, else None."""
    name, _, type_text = kind.rpartition("_")
    try:
        unit, failure_type = Unit[name], Type[type_text]
    except KeyError:
        return None
    model = FAILURES.get(unit)
    if model is None or model.where is not Where.SENSORS or failure_type not in model.effects:
        return None
    return unit, failure_type, model.effects[failure_type]


def markdown_table() -> str:
    """The table as Markdown (the one in docs/failures.md): a row per modelled unit and type."""
    rows = ["| unit (`FAILURE_UNIT`) | acts in | type | what it does |", "|---|---|---|---|"]
    for model in FAILURES.values():
        unit = f"`{model.unit.name}` ({model.unit.value}): {model.note}"
        for i, (failure_type, effect) in enumerate(model.effects.items()):
            first = unit if i == 0 else ""
            where = model.where.value if i == 0 else ""
            rows.append(f"| {first} | {where} | `{failure_type.name}` | {effect.meaning} |")
    for unit, why in UNMODELLED.items():
        rows.append(f"| `{unit.name}` ({unit.value}) | | (none) | unsupported: {why} |")
    return "\n".join(rows)


def help_text() -> str:
    """The modelled units and their types, one line each (``quadsitl fail --help``)."""
    lines = [f"{m.unit.name}: {', '.join(t.name for t in m.types)}" for m in FAILURES.values()]
    lines.append(f"unsupported: {', '.join(u.name for u in UNMODELLED)}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown_table())
