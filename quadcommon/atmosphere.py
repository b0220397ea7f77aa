"""The ISA troposphere (ICAO Doc 7488), written once as kernels (:mod:`quadcommon.kernel`).

The simulator's barometer turns the vehicle's altitude into a pressure with it; the autopilot
reports that pressure and its temperature back from the pressure altitude it fused (HIGHRES_IMU).

``p = p0 (1 - L h / T0)^(g M / (R L))``, valid below 11 km.
"""

from __future__ import annotations

from quadcommon.kernel import kernel

ISA_SEA_LEVEL_PRESSURE_HPA = 1013.25
ISA_SEA_LEVEL_TEMPERATURE_C = 15.0
ISA_LAPSE_RATE_K_M = 0.0065
ISA_SEA_LEVEL_TEMPERATURE_K = 288.15
ISA_EXPONENT = 5.255877  # g M / (R L)


@kernel
def isa_pressure_hpa(altitude_amsl_m: float) -> float:
    """Static pressure (hPa) at ``altitude_amsl_m`` (m) in the ISA troposphere (< 11 km)."""
    ratio = 1.0 - ISA_LAPSE_RATE_K_M * altitude_amsl_m / ISA_SEA_LEVEL_TEMPERATURE_K
    return ISA_SEA_LEVEL_PRESSURE_HPA * ratio**ISA_EXPONENT


@kernel
def isa_altitude_m(pressure_hpa: float) -> float:
    """Pressure altitude (m AMSL) of ``pressure_hpa`` (hPa): the inverse of :func:`isa_pressure_hpa`."""
    ratio = (pressure_hpa / ISA_SEA_LEVEL_PRESSURE_HPA) ** (1.0 / ISA_EXPONENT)
    return (1.0 - ratio) * ISA_SEA_LEVEL_TEMPERATURE_K / ISA_LAPSE_RATE_K_M


@kernel
def isa_temperature_c(altitude_amsl_m: float) -> float:
    """Air temperature (deg C) at ``altitude_amsl_m`` (m) in the ISA troposphere."""
    return ISA_SEA_LEVEL_TEMPERATURE_C - ISA_LAPSE_RATE_K_M * altitude_amsl_m
