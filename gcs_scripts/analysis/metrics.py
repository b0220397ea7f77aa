"""The paper's performance indices (Tables I-III), pure functions of a FlightRecord.

* Final position error per axis at the end of the run (e = actual - desired), metres.
* ISE = integral of e^2 dt per state (x, y, z, phi, theta, psi), trapezoidal rule.
* IADU = integral of |du/dt| dt = total variation of each control signal (U1, tau_phi,
  tau_theta, tau_psi), as the sum of |u[k+1] - u[k]|; it depends on the sampling of u (we sample
  at the control rate).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .record import FlightRecord

STATE_NAMES = ("x", "y", "z", "phi", "theta", "psi")
CONTROL_NAMES = ("U1", "tau_phi", "tau_theta", "tau_psi")


class Indices(NamedTuple):
    final_error_m: tuple[float, float, float]
    ise: dict[str, float]
    iadu: dict[str, float]


def final_errors(record: FlightRecord) -> tuple[float, float, float]:
    """The position error ``actual - desired`` at the record's last sample, per axis (m)."""
    e = record.position_error_m[-1]
    return (float(e[0]), float(e[1]), float(e[2]))


def ise(time_s: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Integral of squared error per column, trapezoidal."""
    sq = np.asarray(error, dtype=float) ** 2
    if sq.ndim == 1:
        sq = sq[:, None]
    dt = np.diff(time_s)[:, None]
    return np.sum(0.5 * (sq[1:] + sq[:-1]) * dt, axis=0)


def iadu(signal: np.ndarray) -> np.ndarray:
    """Total variation per column: sum |u[k+1] - u[k]|."""
    u = np.asarray(signal, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    return np.sum(np.abs(np.diff(u, axis=0)), axis=0)


def indices(record: FlightRecord) -> Indices:
    """The paper's indices of ``record`` (Tables I-III): final position error (m), ISE per state
    (x, y, z in m^2 s; phi, theta, psi in rad^2 s) and IADU per control (U1 in N, torques in N m)."""
    errors = np.column_stack([record.position_error_m, record.euler_error_rad])
    ise_values = ise(record.time_s, errors)
    iadu_values = iadu(record.controls)
    return Indices(
        final_errors(record),
        {n: float(v) for n, v in zip(STATE_NAMES, ise_values, strict=True)},
        {n: float(v) for n, v in zip(CONTROL_NAMES, iadu_values, strict=True)},
    )
