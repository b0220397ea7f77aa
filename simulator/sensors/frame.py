"""One frame of the vehicle's sensors, written once as a kernel: when each sensor samples, what
it delivers after its latency, the biases' random walks, the GNSS errors and the injected faults
and failures.

:class:`~.models.SensorSuite` (the simulator) is a thin shell around :func:`sensor_frame`; a
batch engine calls it from its own compiled loop (:func:`sitl.campaign.kernels.simulate_estimated`),
so a seed gives the same readings in both. What a sample is (truth + bias + noise, the ISA,
the Gauss-Markov errors) is :mod:`.kernels`. The draws come from one stream
(:mod:`quadcommon.rng`) in a fixed order per frame: the biases' walks, the IMU, the
magnetometer, the barometer, the GNSS, the vision, then (until the first magnetometer or
barometer sample) the held readings' stand-ins.

Rates and latency: a sensor samples when ``t`` reaches its next multiple of the period (one
sample per frame at most: a coarse caller skips samples), and the sample is delivered
``latency`` after the time it is valid for (the first frame whose time reaches it; of two due in
one frame, the newer). The memory is float arrays laid out by the layouts below
(:mod:`quadcommon.layout`):

* ``C`` (:data:`FIGURES`, :func:`config_array`): the sensors' figures;
* ``S`` (:data:`STATE`, :func:`initial_state`): biases, GNSS errors, held readings, the schedules
  and the queues of readings in flight (:data:`QUEUE`);
* ``faults`` (n rows of :data:`FAULT`): kind, start, duration, value (3) per injected fault;
* ``out`` (:data:`DELIVERY`): what the frame delivers (a flag per sensor: 1 when it delivered, then
  its reading: :data:`MAG_READING`, :data:`BARO_READING`, :data:`GPS_READING`, :data:`VISION_READING`).

Failures (``MAV_CMD_INJECT_FAILURE``'s sensor units, :mod:`quadcommon.failures`) are rows of the
same fault table: kind :func:`fault_code` of ``"<unit>_<type>"`` (``gps_off``, ``baro_stuck``...),
active over ``[start, start + duration)`` like any fault, the table's figure in ``value``. A profile's
``[[faults]]``, a campaign's draws and a failure injected in flight (a row from its time on; a
recovery ends the unit's active rows) are the same rows. A unit fails one way at a time: the
latest-started active row of the unit decides (:func:`failure_of`). Per sample, as the table says:
*off* no sample (and nothing in flight is delivered), *stuck* the values of the unit's last good
sample, *garbage* uniform draws over the range, *wrong* the offset added, *slow* one due sample in
``value[0]``, *delayed* ``value[0]`` s more latency, *intermittent* each due sample dropped with
probability ``value[0]``. The draws of garbage and intermittent come from the sensors' stream
after the sample's own.

(One module: the sensors' memory layouts and the one kernel that reads and writes them; a
sensor's schedule, queue and failure rows are read together every frame.)
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from quadcommon.atmosphere import isa_altitude_m
from quadcommon.failures import Type, effect_of_kind
from quadcommon.kernel import kernel
from quadcommon.layout import Field, fields_of, layout, values, vector_at
from quadcommon.rigid_body import Quaternion, Vector3
from quadcommon.rng import normal, uniform
from simulator.dynamics.equations import TruthState

from .config import FAULT_KINDS, SensorConfig
from .kernels import (
    barometer_reading,
    draw3,
    gauss_markov,
    imu_reading,
    magnetometer_reading,
    random_walk,
    stationary,
    vision_reading,
)

EPS_S = 1e-9  # time comparisons on a float grid
GPS_FIX_NONE = 1.0  # MAVLink GPS_FIX_TYPE_NO_FIX: the receiver talks but has no position
GPS_FIX_3D = 3.0
NO_FIX_ACCURACY = 99.99  # eph, epv and speed accuracy of a "no fix" report

MAG, BARO, GPS, VISION = 0, 1, 2, 3  # the scheduled sensors

# -- the sensors' figures (config_array) ----------------------------------------------------------
FIGURES = layout("SensorFigures", (
    Field("accel_std", unit="m/s^2", doc="per-sample std"),
    Field("gyro_std", unit="rad/s", doc="per-sample std"),
    Field("accel_random_walk", unit="m/s^2/sqrt(s)"), Field("gyro_random_walk", unit="rad/s/sqrt(s)"),
    Field("baro_drift", unit="hPa/sqrt(s)"), Field("mag_std", unit="gauss"),
    Field("field", 3, unit="gauss", doc="earth field, world"),
    Field("baro_bias", unit="hPa"), Field("baro_std", unit="hPa"), Field("home_altitude", unit="m AMSL"),
    Field("gps_tau_position", unit="s"), Field("gps_tau_velocity", unit="s"),
    Field("gps_std_position", 3, unit="m", doc="stationary std of the position errors per axis"),
    Field("gps_std_velocity", 3, unit="m/s"),
    Field("gps_eph", unit="m"), Field("gps_epv", unit="m"), Field("gps_speed_accuracy", unit="m/s"),
    Field("gps_satellites"), Field("gps_on"), Field("vision_on"), Field("vision_std", unit="m"),
    Field("vision_yaw_std", unit="rad"),
    Field("period", 4, unit="s", doc="per scheduled sensor"),
    Field("latency", 4, unit="s", doc="per scheduled sensor"),
))  # fmt: skip

# -- a scheduled sensor's reading: its time, then its values ----------------------------------------
TIME = Field("time", unit="s", doc="the time the sample is valid for")
MAG_READING = layout("MagnetometerRecord", (TIME, Field("field", 3, unit="gauss", doc="body FLU")))
BARO_READING = layout("BarometerRecord", (
    TIME, Field("pressure", unit="hPa"), Field("altitude", unit="m AMSL", doc="pressure altitude (ISA)"),
    Field("temperature", unit="deg C"),
))  # fmt: skip
GPS_READING = layout("GpsRecord", (
    TIME, Field("position", 3, unit="m", doc="world"), Field("velocity", 3, unit="m/s", doc="world"),
    Field("eph", unit="m"), Field("epv", unit="m"), Field("satellites"), Field("speed_accuracy", unit="m/s"),
    Field("fix_type", doc="GPS_FIX_TYPE (GPS_FIX_NONE in an outage)"),
))  # fmt: skip
VISION_READING = layout("VisionRecord", (
    TIME, Field("position", 3, unit="m", doc="world"), Field("yaw", unit="rad"),
    Field("position_std", unit="m"), Field("yaw_std", unit="rad"),
))  # fmt: skip
READINGS = (MAG_READING, BARO_READING, GPS_READING, VISION_READING)  # by scheduled sensor (MAG ...)
READING_ROOM = max(r.size for r in READINGS)  # floats a reading may hold
# Any reading, as the code common to all sensors sees it (the IMU's too: its time, its vector).
READING = layout("Reading", (TIME, Field("values", READING_ROOM - 1, doc="the sensor's values (above)")))

# -- the sensors' state --------------------------------------------------------------------------
PENDING = 128  # readings in flight per sensor (latency / period: 0.2 s delayed at 500 Hz is 100)
QUEUED = layout("QueuedReading", (
    Field("due", unit="s", doc="when it is delivered"), Field("reading", READING_ROOM),
))  # fmt: skip
QUEUE = layout("ReadingQueue", (
    Field("oldest", doc="the index of the oldest item"), Field("in_flight", doc="the items in flight"),
    Field("items", PENDING * QUEUED.size, doc="a ring of PENDING QUEUED records"),
))  # fmt: skip
GOOD = READING_ROOM  # room for a failing unit's last good sample (a reading's values)
STATE = layout("SensorState", (
    Field("accel_bias", 3, unit="m/s^2"), Field("gyro_bias", 3, unit="rad/s"),
    Field("mag_bias", 3, unit="gauss"),
    Field("baro_drift", unit="hPa"),
    Field("gps_position_error", 3, unit="m"), Field("gps_velocity_error", 3, unit="m/s"),
    Field("t_last", unit="s", doc="NaN: none yet"), Field("t_gps", unit="s", doc="NaN: none yet"),
    Field("last_fix", 3, unit="m", doc="the last good fix's position"), Field("has_fix"),
    Field("held_mag", 3, unit="gauss", doc="the last magnetometer reading (what HIL_SENSOR repeats)"),
    Field("has_mag"),
    Field("held_baro", BARO_READING.size, doc="the last barometer reading (BARO_READING)"), Field("has_baro"),
    Field("next_sample", 4, doc="per scheduled sensor, the index of its next sample"),
    Field("queues", 4 * QUEUE.size, doc="per scheduled sensor, the readings in flight (QUEUE)"),
    Field("reading", READING_ROOM, doc="the reading being made (room the frame needs, not state)"),
    Field("good", 6 * GOOD, doc="per failing unit (FAILING), its last good sample"),
    Field("has_good", 6), Field("slow_count", 6, doc="due samples counted by a slow failure"),
    Field("held_imu", 6, doc="the accelerometer's and the gyro's last delivered sample"),
))  # fmt: skip

# -- faults ---------------------------------------------------------------------------------------
FAULT = layout("SensorFaultRow", (
    Field("kind", doc="fault_code: a profile fault's kind, or a failure's FAILURE_BASE + 8 * unit + type"),
    Field("onset", unit="s"), Field("duration", unit="s", doc="active over [onset, onset + duration)"),
    Field("value", 3, doc="the kind's figures (a vector, a range, a count, a probability, a delay)"),
))  # fmt: skip
GPS_OUTAGE, GPS_GLITCH, VISION_OUTAGE, MAG_DISTURBANCE, ACCEL_BIAS_STEP, GYRO_BIAS_STEP = range(6)
# Failures: the failing units by their names in quadcommon.failures, and a failure's kind code.
FAILING = ("accel", "gyro", "mag", "baro", "gps", "vio")
F_ACCEL, F_GYRO, F_MAG, F_BARO, F_GPS, F_VIO = range(6)
FAILURE_BASE = 100  # a failure's kind code: FAILURE_BASE + 8 * unit + type
OK, OFF, STUCK, GARBAGE = int(Type.ok), int(Type.off), int(Type.stuck), int(Type.garbage)
WRONG, SLOW = int(Type.wrong), int(Type.slow)
DELAYED, INTERMITTENT = int(Type.delayed), int(Type.intermittent)


# -- out: one frame's delivery ---------------------------------------------------------------------
def _fields_as(prefix: str, record) -> tuple[Field, ...]:  # noqa: ANN001 - a layout
    """``record``'s fields named ``prefix_name``: a reading as it sits in the delivery."""
    return tuple(f._replace(name=f"{prefix}_{f.name}") for f in fields_of(record))


DELIVERY = layout("SensorDelivery", (
    Field("force", 3, unit="m/s^2", doc="the IMU sample: specific force, body"),
    Field("rate", 3, unit="rad/s", doc="the IMU sample: body rates"),
    Field("mag_fresh"), *_fields_as("mag", MAG_READING),
    Field("baro_fresh"), *_fields_as("baro", BARO_READING),
    Field("gps_fresh"), *_fields_as("gps", GPS_READING),
    Field("vision_fresh"), *_fields_as("vision", VISION_READING),
    Field("held_mag", 3, unit="gauss"), *_fields_as("held_baro", BARO_READING),
    Field("accel_fresh", doc="1 when the IMU's accelerometer sampled (else held)"),
    Field("gyro_fresh", doc="1 when the IMU's gyro sampled (else held)"),
))  # fmt: skip
# Per scheduled sensor: where its flag (1 when it delivered) and its reading sit in the delivery.
FRESH_AT = (DELIVERY.mag_fresh, DELIVERY.baro_fresh, DELIVERY.gps_fresh, DELIVERY.vision_fresh)
READING_AT = (DELIVERY.mag_time, DELIVERY.baro_time, DELIVERY.gps_time, DELIVERY.vision_time)
READING_SIZE = tuple(r.size for r in READINGS)


# =================================================================================================
# Python: the arrays from a SensorConfig
# =================================================================================================
def config_array(config: SensorConfig, home_altitude_m: float, imu_rate_hz: float) -> np.ndarray:
    """The sensors' figures as :func:`sensor_frame` reads them (the IMU's per-sample noise from its
    density at ``imu_rate_hz``, the frame rate)."""
    a, g, m, b, gps, v = (config.accelerometer, config.gyroscope, config.magnetometer, config.barometer,
                          config.gps, config.vision)  # fmt: skip
    C = np.zeros(FIGURES.size)
    C[FIGURES.accel_std] = a.noise_density * math.sqrt(imu_rate_hz)
    C[FIGURES.gyro_std] = g.noise_density * math.sqrt(imu_rate_hz)
    C[FIGURES.accel_random_walk], C[FIGURES.gyro_random_walk], C[FIGURES.baro_drift] = (
        a.bias_random_walk,
        g.bias_random_walk,
        b.drift_hpa_rthz,
    )
    C[FIGURES.mag_std] = m.noise_std_gauss
    C[FIGURES.field : FIGURES.field + 3] = [float(c) for c in m.earth_field_world_gauss]
    C[FIGURES.baro_bias], C[FIGURES.baro_std], C[FIGURES.home_altitude] = (
        b.bias_hpa,
        b.noise_std_hpa,
        home_altitude_m,
    )
    C[FIGURES.gps_tau_position], C[FIGURES.gps_tau_velocity] = (
        gps.position_correlation_time_s,
        gps.velocity_correlation_time_s,
    )
    sh, sv, s = gps.horizontal_noise_std_m, gps.vertical_noise_std_m, gps.velocity_noise_std_m_s
    C[FIGURES.gps_std_position : FIGURES.gps_std_position + 3] = (sh, sh, sv)
    C[FIGURES.gps_std_velocity : FIGURES.gps_std_velocity + 3] = (s, s, s)
    C[FIGURES.gps_eph], C[FIGURES.gps_epv] = gps.reported_eph_m, gps.reported_epv_m
    C[FIGURES.gps_speed_accuracy], C[FIGURES.gps_satellites] = (
        gps.reported_speed_accuracy_m_s,
        gps.satellites_visible,
    )
    C[FIGURES.gps_on], C[FIGURES.vision_on] = float(gps.enabled), float(v.enabled)
    C[FIGURES.vision_std], C[FIGURES.vision_yaw_std] = v.position_noise_std_m, v.yaw_noise_std_rad
    for i, model in enumerate((m, b, gps, v)):
        C[FIGURES.period + i] = 1.0 / model.rate_hz
        C[FIGURES.latency + i] = model.latency_s
    return C


def new_sensors(config: SensorConfig, home_altitude_m: float, imu_rate_hz: float,
                initial_state_entry: Any = None) -> tuple[Any, np.ndarray, np.ndarray]:  # fmt: skip
    """``(rng, S, C)`` of sensors switched on: the stream of ``config.seed`` and the state after
    :func:`initial_state` (called through ``initial_state_entry``, a compiled entry of it, when
    given), the figures of :func:`config_array`."""
    from quadcommon.rng import stream

    rng = stream(config.seed)
    C = config_array(config, home_altitude_m, imu_rate_hz)
    S = np.zeros(STATE.size)
    a, g, m = config.accelerometer, config.gyroscope, config.magnetometer

    def f3(v: Any) -> Vector3:
        return (float(v[0]), float(v[1]), float(v[2]))

    (initial_state_entry or initial_state)(rng, C, f3(a.bias), f3(g.bias), f3(m.bias_gauss),
                                           float(a.turn_on_bias_std), float(g.turn_on_bias_std),
                                           float(m.turn_on_bias_std_gauss), S)  # fmt: skip
    return rng, S, C


def fault_code(kind: str) -> int:
    """The kind code of a fault row: a profile fault's index in the kinds of the profile format,
    a failure's ``FAILURE_BASE + 8 * unit + type``."""
    failure = effect_of_kind(kind)
    if failure is not None:
        unit, failure_type, _ = failure
        return FAILURE_BASE + 8 * FAILING.index(unit.name) + int(failure_type)
    return FAULT_KINDS.index(kind)


def fault_array(faults) -> np.ndarray:  # noqa: ANN001 - a sequence of SensorFault
    """Injected faults (:class:`~.config.SensorFault`) as rows of :func:`sensor_frame`'s table."""
    rows = np.zeros((len(faults), FAULT.size))
    for i, f in enumerate(faults):
        rows[i] = values(FAULT, kind=fault_code(f.kind), onset=f.start_s, duration=f.duration_s,
                         value=f.value)  # fmt: skip
    return rows


# =================================================================================================
# Kernels
# =================================================================================================
@kernel
def initial_state(rng: Any, C: Any, accel_bias: Vector3, gyro_bias: Vector3, mag_bias: Vector3,
                  accel_bias_std: float, gyro_bias_std: float, mag_bias_std: float,
                  S: Any) -> None:  # fmt: skip
    """``S`` at switch-on: the fixed biases plus a draw of their random part (same seed, same
    biases), the GNSS errors drawn from their stationary distribution, nothing sampled yet."""
    for i in range(S.shape[0]):
        S[i] = 0.0
    n = draw3(rng, accel_bias_std)
    for i in range(3):
        S[STATE.accel_bias + i] = accel_bias[i] + n[i]
    n = draw3(rng, gyro_bias_std)
    for i in range(3):
        S[STATE.gyro_bias + i] = gyro_bias[i] + n[i]
    n = draw3(rng, mag_bias_std)
    for i in range(3):
        S[STATE.mag_bias + i] = mag_bias[i] + n[i]
    e = stationary(
        rng, (C[FIGURES.gps_std_position], C[FIGURES.gps_std_position + 1], C[FIGURES.gps_std_position + 2])
    )
    u = stationary(
        rng, (C[FIGURES.gps_std_velocity], C[FIGURES.gps_std_velocity + 1], C[FIGURES.gps_std_velocity + 2])
    )
    for i in range(3):
        S[STATE.gps_position_error + i] = e[i]
        S[STATE.gps_velocity_error + i] = u[i]
    S[STATE.t_last] = math.nan
    S[STATE.t_gps] = math.nan


@kernel
def fault_sum(faults: Any, kind: int, t: float) -> Vector3:
    """The summed value of the faults of ``kind`` active at ``t`` (``[start, start + duration)``)."""
    x = y = z = 0.0
    for i in range(faults.shape[0]):
        f = faults[i]
        if int(f[FAULT.kind]) == kind and f[FAULT.onset] <= t < f[FAULT.onset] + f[FAULT.duration]:
            x += f[FAULT.value]
            y += f[FAULT.value + 1]
            z += f[FAULT.value + 2]
    return (x, y, z)


@kernel
def fault_active(faults: Any, kind: int, t: float) -> bool:
    """Whether a fault of ``kind`` acts at ``t`` (within ``[start, start + duration)``)."""
    for i in range(faults.shape[0]):
        f = faults[i]
        if int(f[FAULT.kind]) == kind and f[FAULT.onset] <= t < f[FAULT.onset] + f[FAULT.duration]:
            return True
    return False


@kernel
def due(S: Any, C: Any, sensor: int, t: float) -> bool:
    """True (once) when the sensor's next sample time has been reached; a coarse caller's skipped
    samples are skipped (one sample per call at most)."""
    period = C[FIGURES.period + sensor]
    if t + EPS_S >= S[STATE.next_sample + sensor] * period:
        S[STATE.next_sample + sensor] = float(int((t + EPS_S) / period) + 1)
        return True
    return False


@kernel
def enqueue(S: Any, sensor: int, t_due: float, reading: Any, size: int) -> None:
    """A reading into the sensor's queue, to be delivered at ``t_due``."""
    q = STATE.queues + sensor * QUEUE.size
    head, count = int(S[q + QUEUE.oldest]), int(S[q + QUEUE.in_flight])
    if count >= PENDING:  # full (a latency far beyond the period): the oldest is lost
        head = (head + 1) % PENDING
        count -= 1
    at = q + QUEUE.items + ((head + count) % PENDING) * QUEUED.size
    S[at + QUEUED.due] = t_due
    for i in range(size):
        S[at + QUEUED.reading + i] = reading[i]
    S[q + QUEUE.oldest], S[q + QUEUE.in_flight] = head, count + 1


@kernel
def dequeue(S: Any, sensor: int, t: float, out: Any, size: int) -> bool:
    """The newest reading whose delivery time has come into ``out`` (older ones in the same
    frame are dropped); False when none has."""
    q = STATE.queues + sensor * QUEUE.size
    head, count = int(S[q + QUEUE.oldest]), int(S[q + QUEUE.in_flight])
    found = False
    while count > 0:
        at = q + QUEUE.items + head * QUEUED.size
        if S[at + QUEUED.due] > t + EPS_S:
            break
        for i in range(size):
            out[i] = S[at + QUEUED.reading + i]
        found = True
        head = (head + 1) % PENDING
        count -= 1
    S[q + QUEUE.oldest], S[q + QUEUE.in_flight] = head, count
    return found


@kernel
def deliver(S: Any, C: Any, sensor: int, t: float, reading: Any, out: Any, extra_latency: float) -> None:
    """A reading sampled at ``t``: delivered now without latency (and nothing in flight), else
    queued for its latency (plus ``extra_latency``, a delayed failure's); the frame's delivery (if
    any) into ``out`` (flag, then the reading)."""
    size = READING_SIZE[sensor]
    fresh, at = FRESH_AT[sensor], READING_AT[sensor]
    latency = C[FIGURES.latency + sensor] + extra_latency
    if latency == 0.0 and S[STATE.queues + sensor * QUEUE.size + QUEUE.in_flight] == 0.0:
        for i in range(size):
            out[at + i] = reading[i]
        out[fresh] = 1.0
        return
    enqueue(S, sensor, t + latency, reading, size)
    out[fresh] = 1.0 if dequeue(S, sensor, t, out[at : at + size], size) else 0.0


@kernel
def pending(S: Any, sensor: int, t: float, out: Any) -> None:
    """A frame in which the sensor does not sample: what of its queue is due now."""
    fresh = FRESH_AT[sensor]
    out[fresh] = 0.0
    if S[STATE.queues + sensor * QUEUE.size + QUEUE.in_flight] > 0.0:
        at, size = READING_AT[sensor], READING_SIZE[sensor]
        out[fresh] = 1.0 if dequeue(S, sensor, t, out[at : at + size], size) else 0.0


@kernel
def silence(S: Any, sensor: int, out: Any) -> None:
    """An off sensor: nothing delivered this frame, nothing left in flight."""
    S[STATE.queues + sensor * QUEUE.size + QUEUE.in_flight] = 0.0
    out[FRESH_AT[sensor]] = 0.0


@kernel
def failure_of(faults: Any, unit: int, t: float) -> tuple[int, int]:
    """``(type, row)`` of the failure of ``unit`` (``FAILING``) active at ``t``: the latest-started
    active row of the unit decides; ``(OK, -1)`` when none is."""
    lo = FAILURE_BASE + 8 * unit
    mode, row, start = OK, -1, -math.inf
    for i in range(faults.shape[0]):
        f = faults[i]
        code, began = int(f[FAULT.kind]), f[FAULT.onset]
        if lo < code < lo + 8 and began <= t < began + f[FAULT.duration] and began >= start:
            mode, row, start = code - lo, i, began
    return mode, row


@kernel
def sample_kept(rng: Any, S: Any, faults: Any, unit: int, mode: int, row: int) -> bool:
    """Whether a sample due now is taken: not when off, one in ``value[0]`` when slow, with
    probability ``1 - value[0]`` (a draw) when intermittent."""
    if mode == OFF:
        return False
    if mode == SLOW:
        count = S[STATE.slow_count + unit] + 1.0
        if count >= faults[row][FAULT.value]:
            S[STATE.slow_count + unit] = 0.0
            return True
        S[STATE.slow_count + unit] = count
        return False
    if mode == INTERMITTENT:
        return uniform(rng) >= faults[row][FAULT.value]
    return True


@kernel
def extra_latency(faults: Any, mode: int, row: int) -> float:
    """The latency a ``delayed`` failure (``faults[row]``) adds (s); 0 for any other mode."""
    return faults[row][FAULT.value] if mode == DELAYED else 0.0


@kernel
def spread(rng: Any, half_width: float) -> float:
    """A uniform draw over ``[-half_width, half_width]``."""
    return half_width * (2.0 * uniform(rng) - 1.0)


@kernel
def corrupt(rng: Any, S: Any, faults: Any, unit: int, mode: int, row: int, reading: Any, size: int) -> None:
    """A sample of ``unit`` (a :data:`READING`: its ``size`` values after its time) as the unit's
    failure makes it: stuck repeats the last good sample, wrong adds the offset, garbage draws
    over the range; otherwise it is true and becomes the last good sample."""
    good = STATE.good + unit * GOOD
    values = READING.values
    if mode == STUCK and S[STATE.has_good + unit] != 0.0:
        for i in range(size):
            reading[values + i] = S[good + i]
        return
    if mode == WRONG:
        f = faults[row]
        if unit == F_BARO:  # the pressure (hPa); the altitude is what it means under the ISA
            reading[BARO_READING.pressure] += f[FAULT.value]
            reading[BARO_READING.altitude] = isa_altitude_m(reading[BARO_READING.pressure])
        else:  # the first three values: a vector (m/s^2, rad/s, gauss, m)
            for i in range(3):
                reading[values + i] += f[FAULT.value + i]
        return
    if mode == GARBAGE:
        f = faults[row]
        if unit == F_BARO:  # uniform over [value[0], value[1]] hPa
            low, high = f[FAULT.value], f[FAULT.value + 1]
            reading[BARO_READING.pressure] = low + (high - low) * uniform(rng)
            reading[BARO_READING.altitude] = isa_altitude_m(reading[BARO_READING.pressure])
        elif unit == F_GPS:  # position +-value[0] m, velocity +-value[1] m/s about the truth
            for i in range(3):
                reading[GPS_READING.position + i] += spread(rng, f[FAULT.value])
            for i in range(3):
                reading[GPS_READING.velocity + i] += spread(rng, f[FAULT.value + 1])
        elif unit == F_VIO:  # position +-value[0] m about the truth, any yaw
            for i in range(3):
                reading[VISION_READING.position + i] += spread(rng, f[FAULT.value])
            reading[VISION_READING.yaw] = spread(rng, math.pi)
        else:  # accelerometer, gyro, magnetometer: anywhere in +-value[0]
            for i in range(3):
                reading[values + i] = spread(rng, f[FAULT.value])
        return
    for i in range(size):
        S[good + i] = reading[values + i]
    S[STATE.has_good + unit] = 1.0


@kernel
def imu_sample(rng: Any, S: Any, faults: Any, unit: int, t: float, value: Vector3, reading: Any,
               out: Any, at: int) -> float:  # fmt: skip
    """The accelerometer's or the gyro's sample at ``t`` into ``out[at : at + 3]`` as its failure
    makes it; 1.0 when it sampled, 0.0 when it holds its last sample (off, a skipped one)."""
    held = STATE.held_imu + 3 * (unit - F_ACCEL)
    mode, row = failure_of(faults, unit, t)
    if not sample_kept(rng, S, faults, unit, mode, row):
        for i in range(3):
            out[at + i] = S[held + i]
        return 0.0
    reading[READING.time] = t
    for i in range(3):
        reading[READING.values + i] = value[i]
    corrupt(rng, S, faults, unit, mode, row, reading, 3)
    for i in range(3):
        out[at + i] = reading[READING.values + i]
        S[held + i] = reading[READING.values + i]
    return 1.0


@kernel
def magnetometer(rng: Any, S: Any, C: Any, faults: Any, q: Quaternion, t: float) -> Vector3:
    """One magnetometer sample (gauss, body FLU) at attitude ``q``: the Earth's field rotated into
    the body, plus the hard-iron bias and any injected disturbance active at ``t``, plus noise."""
    bias = (S[STATE.mag_bias], S[STATE.mag_bias + 1], S[STATE.mag_bias + 2])
    d = fault_sum(faults, MAG_DISTURBANCE, t)
    bias = (bias[0] + d[0], bias[1] + d[1], bias[2] + d[2])
    return magnetometer_reading(
        rng, q, (C[FIGURES.field], C[FIGURES.field + 1], C[FIGURES.field + 2]), bias, C[FIGURES.mag_std]
    )


@kernel
def barometer(rng: Any, S: Any, C: Any, height: float) -> tuple[float, float, float]:
    """``(pressure, pressure altitude, temperature)`` at ``height`` (m above home)."""
    return barometer_reading(
        rng, C[FIGURES.home_altitude] + height, C[FIGURES.baro_bias], S[STATE.baro_drift], C[FIGURES.baro_std]
    )


@kernel
def gps_fix(rng: Any, S: Any, C: Any, faults: Any, t: float, position: Vector3, velocity: Vector3,
            reading: Any) -> None:  # fmt: skip
    """A fix at ``t`` into ``reading`` (:data:`GPS_READING`): the Gauss-Markov errors advanced since
    the last fix; in an outage "no fix", the last good position repeated (home before any)."""
    if not math.isnan(S[STATE.t_gps]):
        dt = t - S[STATE.t_gps]
        e = gauss_markov(
            rng,
            vector_at(S, STATE.gps_position_error),
            dt,
            C[FIGURES.gps_tau_position],
            vector_at(C, FIGURES.gps_std_position),
        )
        u = gauss_markov(
            rng,
            vector_at(S, STATE.gps_velocity_error),
            dt,
            C[FIGURES.gps_tau_velocity],
            vector_at(C, FIGURES.gps_std_velocity),
        )
        for i in range(3):
            S[STATE.gps_position_error + i] = e[i]
            S[STATE.gps_velocity_error + i] = u[i]
    S[STATE.t_gps] = t
    G = GPS_READING
    reading[G.time] = t
    if fault_active(faults, GPS_OUTAGE, t):
        for i in range(3):
            reading[G.position + i] = S[STATE.last_fix + i] if S[STATE.has_fix] != 0.0 else 0.0
            reading[G.velocity + i] = 0.0
        reading[G.eph], reading[G.epv], reading[G.satellites] = NO_FIX_ACCURACY, NO_FIX_ACCURACY, 0.0
        reading[G.speed_accuracy], reading[G.fix_type] = NO_FIX_ACCURACY, GPS_FIX_NONE
        return
    glitch = fault_sum(faults, GPS_GLITCH, t)
    for i in range(3):
        p = position[i] + S[STATE.gps_position_error + i] + glitch[i]
        reading[G.position + i] = p
        reading[G.velocity + i] = velocity[i] + S[STATE.gps_velocity_error + i]
        S[STATE.last_fix + i] = p
    S[STATE.has_fix] = 1.0
    reading[G.eph], reading[G.epv] = C[FIGURES.gps_eph], C[FIGURES.gps_epv]
    reading[G.satellites] = C[FIGURES.gps_satellites]
    reading[G.speed_accuracy], reading[G.fix_type] = C[FIGURES.gps_speed_accuracy], GPS_FIX_3D


class SensorMemory(NamedTuple):
    """The sensors' memory (the module's docstring describes each array)."""

    rng: Any  # the sensors' random stream (quadcommon.rng)
    state: Any  # S, layout STATE
    figures: Any  # C, layout FIGURES
    faults: Any  # rows of FAULT


@kernel
def sensor_frame(memory: SensorMemory, t: float, truth: TruthState, out: Any) -> None:
    """Advance the sensors to ``t`` from the plant's ``truth`` at O (specific force and rates in
    the body, attitude, position and velocity in the world, the paper's yaw) and write what is
    delivered at ``t`` into ``out`` (:data:`DELIVERY`)."""
    rng, S, C, faults = memory
    specific_force, body_rates, q = truth.specific_force_body_m_s2, truth.body_rates_rad_s, truth.quaternion
    position, velocity, yaw = truth.position_m, truth.velocity_m_s, truth.euler_rad[2]
    # The biases' random walks and the baro drift since the last frame.
    if not math.isnan(S[STATE.t_last]):
        dt = t - S[STATE.t_last]
        if dt > 0.0:
            if C[FIGURES.accel_random_walk] > 0.0:
                b = random_walk(
                    rng,
                    (S[STATE.accel_bias], S[STATE.accel_bias + 1], S[STATE.accel_bias + 2]),
                    C[FIGURES.accel_random_walk],
                    dt,
                )
                S[STATE.accel_bias], S[STATE.accel_bias + 1], S[STATE.accel_bias + 2] = b[0], b[1], b[2]
            if C[FIGURES.gyro_random_walk] > 0.0:
                b = random_walk(
                    rng,
                    (S[STATE.gyro_bias], S[STATE.gyro_bias + 1], S[STATE.gyro_bias + 2]),
                    C[FIGURES.gyro_random_walk],
                    dt,
                )
                S[STATE.gyro_bias], S[STATE.gyro_bias + 1], S[STATE.gyro_bias + 2] = b[0], b[1], b[2]
            if C[FIGURES.baro_drift] > 0.0:
                S[STATE.baro_drift] += C[FIGURES.baro_drift] * math.sqrt(dt) * normal(rng)
    S[STATE.t_last] = t

    # IMU: every frame (biases with the injected steps).
    sa = fault_sum(faults, ACCEL_BIAS_STEP, t)
    sg = fault_sum(faults, GYRO_BIAS_STEP, t)
    ba = (S[STATE.accel_bias] + sa[0], S[STATE.accel_bias + 1] + sa[1], S[STATE.accel_bias + 2] + sa[2])
    bg = (S[STATE.gyro_bias] + sg[0], S[STATE.gyro_bias + 1] + sg[1], S[STATE.gyro_bias + 2] + sg[2])
    force, rates = imu_reading(
        rng, specific_force, body_rates, ba, bg, C[FIGURES.accel_std], C[FIGURES.gyro_std]
    )
    reading = S[STATE.reading : STATE.reading + READING_ROOM]
    out[DELIVERY.accel_fresh] = imu_sample(rng, S, faults, F_ACCEL, t, force, reading, out, DELIVERY.force)
    out[DELIVERY.gyro_fresh] = imu_sample(rng, S, faults, F_GYRO, t, rates, reading, out, DELIVERY.rate)

    # The scheduled sensors: a sample when due (and kept by the unit's failure), made as the
    # failure says, delivered after its latency (and a delayed failure's).
    mode, row = failure_of(faults, F_MAG, t)
    if due(S, C, MAG, t) and sample_kept(rng, S, faults, F_MAG, mode, row):
        m = magnetometer(rng, S, C, faults, q, t)
        M = MAG_READING
        reading[M.time], reading[M.field], reading[M.field + 1], reading[M.field + 2] = t, m[0], m[1], m[2]
        corrupt(rng, S, faults, F_MAG, mode, row, reading, M.size - READING.values)
        deliver(S, C, MAG, t, reading, out, extra_latency(faults, mode, row))
    else:
        pending(S, MAG, t, out)
    if mode == OFF:
        silence(S, MAG, out)
    mode, row = failure_of(faults, F_BARO, t)
    if due(S, C, BARO, t) and sample_kept(rng, S, faults, F_BARO, mode, row):
        p, h, temperature = barometer(rng, S, C, position[2])
        B = BARO_READING
        reading[B.time], reading[B.pressure] = t, p
        reading[B.altitude], reading[B.temperature] = h, temperature
        corrupt(rng, S, faults, F_BARO, mode, row, reading, B.size - READING.values)
        deliver(S, C, BARO, t, reading, out, extra_latency(faults, mode, row))
    else:
        pending(S, BARO, t, out)
    if mode == OFF:
        silence(S, BARO, out)
    mode, row = failure_of(faults, F_GPS, t)
    if C[FIGURES.gps_on] != 0.0 and due(S, C, GPS, t) and sample_kept(rng, S, faults, F_GPS, mode, row):
        gps_fix(rng, S, C, faults, t, position, velocity, reading)
        corrupt(rng, S, faults, F_GPS, mode, row, reading, GPS_READING.size - READING.values)
        deliver(S, C, GPS, t, reading, out, extra_latency(faults, mode, row))
    else:
        pending(S, GPS, t, out)
    if mode == OFF:
        silence(S, GPS, out)
    mode, row = failure_of(faults, F_VIO, t)
    if (C[FIGURES.vision_on] != 0.0 and due(S, C, VISION, t) and not fault_active(faults, VISION_OUTAGE, t)
            and sample_kept(rng, S, faults, F_VIO, mode, row)):  # fmt: skip
        p3, y = vision_reading(rng, position, yaw, C[FIGURES.vision_std], C[FIGURES.vision_yaw_std])
        V = VISION_READING
        reading[V.time] = t
        for i in range(3):
            reading[V.position + i] = p3[i]
        reading[V.yaw] = y
        reading[V.position_std], reading[V.yaw_std] = C[FIGURES.vision_std], C[FIGURES.vision_yaw_std]
        corrupt(rng, S, faults, F_VIO, mode, row, reading, V.size - READING.values)
        deliver(S, C, VISION, t, reading, out, extra_latency(faults, mode, row))
    else:
        pending(S, VISION, t, out)
    if mode == OFF:
        silence(S, VISION, out)

    # What HIL_SENSOR carries between samples: the last magnetometer and barometer readings
    # (before the first, a reading of now).
    if out[DELIVERY.mag_fresh] != 0.0:
        S[STATE.held_mag], S[STATE.held_mag + 1], S[STATE.held_mag + 2] = (
            out[DELIVERY.mag_field],
            out[DELIVERY.mag_field + 1],
            out[DELIVERY.mag_field + 2],
        )
        S[STATE.has_mag] = 1.0
    if out[DELIVERY.baro_fresh] != 0.0:
        for i in range(BARO_READING.size):
            S[STATE.held_baro + i] = out[DELIVERY.baro_time + i]
        S[STATE.has_baro] = 1.0
    if S[STATE.has_mag] != 0.0:
        for i in range(3):
            out[DELIVERY.held_mag + i] = S[STATE.held_mag + i]
    else:
        m = magnetometer(rng, S, C, faults, q, t)
        out[DELIVERY.held_mag], out[DELIVERY.held_mag + 1], out[DELIVERY.held_mag + 2] = m[0], m[1], m[2]
    if S[STATE.has_baro] != 0.0:
        for i in range(BARO_READING.size):
            out[DELIVERY.held_baro_time + i] = S[STATE.held_baro + i]
    else:
        p, h, temperature = barometer(rng, S, C, position[2])
        out[DELIVERY.held_baro_time], out[DELIVERY.held_baro_pressure] = t, p
        out[DELIVERY.held_baro_altitude], out[DELIVERY.held_baro_temperature] = h, temperature


@kernel
def sensor_frame_fields(rng: Any, S: Any, C: Any, faults: Any, t: float, truth: tuple, out: Any) -> None:
    """:func:`sensor_frame` as the entry Python calls: the memory's arrays and the
    :class:`~simulator.dynamics.equations.TruthState` as plain arguments (a compiled call types a
    plain tuple in C, a named tuple through Python: microseconds a call)."""
    sensor_frame(SensorMemory(rng, S, C, faults), t, TruthState(*truth), out)
