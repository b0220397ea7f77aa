"""Sensor models of the simulated vehicle (IMU, magnetometer, barometer, GPS, motion capture):
pure functions of the ground truth and time; parameters from ``config/sensors/`` (profiles
``ideal``, ``mocap``, ``gps``)."""

from quadcommon.atmosphere import isa_altitude_m, isa_pressure_hpa, isa_temperature_c

from .config import EXACT, FAULT_KINDS, SensorConfig, SensorFault, load_sensors
from .models import (
    BaroReading,
    GpsReading,
    ImuReading,
    MagReading,
    SensorFrame,
    SensorReadings,
    SensorSuite,
    VisionReading,
)

__all__ = [
    "EXACT",
    "FAULT_KINDS",
    "BaroReading",
    "GpsReading",
    "ImuReading",
    "MagReading",
    "SensorConfig",
    "SensorFault",
    "SensorFrame",
    "SensorReadings",
    "SensorSuite",
    "VisionReading",
    "isa_altitude_m",
    "isa_pressure_hpa",
    "isa_temperature_c",
    "load_sensors",
]
