"""Sensor models of the simulated vehicle (IMU, magnetometer, barometer, GPS): pure functions of
the ground truth; parameters from ``config/sensors/``."""

from .config import EXACT, SensorConfig, load_sensors
from .models import (
    BaroReading,
    GpsReading,
    ImuReading,
    SensorReadings,
    SensorSuite,
    isa_altitude_m,
    isa_pressure_hpa,
    isa_temperature_c,
)

__all__ = [
    "EXACT",
    "BaroReading",
    "GpsReading",
    "ImuReading",
    "SensorConfig",
    "SensorReadings",
    "SensorSuite",
    "isa_altitude_m",
    "isa_pressure_hpa",
    "isa_temperature_c",
    "load_sensors",
]
