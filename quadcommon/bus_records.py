"""Row layouts published on zenoh: ground truth (simulator), controller internals and the
estimator's state and health (autopilot, ``quadsitl/<N>/estimator``, only when it flies on its EKF).

Payload of one zenoh sample = a batch of rows::

    header  "<4sHH": magic (b"QST1" truth, b"QSC1" controller, b"QSE1" estimator), row count,
            fields per row
    rows    count x fields little-endian float64, in the field order below

Paper frames (z up) and SI units; ``time_s`` is simulation time. Field names are the column names
in the recorder's Parquet file (the same names :class:`gcs_scripts.analysis.record.FlightRecord`
reads). Decoding needs only ``struct``/numpy, so any zenoh client can read the stream.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence

import numpy as np

TRUTH_MAGIC = b"QST1"
CONTROLLER_MAGIC = b"QSC1"
ESTIMATOR_MAGIC = b"QSE1"
_HEADER = struct.Struct("<4sHH")

TRUTH_FIELDS = (
    "time_s",
    "x_m", "y_m", "z_m",  # position of O, world
    "vx_m_s", "vy_m_s", "vz_m_s",
    "ax_m_s2", "ay_m_s2", "az_m_s2",
    "qw", "qx", "qy", "qz",  # body to world
    "phi_rad", "theta_rad", "psi_rad",
    "p_rad_s", "q_rad_s", "r_rad_s",  # body rates (front-left-up)
    "Ax_n", "Ay_n", "Az_n",  # applied disturbance force, world, at the CoM
    "Ap_n_m", "Aq_n_m", "Ar_n_m",  # applied disturbance torque on the Euler coordinates
    "wind_x_m_s", "wind_y_m_s", "wind_z_m_s",
    "thrust_n",  # applied U1
    "tau_x_n_m", "tau_y_n_m", "tau_z_n_m",  # applied control torque, body
    "rotor1_rad_s", "rotor2_rad_s", "rotor3_rad_s", "rotor4_rad_s",  # 1 front, 2 right, 3 rear, 4 left
    # the rotors' health (the same order): the fraction of thrust and reaction torque each gives
    # (1 healthy, 0 off), and its failure as MAVLink's FAILURE_TYPE (0 none, 1 off, 2 stuck, 4
    # wrong: a loss of effectiveness); on the ideal-wrench vehicle, its share of the wrench's
    "rotor1_effectiveness", "rotor2_effectiveness", "rotor3_effectiveness", "rotor4_effectiveness",
    "rotor1_failure", "rotor2_failure", "rotor3_failure", "rotor4_failure",
    "on_ground",
)  # fmt: skip

CONTROLLER_FIELDS = (
    "time_s",
    "x_ref_m", "y_ref_m", "z_ref_m",
    "vx_ref_m_s", "vy_ref_m_s", "vz_ref_m_s",
    "ax_ref_m_s2", "ay_ref_m_s2", "az_ref_m_s2",
    "phi_ref_rad", "theta_ref_rad", "psi_ref_rad",  # eta_d (filtered), as the inner loop sees it
    "phi_raw_rad", "theta_raw_rad",  # phi_r, theta_r from eq. 29, before the command filter
    "U1_n", "tau_phi_n_m", "tau_theta_n_m", "tau_psi_n_m",  # applied, Euler coordinates
    "armed", "custom_mode",
)  # fmt: skip


ESTIMATOR_FIELDS = (
    "time_s",
    "x_est_m", "y_est_m", "z_est_m",  # the estimate the controllers fly on (paper frames)
    "vx_est_m_s", "vy_est_m_s", "vz_est_m_s",
    "phi_est_rad", "theta_est_rad", "psi_est_rad",
    "gyro_bias_x_rad_s", "gyro_bias_y_rad_s", "gyro_bias_z_rad_s",
    "accel_bias_x_m_s2", "accel_bias_y_m_s2", "accel_bias_z_m_s2",
    "pos_horiz_accuracy_m", "pos_vert_accuracy_m", "vel_accuracy_m_s", "tilt_accuracy_rad",
    "yaw_accuracy_rad",  # 1-sigma from the covariance
    "vel_ratio", "pos_horiz_ratio", "pos_vert_ratio", "mag_ratio",  # PX4's test ratios (<= 1 passes)
    # normalised innovation (innovation / sqrt(S)) of the last sample of each kind
    "innov_gps_pos", "innov_gps_vel", "innov_baro", "innov_mag", "innov_ev_pos", "innov_ev_yaw",
    "flags", "converged",  # ESTIMATOR_STATUS_FLAGS; 1 when fit to arm on
)  # fmt: skip


class RowCodec:
    """Encodes rows (sequences of floats) into a batch payload and decodes it to an array."""

    def __init__(self, magic: bytes, fields: Sequence[str]) -> None:
        self.magic = magic
        self.fields = tuple(fields)
        self.width = len(self.fields)
        self._row = struct.Struct(f"<{self.width}d")

    def encode(self, rows: Iterable[Sequence[float]]) -> bytes:
        """``rows`` (each ``width`` floats) as one payload: the header (magic, count, width), then
        the rows as float64."""
        packed = [self._row.pack(*row) for row in rows]
        return _HEADER.pack(self.magic, len(packed), self.width) + b"".join(packed)

    def decode(self, payload: bytes) -> np.ndarray:
        """(count, width) float64 array; raises ValueError on a foreign or truncated payload."""
        if len(payload) < _HEADER.size:
            raise ValueError("payload shorter than the header")
        magic, count, width = _HEADER.unpack_from(payload)
        if magic != self.magic:
            raise ValueError(f"expected magic {self.magic!r}, got {magic!r}")
        if width != self.width:
            raise ValueError(f"expected {self.width} fields per row, got {width}")
        expected = _HEADER.size + count * width * 8
        if len(payload) != expected:
            raise ValueError(f"payload is {len(payload)} bytes, expected {expected}")
        return np.frombuffer(payload, dtype="<f8", offset=_HEADER.size).reshape(count, width)


TRUTH_CODEC = RowCodec(TRUTH_MAGIC, TRUTH_FIELDS)
CONTROLLER_CODEC = RowCodec(CONTROLLER_MAGIC, CONTROLLER_FIELDS)
ESTIMATOR_CODEC = RowCodec(ESTIMATOR_MAGIC, ESTIMATOR_FIELDS)
