"""Error-state extended Kalman filter for an IMU-driven quadrotor (pure: no I/O, no clock).

References: J. Solà, *Quaternion kinematics for the error-state Kalman filter*, arXiv:1711.02508
(2017): cited by section (§5 the ESKF for IMU-driven systems, §6 fusion with complementary
sensors, §7 the variant with global angular errors used here) and by equation number where the
number is unambiguous (eq. 269, the covariance prediction). PX4's EKF2 for parameter names,
defaults and the handling of gates, floors and checks.

Nominal state (paper frames: world x north / y west / z up, body front-left-up):
``p`` (m), ``v`` (m/s), ``q`` (body to world), gyro bias ``b_g`` (rad/s), accelerometer bias
``b_a`` (m/s^2), magnetometer hard-iron bias ``b_m`` (gauss, body) and baro height offset ``b_h``
(m). Error state (19): ``dx = [dp, dv, dtheta, db_g, db_a, db_m, db_h]`` with a *global* angular
error, ``q_true = Exp(dtheta) (x) q`` (Solà §7, the ESKF using global angular errors): the attitude
error lives in the world frame, so a yaw measurement's Jacobian is ``~[0, 0, 1]`` and the
error-state transition has identity diagonal blocks.

Prediction, per IMU sample (the control rate), from ``t_{k-1}`` to ``t_k = t_{k-1} + dt``:

* nominal state (Solà §5.4.1 / §7.2.1, with trapezoidal samples, second order in dt):
  ``q <- q (x) Exp((w_{k-1} + w_k)/2 - b_g) dt)``;
  ``a_j = R_j (f_j - b_a)`` the world specific force of sample j;
  ``p <- p + v dt + (a_{k-1}/3 + a_k/6 - g e_z/2) dt^2``, ``v <- v + ((a_{k-1} + a_k)/2 - g e_z) dt``
  (exact for a specific force linear in time over the step);
* covariance (eq. 269): ``P <- F P F^T + Q``, ``F = I + A dt`` truncated at first order (Solà
  §5.4.3, global-error form of §7.2.3) with the non-zero blocks
  ``F_pv = I dt``, ``F_v theta = -[a]_x dt``, ``F_v ba = -R dt``, ``F_theta bg = -R dt``, and
  ``Q = diag(0, s_a^2 dt I, s_g^2 dt I, s_bg^2 dt I, s_ba^2 dt I, s_bm^2 dt I, s_bh^2 dt)`` from the
  noise densities (see :mod:`.parameters` for how PX4's figures become densities).

Correction (Solà §6.1-6.3, §7.3): one measurement (all its axes) is one batch update,
``K = P H^T S^-1``, ``S = H P H^T + R``, with the covariance in Joseph form,
``P <- (I - K H) P (I - K H)^T + K R K^T`` (the factorised form, never the algebraically equal
``P - K H P``, so the update stays symmetric and positive for any gain). First every group of
axes (GPS horizontal position, GPS height, GPS horizontal velocity, ...) passes its innovation
gate on the prior, as PX4 gates them: a group with ``innovation^2 > gate^2 S`` on any axis is
rejected and counted. The error ``K y`` is then injected into the nominal state (§6.2,
``q <- Exp(dtheta) (x) q``) and the error reset with ``P <- G P G^T``,
``G_theta = I + [dtheta/2]_x`` (§7.3.3, the global-error sign; skipped below 1 mrad).

Delayed measurements: after every prediction the nominal state is stored in a ring buffer
(``RING`` IMU steps: 8 s at 500 Hz; the EKF2_*_DELAY parameters stop at 300 ms). A sample valid
at ``t_m = arrival - delay`` is compared with the buffered state at ``t_m`` (its innovation is
the one the measurement really has), and its correction is applied to the current state with the
current covariance, the measurement Jacobian carried to now to first order: for a position,
``dp(t_m) = dp - D dv`` with ``D = t - t_m``. Corrections applied since ``t_m`` are added to the
buffered state (cumulative-correction bookkeeping, so no sample is fused against a stale past).
This is the "delayed-state buffer" of PX4's EKF2 without its delayed time horizon: one filter,
one propagation, no output predictor; the neglected terms are of order ``D x (velocity and
attitude uncertainty)``, well below the noise of the delayed sensors (mm for a 0.1 s GPS delay).

Hot path: the filter's steps are kernels written once: :mod:`.filter` (its memory's layouts,
prediction and buffering, the convergence verdict), :mod:`.fusion` (the fusions with their gates)
and :mod:`.checks` (their quality checks and resets), over the arithmetic of :mod:`.kernels`; this
class is their shell. It calls their compiled entries (numba: one call per IMU sample, one per
fusion), or the same functions run by Python where nothing compiles (``QUADSITL_PURE_PYTHON=1``;
slower), and keeps in Python what runs once or reports: the alignment at rest, the records and the
messages. The filter's memory is the float arrays of :func:`.filter.new_memory`, which a batch
engine's compiled loop holds in the same layout (:func:`sitl.campaign.kernels.simulate_estimated`).
``benchmarks/estimator.py`` measures the choices: a prediction costs a few microseconds, so the
covariance is predicted at every IMU sample (PX4's 100 Hz down-sampling is not needed).

(One module: the filter's Python face, one class over one memory: the alignment, the calls of
the compiled entries, the records and the messages; the kernels are in :mod:`.filter`,
:mod:`.fusion` and :mod:`.checks`.)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, NamedTuple

import numpy as np

from quadcommon import frames
from quadcommon.kernel import compiled, compiling, freeze
from quadcommon.layout import fields_of, generated, reader
from quadcommon.rigid_body import (
    euler_from_quaternion,
    euler_rates_from_body_rates,
    quaternion_from_euler,
    rotation_from_quaternion,
)

from ..records import BaroSample, GpsFix, ImuSample, MagSample, VisionPose
from . import aiding, checks, fusion, kernels
from . import filter as fk
from .aiding import NO_AIDING, Aiding
from .kernels import IBA, IBG, IBH, IBM, IP, ITH, IV, N, update_work_size
from .parameters import (
    DEFAULT_PARAMS,
    EV_CTRL_HPOS,
    EV_CTRL_VPOS,
    EV_CTRL_YAW,
    GPS_CTRL_HPOS,
    GPS_CTRL_VEL,
    MAG_TYPE_NONE,
    EstimatorParams,
)
from .status import (
    ESTIMATOR_ACCEL_ERROR,
    ESTIMATOR_ATTITUDE,
    ESTIMATOR_CONST_POS_MODE,
    ESTIMATOR_GPS_GLITCH,
    ESTIMATOR_POS_HORIZ_ABS,
    ESTIMATOR_POS_HORIZ_REL,
    ESTIMATOR_POS_VERT_ABS,
    ESTIMATOR_PRED_POS_HORIZ_ABS,
    ESTIMATOR_PRED_POS_HORIZ_REL,
    ESTIMATOR_VELOCITY_HORIZ,
    ESTIMATOR_VELOCITY_VERT,
    SOURCE,
    SOURCE_NAMES,
    Estimate,
    EstimatorStatus,
    SourceStats,
)

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

DEFAULT_EARTH_FIELD_WORLD_GAUSS: Vector3 = frames.vector_from_ned((0.21, 0.016, 0.43))  # type: ignore[assignment]
"""The simulator's default field (about Zurich's), in the paper's world frame."""

REST_GYRO_RAD_S = 0.05  # alignment: at rest when |gyro| stays below this ...
REST_ACCEL_M_S2 = 0.5  # ... and ||f| - g| below this
GLITCH_FLAG_S = 1.0  # ESTIMATOR_GPS_GLITCH while a GPS position was gated out this recently

_Z3 = (0.0, 0.0, 0.0)


_STATS_INTEGERS = {f.name for f in fields_of(fk.STATS) if isinstance(getattr(SourceStats, f.name), int)}
_STATS_INTEGER_AT = tuple(i for i, f in enumerate(fields_of(fk.STATS)) if f.name in _STATS_INTEGERS)
if [f.name for f in dataclasses.fields(SourceStats)] != [f.name for f in fields_of(fk.STATS)]:
    raise ImportError("SourceStats's fields must be the filter's STATS layout, in its order")


class SourceRow:
    """One measurement kind's figures (:class:`~.status.SourceStats`' fields), read from the
    filter's ``stats`` array as they are now."""

    __slots__ = ("_row",)

    def __init__(self, row: np.ndarray) -> None:
        self._row = row

    def snapshot(self) -> SourceStats:
        """The row as a :class:`~.status.SourceStats` record (a copy: it no longer follows the filter)."""
        values = self._row.tolist()
        for i in _STATS_INTEGER_AT:
            values[i] = int(values[i])
        return SourceStats(*values)  # (its fields are the layout's, in order: checked below)


def _stats_property(index: int, integer: bool, doc: str) -> property:
    if integer:
        return property(lambda self: int(self._row[index]), doc=doc)
    return property(lambda self: float(self._row[index]), doc=doc)


for _field in fields_of(fk.STATS):
    setattr(SourceRow, _field.name, _stats_property(
        getattr(fk.STATS, _field.name), _field.name in _STATS_INTEGERS,
        f"This source's :attr:`~.status.SourceStats.{_field.name}`, read from the filter as it is now.",
    ))  # fmt: skip


def _span(name: str) -> tuple[int, int]:
    """Where the nominal state's field ``name`` lies in the memory (layout :data:`.filter.MEMORY`)."""
    start = getattr(fk.MEMORY, name)
    return start, start + next(f.width() for f in fields_of(fk.MEMORY) if f.name == name)


def _state_property(name: str, doc: str) -> property:
    """The memory's field ``name`` as a tuple (read), or set from any sequence of floats."""
    start, end = _span(name)

    def get(self: ErrorStateEkf) -> tuple[float, ...]:
        return tuple(self._F[start:end].tolist())

    def put(self: ErrorStateEkf, value: Any) -> None:
        self._F[start:end] = [float(c) for c in value]

    return property(get, put, doc=doc)


# What estimate() reads: one list of the memory's head, its fields at offsets generated from the layout.
_ESTIMATED = ("p", "v", "q", "rate", "gyro_bias", "accel_bias", "mag_bias", "baro_bias")
_ESTIMATE_END = max(_span(name)[1] for name in _ESTIMATED)
_estimate_of = generated(fk.MEMORY, """
def estimate_of(x, time_s):
    q, rate = {q}, {rate}
    euler = euler_from_quaternion(q[0], q[1], q[2], q[3])
    return Estimate(time_s, {p}, {v}, q, euler, rate, euler_rates_from_body_rates(euler[0], euler[1], rate),
                    {gyro_bias}, {accel_bias}, {mag_bias}, {baro_bias})
""", {"Estimate": Estimate, "euler_from_quaternion": euler_from_quaternion,
      "euler_rates_from_body_rates": euler_rates_from_body_rates})  # fmt: skip
_READ_BIASES = reader(fk.MEMORY, ("gyro_bias", "accel_bias"))


class ErrorStateEkf:
    """The filter. Feed it with :meth:`predict` every IMU sample and ``fuse_*`` as samples
    arrive (after the prediction of their arrival step); read :meth:`estimate` and
    :meth:`status`. Until aligned it collects samples (:attr:`initialised` False)."""

    _p = _state_property("p", "position (m)")
    _v = _state_property("v", "velocity (m/s)")
    _q = _state_property("q", "attitude, body to world")
    _bg = _state_property("gyro_bias", "gyro bias (rad/s)")
    _ba = _state_property("accel_bias", "accelerometer bias (m/s^2)")
    _bm = _state_property("mag_bias", "magnetometer hard iron (gauss)")

    def __init__(
        self,
        params: EstimatorParams = DEFAULT_PARAMS,
        *,
        earth_field_world_gauss: Vector3 = DEFAULT_EARTH_FIELD_WORLD_GAUSS,
        gravity_m_s2: float = 9.81,
    ) -> None:
        self.gravity = gravity_m_s2
        self.earth_field = tuple(float(c) for c in earth_field_world_gauss)
        self._F, self.P, self._ring, self._stats, self._windows, self._scratch = fk.new_memory()
        self.set_params(params)
        self._entries = filter_entries()
        self.sources: dict[str, SourceRow] = {
            name: SourceRow(self._stats[getattr(SOURCE, name)]) for name in SOURCE_NAMES
        }
        self.initialised = False
        self.init_time_s = -1.0

        # Alignment accumulators.
        self._align_n = 0
        self._align_t0 = 0.0
        self._align_f = [0.0, 0.0, 0.0]
        self._align_w = [0.0, 0.0, 0.0]
        self._align_w2 = [0.0, 0.0, 0.0]
        self._align_f2 = [0.0, 0.0, 0.0]
        self._align_m = [0.0, 0.0, 0.0]
        self._align_mn = 0
        self._pending_gps: GpsFix | None = None
        self._pending_vision: VisionPose | None = None
        self._pending_baro: BaroSample | None = None
        self._align_reason = "aligning: no IMU sample yet"

    def set_params(self, params: EstimatorParams) -> None:
        """New parameters from the next sample on (a PARAM_SET of an EKF2_* parameter): the
        process noise is derived again; the state and covariance are kept."""
        self.params = params
        self._A = fk.parameter_array(params, self.gravity, self.earth_field)
        self._F[fk.MEMORY.q_dt] = -1.0

    # -- read-outs of the memory -------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulation time (s) of the nominal state: the last IMU sample predicted to, or the
        initialisation."""
        return float(self._F[fk.MEMORY.time])

    @property
    def imu_samples(self) -> int:
        """IMU samples received, counted from the first one (alignment included)."""
        return int(self._F[fk.MEMORY.imu_samples])

    @property
    def imu_dt_rejected(self) -> int:
        """IMU samples not integrated because their interval was not within (0, 0.1] s."""
        return int(self._F[fk.MEMORY.imu_dt_rejected])

    @property
    def bad_accel_detections(self) -> int:
        """Detections of bad vertical accelerometer data (PX4's bad-acceleration check: over 1 s, large
        vertical velocity innovations of one sign, which the height innovation shares); each starts a hold
        of PX4's larger vertical process noise (``BAD_ACCEL_HOLD_S``)."""
        return int(self._F[fk.MEMORY.bad_accel_detections])

    @property
    def _bh(self) -> float:
        return float(self._F[fk.MEMORY.baro_bias])

    # ------------------------------------------------------------------------------------------
    # Prediction
    # ------------------------------------------------------------------------------------------
    def predict(self, imu: ImuSample) -> None:
        """Propagate the nominal state and the covariance over ``imu.dt_s`` (see module doc)."""
        if not self.initialised:
            self._F[fk.MEMORY.imu_samples] += 1.0
            self._align(imu)
            return
        self._entries.predict_step(self._F, self.P, self._ring, self._A, imu.time_s, imu.dt_s,
                                   imu.angular_rate_rad_s, imu.specific_force_m_s2)  # fmt: skip

    def _restart_trapezoid(self, imu: ImuSample) -> None:
        fk.restart_trapezoid(self._F, imu.angular_rate_rad_s, imu.specific_force_m_s2)

    # ------------------------------------------------------------------------------------------
    # Alignment and explicit initialisation
    # ------------------------------------------------------------------------------------------
    def _align(self, imu: ImuSample) -> None:
        """Collect IMU samples at rest; initialise once ``EST_ALIGN_T`` of them and a position
        source are there (tilt from the mean specific force, gyro bias from the mean rate)."""
        self._F[fk.MEMORY.time] = imu.time_s
        g = imu.angular_rate_rad_s
        f = imu.specific_force_m_s2
        at_rest = (
            math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) < REST_GYRO_RAD_S
            and abs(math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) - self.gravity) < REST_ACCEL_M_S2
        )
        if not at_rest:
            self._align_n = 0
            self._align_mn = 0
            self._align_reason = "aligning: the IMU is not at rest (keep the vehicle still)"
            return
        if self._align_n == 0:
            self._align_t0 = imu.time_s
            self._align_f = [0.0, 0.0, 0.0]
            self._align_w = [0.0, 0.0, 0.0]
            self._align_w2 = [0.0, 0.0, 0.0]
            self._align_f2 = [0.0, 0.0, 0.0]
            self._align_m = [0.0, 0.0, 0.0]
            self._align_mn = 0
        self._align_n += 1
        for i in range(3):
            self._align_f[i] += f[i]
            self._align_f2[i] += f[i] * f[i]
            self._align_w[i] += g[i]
            self._align_w2[i] += g[i] * g[i]
        elapsed = imu.time_s - self._align_t0
        need = self.params.align_time_s
        if elapsed < need:
            self._align_reason = f"aligning: IMU at rest for {elapsed:.1f} s of {need:.1f} s"
            return
        p = self.params
        vision_position = self._pending_vision is not None and p.ev_ctrl & (EV_CTRL_HPOS | EV_CTRL_VPOS)
        position = vision_position or (self._pending_gps is not None and p.gps_ctrl & GPS_CTRL_HPOS)
        if not position:
            sources = []
            if p.gps_ctrl & GPS_CTRL_HPOS:
                eph, sats = p.gps_req_eph_m, p.gps_req_nsats
                sources.append(f"a GPS 3D fix with eph <= {eph:g} m and >= {sats} satellites")
            if p.ev_ctrl & (EV_CTRL_HPOS | EV_CTRL_VPOS):
                sources.append("vision")
            wanted = " or ".join(sources) or "none enabled (EKF2_GPS_CTRL, EKF2_EV_CTRL)"
            self._align_reason = f"aligning: waiting for a position source ({wanted})"
            return
        heading = (self._pending_vision is not None and self.params.ev_ctrl & EV_CTRL_YAW) or (
            self._align_mn > 0 and self.params.mag_type != MAG_TYPE_NONE
        )
        if not heading:
            # Without one the yaw is unobservable at rest, and an EKF linearised about a wrong yaw
            # invents information about it (and about the accelerometer bias): do not start.
            self._align_reason = "aligning: waiting for a heading source (magnetometer, or vision yaw)"
            return
        self._initialise_from_alignment(imu)

    def _mag_heading(self, m: Vector3, phi: float, theta: float, bias: Vector3) -> float:
        return fusion.mag_heading(self._A, m, phi, theta, bias)

    def _initialise_from_alignment(self, imu: ImuSample) -> None:
        p = self.params
        n = self._align_n
        fbar = [s / n for s in self._align_f]
        wbar = [s / n for s in self._align_w]
        # Tilt from gravity: at rest f = R^T g e_z, so roll = atan2(f_y, f_z), pitch = asin(-f_x/|f|).
        phi = math.atan2(fbar[1], fbar[2])
        theta = math.atan2(-fbar[0], math.hypot(fbar[1], fbar[2]))
        yaw_bm = None
        vision = self._pending_vision
        if vision is not None and p.ev_ctrl & EV_CTRL_YAW:
            yaw = vision.yaw_rad
            yaw_var = fusion.ev_yaw_variance(self._A, vision.yaw_std_rad)
        else:  # the magnetometer (_align checked that one of the two is there)
            mbar = tuple(s / self._align_mn for s in self._align_m)
            yaw = self._mag_heading(mbar, phi, theta, _Z3)
            # Heading error from the unknown hard iron: dpsi = -J db_m (J by central differences).
            eps = 1e-4
            J = []
            for i in range(3):
                hi = list(mbar)
                lo = list(mbar)
                hi[i] += eps
                lo[i] -= eps
                J.append(
                    frames.wrap_pi(
                        self._mag_heading(tuple(hi), phi, theta, _Z3)
                        - self._mag_heading(tuple(lo), phi, theta, _Z3)
                    )
                    / (2.0 * eps)
                )
            yaw_bm = J
            noise = p.mag_noise_gauss / max(math.hypot(self.earth_field[0], self.earth_field[1]), 1e-3)
            yaw_var = (
                p.mag_bias_init_gauss**2 * (J[0] ** 2 + J[1] ** 2 + J[2] ** 2) + noise**2 / self._align_mn
            )
        q = quaternion_from_euler(phi, theta, yaw)
        self._q = q

        P = np.zeros((N, N))
        # Accelerometer bias prior, and the tilt error it causes: the alignment makes the
        # horizontal specific force vanish, so g dth_y = (R b_a)_x and g dth_x = -(R b_a)_y.
        R = rotation_from_quaternion(*q)
        g = self.gravity
        M = np.zeros((3, 3))
        M[0, :] = [-R[1][0] / g, -R[1][1] / g, -R[1][2] / g]
        M[1, :] = [R[0][0] / g, R[0][1] / g, R[0][2] / g]
        Pba = np.eye(3) * p.accel_bias_init**2
        var_f = [max(self._align_f2[i] / n - fbar[i] ** 2, 0.0) for i in range(3)]
        P[IBA : IBA + 3, IBA : IBA + 3] = Pba
        P[ITH : ITH + 3, ITH : ITH + 3] = M @ Pba @ M.T + np.diag(
            [max(var_f[1], var_f[0]) / (n * g * g)] * 2 + [0.0]
        )
        P[ITH : ITH + 3, IBA : IBA + 3] = M @ Pba
        P[IBA : IBA + 3, ITH : ITH + 3] = (M @ Pba).T
        P[ITH + 2, ITH + 2] += yaw_var
        P[IBM : IBM + 3, IBM : IBM + 3] = np.eye(3) * p.mag_bias_init_gauss**2
        if yaw_bm is not None:
            cross = -np.array(yaw_bm) * p.mag_bias_init_gauss**2  # cov(dpsi, db_m) = -J P_bm
            P[ITH + 2, IBM : IBM + 3] = cross
            P[IBM : IBM + 3, ITH + 2] = cross
        # Gyro bias: the mean rate at rest (the Earth's rate, 7e-5 rad/s, is left in the bias).
        self._bg = (wbar[0], wbar[1], wbar[2])
        for i in range(3):
            var_w = max(self._align_w2[i] / n - wbar[i] ** 2, 0.0)
            P[IBG + i, IBG + i] = max(var_w / n, 1e-10)

        # Position and velocity from the position source (vision first: it is the better one).
        gps = self._pending_gps
        if vision is not None and p.ev_ctrl & (EV_CTRL_HPOS | EV_CTRL_VPOS):
            self._p = vision.position_m
            var = fusion.ev_pos_variance(self._A, vision.position_std_m)
            P[IP, IP] = P[IP + 1, IP + 1] = P[IP + 2, IP + 2] = var
            self._v = _Z3
            P[IV, IV] = P[IV + 1, IV + 1] = P[IV + 2, IV + 2] = 0.1**2
        else:
            assert gps is not None
            self._p = gps.position_m
            hv, vv, sv = fusion.gps_variances(self._A, gps.eph_m, gps.epv_m, gps.speed_accuracy_m_s)
            P[IP, IP] = P[IP + 1, IP + 1] = hv
            P[IP + 2, IP + 2] = vv
            self._v = gps.velocity_m_s if p.gps_ctrl & GPS_CTRL_VEL else _Z3
            P[IV, IV] = P[IV + 1, IV + 1] = sv
            P[IV + 2, IV + 2] = sv * 2.25
        # Baro offset: b_h = baro height - z (error anti-correlated with z's).
        baro = self._pending_baro
        self._F[fk.MEMORY.baro_bias] = baro.height_m - self._p[2] if baro is not None else 0.0
        P[IBH, IBH] = P[IP + 2, IP + 2] + p.baro_noise_m**2
        P[IBH, IP + 2] = P[IP + 2, IBH] = -P[IP + 2, IP + 2]
        self.P = P
        self._ba = _Z3
        self._bm = _Z3
        self._finish_initialisation(imu)

    def _finish_initialisation(self, imu: ImuSample) -> None:
        self.initialised = True
        self.init_time_s = imu.time_s
        self._pending_gps = self._pending_vision = self._pending_baro = None
        self._entries.start(self._F, self._ring, imu.time_s, imu.dt_s, imu.angular_rate_rad_s,
                            imu.specific_force_m_s2)  # fmt: skip

    def reset_to(
        self,
        imu: ImuSample,
        position_m: Vector3,
        velocity_m_s: Vector3,
        quaternion: Quaternion,
        *,
        position_std_m: float = 0.1,
        velocity_std_m_s: float = 0.1,
        baro_height_m: float | None = None,
    ) -> None:
        """Initialise from a known state (an in-air start, a test), skipping the alignment
        (:func:`.filter.reset_state`); ``imu`` is the sample at which the state holds."""
        position = tuple(float(c) for c in position_m)
        offset = baro_height_m - position[2] if baro_height_m is not None else 0.0
        self.P = np.zeros((N, N))
        self._entries.reset_state(self._F, self.P, self._A, position, tuple(float(c) for c in velocity_m_s),
                                  tuple(float(c) for c in quaternion), float(position_std_m),
                                  float(velocity_std_m_s), float(offset))  # fmt: skip
        self._F[fk.MEMORY.imu_samples] += 1.0
        self._finish_initialisation(imu)

    # ------------------------------------------------------------------------------------------
    # Fusion (the kernels of .fusion; before the alignment, the samples it waits for)
    # ------------------------------------------------------------------------------------------
    def fuse_gps(self, fix: GpsFix) -> None:
        """GNSS position (horizontal, height) and velocity, valid EKF2_GPS_DELAY before arrival."""
        if not self.initialised:
            if checks.gps_usable(
                self._A, float(fix.fix_type), fix.eph_m, fix.epv_m, float(fix.satellites_visible)
            ):
                self._pending_gps = fix
            return
        self._fuse(fix.time_s, NO_AIDING._replace(
            gps_fresh=True, gps_position_m=_floats(fix.position_m),
            gps_velocity_m_s=_floats(fix.velocity_m_s),
            gps_accuracy=(float(fix.eph_m), float(fix.epv_m), float(fix.speed_accuracy_m_s)),
            gps_fix=(float(fix.fix_type), float(fix.satellites_visible)),
        ))  # fmt: skip

    def fuse_baro(self, sample: BaroSample) -> None:
        """Barometric height: ``h = z + b_h`` (the offset is a state), at most EKF2_BARO_RATE."""
        if not self.params.baro_enabled:
            return
        if not self.initialised:
            self._pending_baro = sample
            return
        self._fuse(sample.time_s, NO_AIDING._replace(baro_fresh=True, baro_height_m=float(sample.height_m)))

    def fuse_mag(self, sample: MagSample) -> None:
        """Magnetometer, at most EKF2_MAG_RATE: the 3-axis field ``m = R^T m_earth + b_m``
        (EKF2_MAG_TYPE 0) or the tilt-compensated heading (1)."""
        if self.params.mag_type == MAG_TYPE_NONE:
            return
        m = sample.field_gauss
        if not self.initialised:
            if self._align_n > 0:
                for i in range(3):
                    self._align_m[i] += m[i]
                self._align_mn += 1
            return
        self._fuse(sample.time_s, NO_AIDING._replace(mag_fresh=True, mag_gauss=_floats(m)))

    def fuse_frame(self, t: float, frame_aiding: Aiding) -> None:
        """A frame's aiding at the time ``t`` of its IMU sample, in PX4's order
        (:func:`.aiding.fuse_frame`, one compiled call); the filter must be initialised (before,
        each sensor's own method holds its samples for the alignment)."""
        self._fuse(t, frame_aiding)

    def _fuse(self, t: float, aiding: Aiding) -> None:
        """One compiled call of :func:`.aiding.fuse_frame`: a frame's aiding or a single sample."""
        memory = (self._F, self.P, self._ring, self._stats, self._windows, self._scratch)  # a FilterArrays
        self._entries.fuse_frame(memory, self._A, float(t), tuple(aiding))

    def fuse_vision(self, pose: VisionPose) -> None:
        """Motion capture / vision position and yaw, and its velocity when it has one (EKF2_EV_CTRL
        bit 2), valid EKF2_EV_DELAY before arrival."""
        if not self.initialised:
            self._pending_vision = pose
            return
        velocity = pose.velocity_m_s
        self._fuse(pose.time_s, NO_AIDING._replace(
            vision_fresh=True, vision_position_m=_floats(pose.position_m), vision_yaw_rad=float(pose.yaw_rad),
            vision_std=(float(pose.position_std_m), float(pose.yaw_std_rad)),
            vision_velocity_fresh=velocity is not None,
            vision_velocity_m_s=_floats(velocity) if velocity is not None else aiding.Z3,
            vision_velocity_std_m_s=float(pose.velocity_std_m_s),
        ))  # fmt: skip

    # ------------------------------------------------------------------------------------------
    # Outputs
    # ------------------------------------------------------------------------------------------
    def estimate(self) -> Estimate:
        """The current state estimate (what the controllers are fed)."""
        return _estimate_of(self._F[:_ESTIMATE_END].tolist(), float(self._F[fk.MEMORY.time]))

    def estimate_biases(self) -> tuple[Vector3, Vector3]:
        """The gyro and accelerometer bias estimates (cheaper than :meth:`estimate`)."""
        return _READ_BIASES(self._F[:_ESTIMATE_END].tolist())

    def covariance(self) -> np.ndarray:
        """A copy of the 19x19 error-state covariance (order: :data:`.kernels.STATE_NAMES`)."""
        return self.P.copy()

    def status(self) -> EstimatorStatus:
        """ESTIMATOR_STATUS-like figures and the pre-arm verdict."""
        p = self.params
        now = self.time_s
        src = {name: row.snapshot() for name, row in self.sources.items()}
        if not self.initialised:
            inf = math.inf
            return EstimatorStatus(
                time_s=now, initialised=False, converged=False, reason=self._align_reason, flags=0,
                vel_ratio=0.0, pos_horiz_ratio=0.0, pos_vert_ratio=0.0, mag_ratio=0.0,
                pos_horiz_accuracy_m=inf, pos_vert_accuracy_m=inf, vel_accuracy_m_s=inf,
                tilt_accuracy_rad=inf, yaw_accuracy_rad=inf, gps_glitch=False, dead_reckoning=False,
                sources=src, imu_samples=self.imu_samples, imu_dt_rejected=self.imu_dt_rejected,
            )  # fmt: skip
        F = self._F
        sigma = fk.accuracies(self.P)
        last_h_aid = float(F[fk.MEMORY.last_h_aid])
        verdict = self._entries.not_converged(F, self.P, self._A)
        dead_reckoning = verdict == fk.DEAD_RECKONING
        glitch = (
            src["gps_pos"].last_rejected_s >= 0.0 and now - src["gps_pos"].last_rejected_s < GLITCH_FLAG_S
        )
        reason = ""
        if dead_reckoning:
            reason = f"dead reckoning: no position or velocity aiding for {now - last_h_aid:.1f} s"
        elif verdict == fk.TILT:
            limit = math.degrees(p.converged_tilt_rad)
            reason = f"tilt not converged (1-sigma {math.degrees(sigma.tilt_rad):.2f} deg > {limit:g} deg)"
        elif verdict == fk.YAW:
            limit = math.degrees(p.converged_yaw_rad)
            reason = f"yaw not converged (1-sigma {math.degrees(sigma.yaw_rad):.2f} deg > {limit:g} deg)"
        elif verdict == fk.POSITION:
            sigma_m, limit = sigma.horizontal_position_m, p.converged_pos_m
            reason = f"horizontal position not converged (1-sigma {sigma_m:.2f} m > {limit:g} m)"
        elif verdict == fk.HEIGHT:
            sigma_m, limit = sigma.vertical_position_m, p.converged_vpos_m
            reason = f"vertical position not converged (1-sigma {sigma_m:.2f} m > {limit:g} m)"
        flags = ESTIMATOR_ATTITUDE
        if not dead_reckoning:
            flags |= ESTIMATOR_VELOCITY_HORIZ | ESTIMATOR_POS_HORIZ_REL | ESTIMATOR_PRED_POS_HORIZ_REL
            last_gps = float(F[fk.MEMORY.last_gps_pos])
            if last_gps >= 0.0 and now - last_gps <= p.no_aid_timeout_s:
                flags |= ESTIMATOR_POS_HORIZ_ABS | ESTIMATOR_PRED_POS_HORIZ_ABS
        else:
            flags |= ESTIMATOR_CONST_POS_MODE
        if now - float(F[fk.MEMORY.last_v_aid]) <= p.no_aid_timeout_s:
            flags |= ESTIMATOR_VELOCITY_VERT | ESTIMATOR_POS_VERT_ABS
        if glitch:
            flags |= ESTIMATOR_GPS_GLITCH
        if now < float(F[fk.MEMORY.bad_accel_until]):
            flags |= ESTIMATOR_ACCEL_ERROR
        pos_ratio = max(src["gps_pos"].test_ratio, src["ev_pos"].test_ratio)
        vert_ratio = max(src["gps_hgt"].test_ratio, src["baro"].test_ratio, src["ev_hgt"].test_ratio)
        mag_ratio = max(src["mag"].test_ratio, src["heading"].test_ratio, src["ev_yaw"].test_ratio)
        return EstimatorStatus(
            time_s=now,
            initialised=True,
            converged=reason == "",
            reason=reason,
            flags=flags,
            vel_ratio=max(src["gps_vel"].test_ratio, src["gps_vvel"].test_ratio, src["ev_vel"].test_ratio),
            pos_horiz_ratio=pos_ratio,
            pos_vert_ratio=vert_ratio,
            mag_ratio=mag_ratio,
            pos_horiz_accuracy_m=sigma.horizontal_position_m,
            pos_vert_accuracy_m=sigma.vertical_position_m,
            vel_accuracy_m_s=sigma.velocity_m_s,
            tilt_accuracy_rad=sigma.tilt_rad,
            yaw_accuracy_rad=sigma.yaw_rad,
            gps_glitch=glitch,
            dead_reckoning=dead_reckoning,
            sources=src,
            imu_samples=self.imu_samples,
            imu_dt_rejected=self.imu_dt_rejected,
        )


def _floats(v: Any) -> Vector3:
    return (float(v[0]), float(v[1]), float(v[2]))


class FilterEntries(NamedTuple):
    """What the filter calls per IMU sample and per fusion: :mod:`.filter`'s and :mod:`.fusion`'s
    compiled entries, or the kernels themselves where nothing compiles (and :mod:`.kernels`'
    arithmetic they call, for tests and benchmarks of its own)."""

    predict: Any
    prior_variances: Any
    joseph_update: Any
    predict_step: Any
    fuse_frame: Any  # every fusion: a frame's aiding or one sample (.aiding.fuse_frame_fields)
    reset_state: Any
    start: Any
    not_converged: Any


def filter_kernels() -> FilterEntries:
    """The kernels themselves (what Python runs where nothing compiles)."""
    arithmetic = ("predict", "prior_variances", "joseph_update")
    own = {name: getattr(kernels, name) for name in arithmetic} | {"fuse_frame": aiding.fuse_frame_fields}
    return FilterEntries(*(own.get(name) or getattr(fk, name) for name in FilterEntries._fields))


@functools.cache
def filter_entries() -> FilterEntries:
    """The entries, compiled (or loaded from numba's cache) and run once on a scratch filter of
    the filter's types now, not at the first sample in flight, then frozen: an argument of another
    type is refused (TypeError) instead of stalling a flight for a compilation. Once per process."""
    entries = FilterEntries(*(compiled(fn) for fn in filter_kernels()))
    if compiling():
        memory = fk.new_memory()
        F, P, ring = memory.state, memory.covariance, memory.ring
        A = fk.parameter_array(DEFAULT_PARAMS, 9.81, DEFAULT_EARTH_FIELD_WORLD_GAUSS)
        z3, g3, q = (0.0, 0.0, 0.0), (0.0, 0.0, 9.81), (1.0, 0.0, 0.0, 0.0)
        H = np.zeros((2, N))
        H[0, IP] = H[1, IP + 1] = 1.0
        entries.predict(P, np.zeros(N), 0.002, 9.81, kernels.ImuStep(z3, z3, z3, z3),
                        kernels.NominalState(q, z3, z3, z3, z3))
        entries.prior_variances(P, H, np.empty(2))
        work = np.empty(update_work_size(2, N))
        entries.joseph_update(np.eye(N), H, np.ones(2), np.zeros(2), np.empty(N), work)
        entries.reset_state(F, P, A, z3, z3, q, 0.1, 0.1, 0.0)
        entries.start(F, ring, 0.0, 0.002, z3, g3)
        entries.predict_step(F, P, ring, A, 0.002, 0.002, z3, g3)
        entries.fuse_frame(tuple(memory), A, 0.002, tuple(aiding.NO_AIDING))
        entries.not_converged(F, P, A)
        for entry in entries:
            freeze(entry)
    return entries
