"""Sensor-model parameters (``config/sensors/NAME.toml``), validated into a frozen record.

Profiles: ``ideal`` (every sensor exact: the paper's assumption), ``mocap`` (motion capture
indoors), ``gps`` (PX4-SITL-like GNSS outdoors); ``default`` is an alias of ``ideal``. A file may
name another with ``alias = "NAME"`` and nothing else.

Units and frames: SI (plus gauss and hPa, the units of ``HIL_SENSOR``); body-frame vectors in the
paper's body frame (front-left-up); the earth magnetic field is read in NED (as field models
publish it) and turned into the paper's world frame here, through :mod:`quadcommon.frames`, once.
White noise of the IMU is given as a density (per sqrt(Hz): the per-sample standard deviation is
``density * sqrt(rate)``), of the other sensors as a per-sample standard deviation; bias random
walks as densities per sqrt(s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from quadcommon import frames
from quadcommon.config import config_path
from quadcommon.failures import effect_of_kind, sensor_fault_kinds
from quadcommon.schema import ConfigError, Section, load_toml

Vector3 = tuple[float, float, float]
_Z3: Vector3 = (0.0, 0.0, 0.0)

PROFILE_FAULT_KINDS = (
    "gps_outage",  # no fix (the receiver reports fix type 1) while active
    "gps_glitch",  # position offset by `value` (m, world) while active; eph unchanged
    "vision_outage",  # no vision/mocap sample while active
    "mag_disturbance",  # field `value` (gauss, body) added while active
    "accel_bias_step",  # accelerometer bias + `value` (m/s^2, body) from start_s on
    "gyro_bias_step",  # gyro bias + `value` (rad/s, body) from start_s on
)
# The failure unit (quadcommon.failures) each profile fault kind belongs to: a recovery of the
# unit (type ok) ends them too.
PROFILE_FAULT_UNITS = {
    "gps_outage": "gps", "gps_glitch": "gps", "vision_outage": "vio", "mag_disturbance": "mag",
    "accel_bias_step": "accel", "gyro_bias_step": "gyro",
}  # fmt: skip
# ... and the sensor failures of MAV_CMD_INJECT_FAILURE ("gps_off", "baro_stuck", ...: the table
# of quadcommon.failures), `value` the table's figure unless given.
FAULT_KINDS = PROFILE_FAULT_KINDS + sensor_fault_kinds()


def fault_unit(kind: str) -> str:
    """The failure unit (``gps``, ``mag``, ...) a fault kind acts on."""
    failure = effect_of_kind(kind)
    return failure[0].name if failure is not None else PROFILE_FAULT_UNITS[kind]


def default_fault_value(kind: str) -> Vector3:
    """A fault's ``value`` when the profile gives none: the table's figure for a failure, else 0."""
    failure = effect_of_kind(kind)
    return failure[2].value if failure is not None else _Z3


@dataclass(frozen=True)
class ImuAxes:
    """One IMU triad (accelerometer or gyroscope): white noise, bias random walk, switch-on bias."""

    noise_density: float  # unit/sqrt(Hz): per-sample std = density * sqrt(sample rate)
    bias_random_walk: float  # unit/s/sqrt(Hz): the bias drifts by this * sqrt(t)
    bias: Vector3 = _Z3  # fixed switch-on bias, body
    turn_on_bias_std: float = 0.0  # random switch-on bias per axis, drawn from the seed

    @property
    def is_exact(self) -> bool:
        """No noise, no bias and no bias random walk: the axis reports the truth."""
        return (
            self.noise_density == 0.0
            and self.bias_random_walk == 0.0
            and self.bias == _Z3
            and self.turn_on_bias_std == 0.0
        )


@dataclass(frozen=True)
class MagModel:
    rate_hz: float
    latency_s: float
    noise_std_gauss: float  # per sample, per axis
    bias_gauss: Vector3  # hard iron, body
    earth_field_world_gauss: Vector3  # paper world frame (x north, y west, z up)
    turn_on_bias_std_gauss: float = 0.0  # random hard iron per axis, drawn from the seed


@dataclass(frozen=True)
class BaroModel:
    rate_hz: float
    latency_s: float
    noise_std_hpa: float  # per sample
    bias_hpa: float  # constant pressure offset
    drift_hpa_rthz: float  # random walk of the offset (hPa per sqrt(s)): the slow drift


@dataclass(frozen=True)
class GpsModel:
    """GNSS: position and velocity errors as first-order Gauss-Markov processes per axis."""

    enabled: bool
    rate_hz: float
    latency_s: float  # a fix is delivered this long after the time it is valid for
    horizontal_noise_std_m: float  # stationary std per horizontal axis
    vertical_noise_std_m: float
    position_correlation_time_s: float  # 0: white
    velocity_noise_std_m_s: float  # per axis (horizontal and vertical)
    velocity_correlation_time_s: float  # 0: white
    satellites_visible: int
    eph_m: float | None = None  # reported eph; None: honest (the horizontal std, >= 1 cm)
    epv_m: float | None = None

    @property
    def reported_eph_m(self) -> float:
        """The horizontal accuracy put in HIL_GPS ``eph`` (m): the configured one, else the horizontal
        noise std (at least 1 cm)."""
        return self.eph_m if self.eph_m is not None else max(self.horizontal_noise_std_m, 0.01)

    @property
    def reported_epv_m(self) -> float:
        """The vertical accuracy put in HIL_GPS ``epv`` (m): the configured one, else the vertical noise
        std (at least 1 cm)."""
        return self.epv_m if self.epv_m is not None else max(self.vertical_noise_std_m, 0.01)

    @property
    def reported_speed_accuracy_m_s(self) -> float:
        """The speed accuracy reported with a fix (m/s): the velocity noise std, at least 1 cm/s."""
        return max(self.velocity_noise_std_m_s, 0.01)


@dataclass(frozen=True)
class VisionModel:
    """Motion capture / vision: position of O and yaw, white noise, a latency."""

    enabled: bool
    rate_hz: float
    latency_s: float
    position_noise_std_m: float  # per axis
    yaw_noise_std_rad: float


@dataclass(frozen=True)
class SensorFault:
    """A fault injected into the sensors: active over ``[start_s, start_s + duration_s)``."""

    kind: str  # one of FAULT_KINDS
    start_s: float
    duration_s: float = math.inf
    value: Vector3 = _Z3

    def active(self, t_s: float) -> bool:
        """Whether the fault acts at simulation time ``t_s``: ``start_s <= t_s < start_s + duration_s``."""
        return self.start_s <= t_s < self.start_s + self.duration_s


@dataclass(frozen=True)
class SensorConfig:
    name: str
    seed: int
    accelerometer: ImuAxes  # m/s^2
    gyroscope: ImuAxes  # rad/s
    magnetometer: MagModel
    barometer: BaroModel
    gps: GpsModel
    vision: VisionModel
    faults: tuple[SensorFault, ...] = field(default=())

    @property
    def earth_field_world_gauss(self) -> Vector3:
        """The earth magnetic field in the world frame (x north, y west, z up; gauss)."""
        return self.magnetometer.earth_field_world_gauss


DEFAULT_EARTH_FIELD_NED_GAUSS: Vector3 = (0.21, 0.016, 0.43)  # north, east, down at home (about Zurich's)

EXACT = SensorConfig(
    name="exact",
    seed=1,
    accelerometer=ImuAxes(0.0, 0.0),
    gyroscope=ImuAxes(0.0, 0.0),
    magnetometer=MagModel(500.0, 0.0, 0.0, _Z3, frames.vector_from_ned(DEFAULT_EARTH_FIELD_NED_GAUSS)),  # type: ignore[arg-type]
    barometer=BaroModel(500.0, 0.0, 0.0, 0.0, 0.0),
    gps=GpsModel(True, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10, eph_m=1.0, epv_m=1.0),
    vision=VisionModel(False, 100.0, 0.0, 0.0, 0.0),
)
"""Noise-free sensors with the default field: what ``config/sensors/ideal.toml`` holds."""


def _imu_axes(sec: Section, unit: str, rw_unit: str, bound: float) -> ImuAxes:
    return ImuAxes(
        noise_density=sec.number(
            f"noise_density_{unit}_rthz", 0.0, lo=0.0, hi=bound, unit=f"{unit}/sqrt(Hz)"
        ),
        bias_random_walk=sec.number(
            f"bias_random_walk_{rw_unit}_rthz", 0.0, lo=0.0, hi=bound, unit=f"{rw_unit}/sqrt(Hz)"
        ),
        bias=sec.vector(f"bias_{unit}", 3, _Z3, lo=-bound, hi=bound, unit=unit),  # type: ignore[arg-type]
        turn_on_bias_std=sec.number(f"turn_on_bias_std_{unit}", 0.0, lo=0.0, hi=bound, unit=unit),
    )


def _rate_latency(sec: Section, rate_default: float) -> tuple[float, float]:
    rate = sec.number("rate_hz", rate_default, lo=0.0, lo_open=True, hi=1000.0, unit="Hz")
    latency = sec.number("latency_s", 0.0, lo=0.0, hi=1.0, unit="s")
    return rate, latency


def load_sensors(name_or_path: str | Path = "ideal", _alias_depth: int = 0) -> SensorConfig:
    """Load ``config/sensors/NAME.toml`` (or a path); errors name file, key, value and range."""
    path = config_path("sensors", name_or_path)
    root = load_toml(path)
    if root.has("alias"):
        target = root.string("alias")
        root.finish()
        if _alias_depth > 0:
            raise ConfigError(f"{path}: key 'alias' = {target!r} names another alias; allowed: a profile")
        return load_sensors(target, _alias_depth + 1)
    seed = root.integer("seed", 1, lo=0, hi=2**63 - 1)

    sec = root.section("accelerometer", optional=True)
    accel = _imu_axes(sec, "m_s2", "m_s3", 50.0)
    sec.finish()
    sec = root.section("gyroscope", optional=True)
    gyro = _imu_axes(sec, "rad_s", "rad_s2", 10.0)
    sec.finish()

    sec = root.section("magnetometer", optional=True)
    rate, latency = _rate_latency(sec, 500.0)
    field_ned = sec.vector(
        "earth_field_ned_gauss", 3, DEFAULT_EARTH_FIELD_NED_GAUSS, lo=-1.0, hi=1.0, unit="gauss"
    )
    mag = MagModel(
        rate_hz=rate,
        latency_s=latency,
        noise_std_gauss=sec.number("noise_std_gauss", 0.0, lo=0.0, hi=2.0, unit="gauss"),
        bias_gauss=sec.vector("bias_gauss", 3, _Z3, lo=-2.0, hi=2.0, unit="gauss"),  # type: ignore[arg-type]
        earth_field_world_gauss=frames.vector_from_ned(field_ned),  # type: ignore[arg-type]
        turn_on_bias_std_gauss=sec.number("turn_on_bias_std_gauss", 0.0, lo=0.0, hi=2.0, unit="gauss"),
    )
    sec.finish()

    sec = root.section("barometer", optional=True)
    rate, latency = _rate_latency(sec, 500.0)
    baro = BaroModel(
        rate_hz=rate,
        latency_s=latency,
        noise_std_hpa=sec.number("noise_std_hpa", 0.0, lo=0.0, hi=100.0, unit="hPa"),
        bias_hpa=sec.number("bias_hpa", 0.0, lo=-100.0, hi=100.0, unit="hPa"),
        drift_hpa_rthz=sec.number("drift_hpa_rthz", 0.0, lo=0.0, hi=10.0, unit="hPa/sqrt(s)"),
    )
    sec.finish()

    sec = root.section("gps", optional=True)
    rate, latency = _rate_latency(sec, 10.0)
    gps = GpsModel(
        enabled=sec.boolean("enabled", True),
        rate_hz=rate,
        latency_s=latency,
        horizontal_noise_std_m=sec.number("horizontal_noise_std_m", 0.0, lo=0.0, hi=100.0, unit="m"),
        vertical_noise_std_m=sec.number("vertical_noise_std_m", 0.0, lo=0.0, hi=100.0, unit="m"),
        position_correlation_time_s=sec.number(
            "position_correlation_time_s", 0.0, lo=0.0, hi=3600.0, unit="s"
        ),
        velocity_noise_std_m_s=sec.number("velocity_noise_std_m_s", 0.0, lo=0.0, hi=10.0, unit="m/s"),
        velocity_correlation_time_s=sec.number(
            "velocity_correlation_time_s", 0.0, lo=0.0, hi=3600.0, unit="s"
        ),
        satellites_visible=sec.integer("satellites_visible", 10, lo=0, hi=254),
        eph_m=sec.number("eph_m", lo=0.0, lo_open=True, hi=600.0, unit="m") if sec.has("eph_m") else None,
        epv_m=sec.number("epv_m", lo=0.0, lo_open=True, hi=600.0, unit="m") if sec.has("epv_m") else None,
    )
    sec.finish()

    sec = root.section("vision", optional=True)
    rate, latency = _rate_latency(sec, 100.0)
    vision = VisionModel(
        enabled=sec.boolean("enabled", False),
        rate_hz=rate,
        latency_s=latency,
        position_noise_std_m=sec.number("position_noise_std_m", 0.0, lo=0.0, hi=10.0, unit="m"),
        yaw_noise_std_rad=sec.number("yaw_noise_std_rad", 0.0, lo=0.0, hi=1.0, unit="rad"),
    )
    sec.finish()

    faults = []
    for fs in root.sections("faults"):
        kind = fs.choice("kind", FAULT_KINDS)
        faults.append(
            SensorFault(
                kind=kind,
                start_s=fs.number("start_s", lo=0.0, hi=1e6, unit="s"),
                duration_s=fs.number("duration_s", math.inf, lo=0.0, lo_open=True, hi=math.inf, unit="s")
                if fs.has("duration_s")
                else math.inf,
                value=fs.vector("value", 3, default_fault_value(kind), lo=-1e4, hi=1e4),  # type: ignore
            )
        )
        fs.finish()
    root.finish()
    return SensorConfig(
        name=Path(path).stem,
        seed=seed,
        accelerometer=accel,
        gyroscope=gyro,
        magnetometer=mag,
        barometer=baro,
        gps=gps,
        vision=vision,
        faults=tuple(faults),
    )
