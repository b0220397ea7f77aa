"""Sensor-model parameters (``config/sensors/NAME.toml``), validated into a frozen record.

Body-frame vectors are in the paper's body frame (front-left-up); the earth magnetic field is
read in NED (as field models publish it) and turned into the paper's world frame here, through
:mod:`quadcommon.frames`, once.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from quadcommon import frames
from quadcommon.config import config_path
from quadcommon.schema import Section, load_toml

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class NoisyVector:
    """A three-axis sensor error: constant bias plus white noise of ``noise_std`` per sample."""

    noise_std: float
    bias: Vector3

    @property
    def is_exact(self) -> bool:
        return self.noise_std == 0.0 and self.bias == (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class GpsModel:
    horizontal_noise_std_m: float
    vertical_noise_std_m: float
    velocity_noise_std_m_s: float
    eph_m: float  # reported horizontal accuracy
    epv_m: float  # reported vertical accuracy
    satellites_visible: int


@dataclass(frozen=True)
class SensorConfig:
    name: str
    seed: int
    accelerometer: NoisyVector  # m/s^2
    gyroscope: NoisyVector  # rad/s
    magnetometer: NoisyVector  # gauss
    earth_field_world_gauss: Vector3  # paper world frame (x north, y west, z up)
    barometer_noise_std_hpa: float
    barometer_bias_hpa: float
    gps: GpsModel


EXACT = SensorConfig(
    name="exact",
    seed=1,
    accelerometer=NoisyVector(0.0, (0.0, 0.0, 0.0)),
    gyroscope=NoisyVector(0.0, (0.0, 0.0, 0.0)),
    magnetometer=NoisyVector(0.0, (0.0, 0.0, 0.0)),
    earth_field_world_gauss=frames.vector_from_ned((0.21, 0.016, 0.43)),
    barometer_noise_std_hpa=0.0,
    barometer_bias_hpa=0.0,
    gps=GpsModel(0.0, 0.0, 0.0, 1.0, 1.0, 10),
)
"""Noise-free sensors with the default field: what ``config/sensors/default.toml`` holds."""


def _noisy(sec: Section, std_key: str, bias_key: str, bound: float, unit: str) -> NoisyVector:
    return NoisyVector(
        noise_std=sec.number(std_key, 0.0, lo=0.0, hi=bound, unit=unit),
        bias=sec.vector(bias_key, 3, (0.0, 0.0, 0.0), lo=-bound, hi=bound, unit=unit),  # type: ignore[arg-type]
    )


def load_sensors(name_or_path: str | Path = "default") -> SensorConfig:
    """Load ``config/sensors/NAME.toml`` (or a path); errors name file, key, value and range."""
    path = config_path("sensors", name_or_path)
    root = load_toml(path)
    seed = root.integer("seed", 1, lo=0, hi=2**63 - 1)

    sec = root.section("accelerometer", optional=True)
    accel = _noisy(sec, "noise_std_m_s2", "bias_m_s2", 50.0, "m/s^2")
    sec.finish()
    sec = root.section("gyroscope", optional=True)
    gyro = _noisy(sec, "noise_std_rad_s", "bias_rad_s", 10.0, "rad/s")
    sec.finish()
    sec = root.section("magnetometer", optional=True)
    mag = _noisy(sec, "noise_std_gauss", "bias_gauss", 2.0, "gauss")
    field_ned = sec.vector("earth_field_ned_gauss", 3, (0.21, 0.016, 0.43), lo=-1.0, hi=1.0, unit="gauss")
    sec.finish()

    sec = root.section("barometer", optional=True)
    baro_std = sec.number("noise_std_hpa", 0.0, lo=0.0, hi=100.0, unit="hPa")
    baro_bias = sec.number("bias_hpa", 0.0, lo=-100.0, hi=100.0, unit="hPa")
    sec.finish()

    sec = root.section("gps", optional=True)
    gps = GpsModel(
        horizontal_noise_std_m=sec.number("horizontal_noise_std_m", 0.0, lo=0.0, hi=100.0, unit="m"),
        vertical_noise_std_m=sec.number("vertical_noise_std_m", 0.0, lo=0.0, hi=100.0, unit="m"),
        velocity_noise_std_m_s=sec.number("velocity_noise_std_m_s", 0.0, lo=0.0, hi=10.0, unit="m/s"),
        eph_m=sec.number("eph_m", 1.0, lo=0.0, lo_open=True, hi=600.0, unit="m"),
        epv_m=sec.number("epv_m", 1.0, lo=0.0, lo_open=True, hi=600.0, unit="m"),
        satellites_visible=sec.integer("satellites_visible", 10, lo=0, hi=254),
    )
    sec.finish()
    root.finish()
    return SensorConfig(
        name=Path(path).stem,
        seed=seed,
        accelerometer=accel,
        gyroscope=gyro,
        magnetometer=mag,
        earth_field_world_gauss=frames.vector_from_ned(field_ned),  # type: ignore[arg-type]
        barometer_noise_std_hpa=baro_std,
        barometer_bias_hpa=baro_bias,
        gps=gps,
    )
