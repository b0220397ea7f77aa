"""Shared test helpers: MAVLink frames as the autopilot sends them, synthetic bus rows."""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from gcs_scripts import link  # noqa: F401  (sets MAVLINK20/common before pymavlink loads)
from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS


class Vehicle:
    """Packs MAVLink 2 frames as vehicle ``instance`` (sysid 1+N, compid 1) would."""

    def __init__(self, instance: int = 0, component: int = 1) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=1 + instance, srcComponent=component)

    def pack(self, msg) -> bytes:
        frame = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) & 0xFF  # pack() does not advance it (notes, B1)
        return bytes(frame)

    def local_position(self, t_s: float, x: float, y: float = 0.0, z: float = 0.0) -> bytes:
        return self.pack(mavlink2.MAVLink_local_position_ned_message(int(round(t_s * 1e3)), x, y, z, 0, 0, 0))

    def heartbeat(self, armed: bool, custom_mode: int = 6 << 16) -> bytes:
        base = 1 | (128 if armed else 0)
        return self.pack(mavlink2.MAVLink_heartbeat_message(2, 12, base, custom_mode, 4, 3))

    def extended_sys_state(self, landed_state: int) -> bytes:
        return self.pack(mavlink2.MAVLink_extended_sys_state_message(0, landed_state))

    def attitude(self, t_s: float, roll: float, pitch: float, yaw: float) -> bytes:
        return self.pack(mavlink2.MAVLink_attitude_message(int(round(t_s * 1e3)), roll, pitch, yaw, 0, 0, 0))

    def home_position(self, time_usec: int, altitude_m: float = 488.0) -> bytes:
        msg = mavlink2.MAVLink_home_position_message(
            0, 0, int(altitude_m * 1000), 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, time_usec
        )
        return self.pack(msg)

    def statustext(self, text: str) -> bytes:
        return self.pack(mavlink2.MAVLink_statustext_message(6, text.encode(), 0, 0))


def parse(frames: list[bytes]) -> list:
    """Frames -> pymavlink message objects (as a receiver would see them)."""
    parser = mavlink2.MAVLink(None)
    out = []
    for f in frames:
        out.extend(parser.parse_buffer(f) or [])
    return out


def truth_x(t):
    return np.sin(t)


def ref_x(t):
    return np.sin(t) + 0.01 * np.cos(3.0 * t)


def truth_rows(times: np.ndarray) -> np.ndarray:
    """Truth rows with known values: x = sin t, phi = 0.1 t, disturbance Ax steps at t >= 1."""
    rows = np.zeros((len(times), len(TRUTH_FIELDS)))
    col = {n: i for i, n in enumerate(TRUTH_FIELDS)}
    rows[:, col["time_s"]] = times
    rows[:, col["x_m"]] = truth_x(times)
    rows[:, col["y_m"]] = 0.5 * np.cos(times)
    rows[:, col["z_m"]] = 1.0 + 0.1 * times
    rows[:, col["phi_rad"]] = 0.1 * times
    rows[:, col["theta_rad"]] = -0.05 * times
    rows[:, col["psi_rad"]] = 0.3
    rows[:, col["Ax_n"]] = np.where(times >= 1.0, 1.0, 0.0)
    rows[:, col["Ap_n_m"]] = np.where(times >= 2.0, 0.5, 0.0)
    rows[:, col["qw"]] = 1.0
    return rows


def controller_rows(times: np.ndarray) -> np.ndarray:
    rows = np.zeros((len(times), len(CONTROLLER_FIELDS)))
    col = {n: i for i, n in enumerate(CONTROLLER_FIELDS)}
    rows[:, col["time_s"]] = times
    rows[:, col["x_ref_m"]] = ref_x(times)
    rows[:, col["y_ref_m"]] = 0.5 * np.cos(times) + 0.002
    rows[:, col["z_ref_m"]] = 1.0 + 0.1 * times - 0.003
    rows[:, col["phi_ref_rad"]] = 0.1 * times + 0.01 * np.sin(times)
    rows[:, col["theta_ref_rad"]] = -0.05 * times
    rows[:, col["psi_ref_rad"]] = 0.3 + 0.001
    rows[:, col["U1_n"]] = 9.81 + np.sin(5.0 * times)
    rows[:, col["tau_phi_n_m"]] = 0.01 * np.cos(7.0 * times)
    rows[:, col["tau_theta_n_m"]] = 0.02 * np.sin(2.0 * times)
    rows[:, col["tau_psi_n_m"]] = 0.001 * times
    rows[:, col["armed"]] = 1.0
    rows[:, col["custom_mode"]] = 6 << 16
    return rows


def control_times(start_s: float, count: int, dt: float = 0.002) -> np.ndarray:
    """Control-step instants as the simulator computes them: k * dt (float, not µs-rounded)."""
    k = np.arange(count) + int(round(start_s / dt))
    return k * dt


__all__ = ["Vehicle", "parse", "truth_rows", "controller_rows", "control_times", "truth_x", "ref_x"]
