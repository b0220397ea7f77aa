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

Hot path: the prediction (nominal state and covariance), the gates' prior variances and the
Joseph update are kernels written once in :mod:`.kernels`. The filter calls their compiled
entries (numba: one call per IMU sample, two per fusion), or the same functions run by Python
where nothing compiles (``QUADSITL_PURE_PYTHON=1``; slower). Between calls the nominal state is
plain floats (tuples) and the 19x19 covariance a numpy array the kernels update in place.
``benchmarks/estimator.py`` measures the choices: the position/velocity step costs ~10x more
with small numpy arrays than in floats, and ``F P F^T + Q`` several times more as two numpy
products than compiled with F's structure. A prediction costs a few microseconds, so the
covariance is predicted at every IMU sample (PX4's 100 Hz down-sampling is not needed).

(One module on purpose: every fusion is written out element by element in plain
floats for speed, and they share the covariance layout; split, the index bookkeeping would be
spread over files.)
"""

from __future__ import annotations

import functools
import math
from collections import deque
from typing import Any, NamedTuple

import numpy as np

from quadcommon import frames
from quadcommon.kernel import compiled, compiling, freeze
from quadcommon.rigid_body import (
    euler_from_quaternion,
    euler_rates_from_body_rates,
    matrix_times,
    quaternion_conjugate,
    quaternion_exp,
    quaternion_from_euler,
    quaternion_multiply,
    quaternion_normalised,
    rotation_from_quaternion,
)

from . import kernels
from .kernels import IBA, IBG, IBH, IBM, IP, ITH, IV, N
from .measurements import GPS_FIX_3D, BaroSample, GpsFix, ImuSample, MagSample, VisionPose
from .parameters import (
    DEFAULT_PARAMS,
    EV_CTRL_HPOS,
    EV_CTRL_VPOS,
    EV_CTRL_YAW,
    GPS_CTRL_HPOS,
    GPS_CTRL_VEL,
    GPS_CTRL_VPOS,
    MAG_CHECK_INCLINATION,
    MAG_CHECK_STRENGTH,
    MAG_TYPE_HEADING,
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
    SOURCE_NAMES,
    Estimate,
    EstimatorStatus,
    SourceStats,
)

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

DEFAULT_EARTH_FIELD_WORLD_GAUSS: Vector3 = frames.vector_from_ned((0.21, 0.016, 0.43))  # type: ignore[assignment]
"""The simulator's default field (about Zurich's), in the paper's world frame."""

RING = 4096  # delayed-state buffer, IMU steps (a power of two: the index wraps with a mask)
RING_MASK = RING - 1
MAX_IMU_DT_S = 0.1  # a longer gap is a lost link, not an interval to integrate across
REST_GYRO_RAD_S = 0.05  # alignment: at rest when |gyro| stays below this ...
REST_ACCEL_M_S2 = 0.5  # ... and ||f| - g| below this
GLITCH_FLAG_S = 1.0  # ESTIMATOR_GPS_GLITCH while a GPS position was gated out this recently
MIN_VARIANCE = 1e-12  # floor of a scalar innovation variance (guards a degenerate P)
# Bad vertical acceleration (PX4's bad_acc_vertical): vertical velocity and height innovations
# both gated out with the same sign mean the accelerometer, not the aiding, is wrong. Then, for
# BAD_ACCEL_HOLD_S, the vertical velocity gets PX4's BADACC_BIAS_PNOISE (4.9 m/s^2 per 10 ms
# prediction, i.e. 0.49 m/s^2/sqrt(Hz)) and the z accelerometer bias a fast random walk, so the
# aiding is accepted again and the new bias is learned instead of the filter diverging.
BAD_ACCEL_VEL_DENSITY = 0.49  # m/s^2/sqrt(Hz)
BAD_ACCEL_BIAS_RW = 0.1  # m/s^2/sqrt(s)
BAD_ACCEL_HOLD_S = 1.0
BAD_ACCEL_WINDOW_S = 1.0  # the mean of the normalised vertical innovations over this window ...
BAD_ACCEL_MEAN = 1.5  # ... beyond this (4.7 sigma of the mean of 10 GPS fixes)
BAD_ACCEL_MIN_SAMPLES = 8

_Q_ID = (1.0, 0.0, 0.0, 0.0)
_Z3 = (0.0, 0.0, 0.0)


def yaw_of(q: Quaternion) -> float:
    """The paper's psi of a body-to-world quaternion (ZYX Euler): ``atan2(R10, R00)`` with the two
    entries of :func:`~quadcommon.rigid_body.rotation_from_quaternion` it reads (per fusion)."""
    w, x, y, z = q
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


def yaw_jacobian(q: Quaternion) -> Vector3:
    """d psi / d dtheta for the global angular error (``R <- (I + [dtheta]_x) R``).

    With ``psi = atan2(R10, R00)``: ``dR00 = -dth_z R10 + dth_y R20``, ``dR10 = dth_z R00 -
    dth_x R20``, so ``dpsi = dth_z - (R00 R20 dth_x + R10 R20 dth_y) / (R00^2 + R10^2)``.
    """
    (r00, _, _), (r10, _, _), (r20, _, _) = rotation_from_quaternion(*q)
    d = r00 * r00 + r10 * r10
    if d < 1e-9:  # pitch at +-90 deg: yaw undefined; fall back to the level-flight Jacobian
        return (0.0, 0.0, 1.0)
    return (-r00 * r20 / d, -r10 * r20 / d, 1.0)


def mag_model(q: Quaternion, earth_field: Vector3, bias: Vector3) -> tuple[Vector3, tuple[Vector3, ...]]:
    """Predicted body field ``R^T m_e + b_m`` and its Jacobian ``R^T [m_e]_x`` on the global
    attitude error (``R <- (I + [dtheta]_x) R`` gives ``R^T m_e <- R^T m_e + R^T [m_e]_x dtheta``);
    the Jacobian on ``b_m`` is the identity."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_from_quaternion(*q)
    ex, ey, ez = earth_field
    pred = (
        r00 * ex + r10 * ey + r20 * ez + bias[0],
        r01 * ex + r11 * ey + r21 * ez + bias[1],
        r02 * ex + r12 * ey + r22 * ez + bias[2],
    )
    # Row i of R^T [m_e]_x is (column i of R) x m_e.
    H = (
        (r10 * ez - r20 * ey, r20 * ex - r00 * ez, r00 * ey - r10 * ex),
        (r11 * ez - r21 * ey, r21 * ex - r01 * ez, r01 * ey - r11 * ex),
        (r12 * ez - r22 * ey, r22 * ex - r02 * ez, r02 * ey - r12 * ex),
    )
    return pred, H


class ErrorStateEkf:
    """The filter. Feed it with :meth:`predict` every IMU sample and ``fuse_*`` as samples
    arrive (after the prediction of their arrival step); read :meth:`estimate` and
    :meth:`status`. Until aligned it collects samples (:attr:`initialised` False)."""

    def __init__(
        self,
        params: EstimatorParams = DEFAULT_PARAMS,
        *,
        earth_field_world_gauss: Vector3 = DEFAULT_EARTH_FIELD_WORLD_GAUSS,
        gravity_m_s2: float = 9.81,
    ) -> None:
        self.params = params
        self.gravity = gravity_m_s2
        self.earth_field = tuple(float(c) for c in earth_field_world_gauss)
        mx, my, mz = self.earth_field
        self._field_strength = math.sqrt(mx * mx + my * my + mz * mz)
        self._field_inclination = math.atan2(-mz, math.hypot(mx, my))  # positive: pointing down
        self._field_heading = math.atan2(my, mx)  # -declination in the paper's frame (z up)

        self.sources: dict[str, SourceStats] = {name: SourceStats() for name in SOURCE_NAMES}
        self.initialised = False
        self.time_s = 0.0
        self.imu_samples = 0
        self.imu_dt_rejected = 0
        self.init_time_s = -1.0

        # Nominal state (plain floats on the hot path).
        self._p: Vector3 = _Z3
        self._v: Vector3 = _Z3
        self._q: Quaternion = _Q_ID
        self._bg: Vector3 = _Z3
        self._ba: Vector3 = _Z3
        self._bm: Vector3 = _Z3
        self._bh = 0.0
        self._prev_rate: Vector3 = _Z3  # raw gyro of the previous sample
        self._prev_force: Vector3 = _Z3  # raw accelerometer of the previous sample
        self._prev_acc_world: Vector3 = _Z3  # R (f - b_a) of the previous sample
        self._rate: Vector3 = _Z3  # bias-corrected rate of the last sample (what the controllers get)
        self._dt_avg = 0.002

        # Covariance (in place: the kernels update it) and the step's process noise.
        self.P = np.zeros((N, N))
        self._entries = filter_entries()
        self._q_dt = -1.0
        self._q_diag = np.zeros(N)

        # Delayed-state ring buffer: (t, p, v, q, cp, cv, cq) per IMU step.
        self._ring: list[tuple | None] = [None] * RING
        self._head = -1
        self._count = 0
        # Cumulative corrections (position, velocity, attitude) for the buffered states.
        self._cp: Vector3 = _Z3
        self._cv: Vector3 = _Z3
        self._cq: Quaternion = _Q_ID

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

        # Aiding bookkeeping (times of the last fusions that constrain the horizontal drift).
        self._last_h_aid_s = -1.0
        self._last_v_aid_s = -1.0
        self._last_gps_pos_s = -1.0
        self._bad_accel_until_s = -math.inf
        # Recent (time, normalised innovation) of the vertical sources the bad-accel check watches.
        self._innovations: dict[int, _Window] = {
            id(self.sources[name]): _Window(256) for name in ("gps_vvel", "ev_hgt")
        }
        self.bad_accel_detections = 0
        self._next_mag_s = -math.inf  # fusion-rate limits (EKF2_MAG_RATE, EKF2_BARO_RATE)
        self._next_baro_s = -math.inf

    def set_params(self, params: EstimatorParams) -> None:
        """New parameters from the next sample on (a PARAM_SET of an EKF2_* parameter): the
        process noise is derived again; the state and covariance are kept."""
        self.params = params
        self._q_dt = -1.0

    # ------------------------------------------------------------------------------------------
    # Prediction
    # ------------------------------------------------------------------------------------------
    def predict(self, imu: ImuSample) -> None:
        """Propagate the nominal state and the covariance over ``imu.dt_s`` (see module doc)."""
        self.imu_samples += 1
        if not self.initialised:
            self._align(imu)
            return
        dt = imu.dt_s
        if not 0.0 < dt <= MAX_IMU_DT_S:
            # Not an interval to integrate across: restart the trapezoid from this sample.
            self.imu_dt_rejected += 1
            self.time_s = imu.time_s
            self._restart_trapezoid(imu)
            return
        self.time_s = t = imu.time_s
        self._dt_avg += 0.01 * (dt - self._dt_avg)

        if abs(dt - self._q_dt) > 1e-9:  # time stamps jitter in the last bits: keep the cache
            self._set_process_noise(dt)
        rate = imu.angular_rate_rad_s
        force = imu.specific_force_m_s2
        bg = self._bg
        P = self.P
        self._q, self._p, self._v, self._prev_acc_world = self._entries.predict(
            P,
            self._q_diag,
            dt,
            self.gravity,
            rate,
            force,
            self._prev_rate,
            self._prev_acc_world,
            bg,
            self._ba,
            self._q,
            self._p,
            self._v,
        )
        self._prev_rate = rate
        self._prev_force = force
        self._rate = (rate[0] - bg[0], rate[1] - bg[1], rate[2] - bg[2])
        if t < self._bad_accel_until_s:
            P[IV + 2, IV + 2] += BAD_ACCEL_VEL_DENSITY**2 * dt
            P[IBA + 2, IBA + 2] += BAD_ACCEL_BIAS_RW**2 * dt
        # Delayed-state buffer.
        head = (self._head + 1) & RING_MASK
        self._ring[head] = (t, self._p, self._v, self._q, self._cp, self._cv, self._cq)
        self._head = head
        if self._count < RING:
            self._count += 1

    def _set_process_noise(self, dt: float) -> None:
        p = self.params
        q = np.zeros(N)
        q[IV : IV + 3] = p.accel_noise_density**2 * dt
        q[ITH : ITH + 3] = p.gyro_noise_density**2 * dt
        q[IBG : IBG + 3] = p.gyro_bias_rw**2 * dt
        q[IBA : IBA + 3] = p.accel_bias_rw**2 * dt
        q[IBM : IBM + 3] = p.mag_bias_rw**2 * dt
        q[IBH] = p.baro_bias_rw**2 * dt
        self._q_diag = q
        self._q_dt = dt

    def _restart_trapezoid(self, imu: ImuSample) -> None:
        self._prev_rate = imu.angular_rate_rad_s
        self._prev_force = imu.specific_force_m_s2
        self._prev_acc_world = self._world_force(imu.specific_force_m_s2)
        g = imu.angular_rate_rad_s
        self._rate = (g[0] - self._bg[0], g[1] - self._bg[1], g[2] - self._bg[2])

    def _world_force(self, f: Vector3) -> Vector3:
        """``R (f - b_a)``: a body specific force in the world frame."""
        ba = self._ba
        return matrix_times(rotation_from_quaternion(*self._q), (f[0] - ba[0], f[1] - ba[1], f[2] - ba[2]))

    # ------------------------------------------------------------------------------------------
    # Alignment and explicit initialisation
    # ------------------------------------------------------------------------------------------
    def _align(self, imu: ImuSample) -> None:
        """Collect IMU samples at rest; initialise once ``EST_ALIGN_T`` of them and a position
        source are there (tilt from the mean specific force, gyro bias from the mean rate)."""
        self.time_s = imu.time_s
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
        position = self._pending_vision is not None or self._pending_gps is not None
        if not position:
            self._align_reason = (
                f"aligning: waiting for a position source (GPS 3D fix with eph <= "
                f"{self.params.gps_req_eph_m:g} m and >= {self.params.gps_req_nsats} satellites, or vision)"
            )
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
            yaw_var = self._ev_yaw_var(vision)
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
            var = self._ev_pos_var(vision)
            P[IP, IP] = P[IP + 1, IP + 1] = P[IP + 2, IP + 2] = var
            self._v = _Z3
            P[IV, IV] = P[IV + 1, IV + 1] = P[IV + 2, IV + 2] = 0.1**2
        else:
            assert gps is not None
            self._p = gps.position_m
            hv, vv, sv = self._gps_variances(gps)
            P[IP, IP] = P[IP + 1, IP + 1] = hv
            P[IP + 2, IP + 2] = vv
            self._v = gps.velocity_m_s if p.gps_ctrl & GPS_CTRL_VEL else _Z3
            P[IV, IV] = P[IV + 1, IV + 1] = sv
            P[IV + 2, IV + 2] = sv * 2.25
        # Baro offset: b_h = baro height - z (error anti-correlated with z's).
        baro = self._pending_baro
        self._bh = baro.height_m - self._p[2] if baro is not None else 0.0
        P[IBH, IBH] = P[IP + 2, IP + 2] + p.baro_noise_m**2
        P[IBH, IP + 2] = P[IP + 2, IBH] = -P[IP + 2, IP + 2]
        self.P = P
        self._ba = _Z3
        self._bm = _Z3
        self._finish_initialisation(imu)

    def _finish_initialisation(self, imu: ImuSample) -> None:
        self.initialised = True
        self.init_time_s = imu.time_s
        if 0.0 < imu.dt_s <= MAX_IMU_DT_S:
            self._dt_avg = imu.dt_s
        self.time_s = imu.time_s
        self._restart_trapezoid(imu)
        self._count = 0
        self._head = -1
        self._cp, self._cv, self._cq = _Z3, _Z3, _Q_ID
        self._last_h_aid_s = self._last_v_aid_s = imu.time_s
        self._pending_gps = self._pending_vision = self._pending_baro = None
        self._ring[0] = (imu.time_s, self._p, self._v, self._q, self._cp, self._cv, self._cq)
        self._head, self._count = 0, 1

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
        """Initialise from a known state (an in-air start, a test), skipping the alignment.

        Attitude uncertainty from EKF2_ANGERR_INIT (tilt) and 5 deg of yaw, biases zero with
        their EKF2_*BIAS_INIT priors; ``imu`` is the sample at which the state holds.
        """
        p = self.params
        self._p = tuple(float(c) for c in position_m)  # type: ignore[assignment]
        self._v = tuple(float(c) for c in velocity_m_s)  # type: ignore[assignment]
        w, x, y, z = quaternion
        n = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
        self._q = (w * n, x * n, y * n, z * n)
        self._bg = self._ba = self._bm = _Z3
        self._bh = baro_height_m - self._p[2] if baro_height_m is not None else 0.0
        P = np.zeros((N, N))
        for i in range(3):
            P[IP + i, IP + i] = position_std_m**2
            P[IV + i, IV + i] = velocity_std_m_s**2
            P[IBG + i, IBG + i] = p.gyro_bias_init**2
            P[IBA + i, IBA + i] = p.accel_bias_init**2
            P[IBM + i, IBM + i] = p.mag_bias_init_gauss**2
        P[ITH, ITH] = P[ITH + 1, ITH + 1] = p.tilt_init**2
        P[ITH + 2, ITH + 2] = math.radians(5.0) ** 2
        P[IBH, IBH] = position_std_m**2 + p.baro_noise_m**2
        self.P = P
        self.imu_samples += 1
        self._finish_initialisation(imu)

    # ------------------------------------------------------------------------------------------
    # Measurement noise (PX4: reported accuracies with the parameters as floors)
    # ------------------------------------------------------------------------------------------
    def _gps_variances(self, fix: GpsFix) -> tuple[float, float, float]:
        p = self.params
        h = max(fix.eph_m, p.gps_pos_noise_m)
        v = max(fix.epv_m, 1.5 * p.gps_pos_noise_m)  # PX4: vertical floor 1.5x the horizontal
        s = max(fix.speed_accuracy_m_s, p.gps_vel_noise_m_s)
        return h * h, v * v, s * s

    def _ev_pos_var(self, pose: VisionPose) -> float:
        p = self.params
        s = p.ev_pos_noise_m if p.ev_noise_mode else max(pose.position_std_m, p.ev_pos_noise_m)
        return s * s

    def _ev_yaw_var(self, pose: VisionPose) -> float:
        p = self.params
        s = p.ev_yaw_noise_rad if p.ev_noise_mode else max(pose.yaw_std_rad, p.ev_yaw_noise_rad)
        return s * s

    # ------------------------------------------------------------------------------------------
    # The delayed-state buffer
    # ------------------------------------------------------------------------------------------
    def _state_at(self, t_m: float) -> tuple[Vector3, Vector3, Quaternion, float] | None:
        """``(p, v, q, D)`` at ``t_m`` (corrected since), ``D = now - t_m``; None if too old."""
        now = self.time_s
        if t_m >= now - 1e-9:
            return self._p, self._v, self._q, 0.0
        k = int((now - t_m) / self._dt_avg + 0.5)
        if k >= self._count:
            return None
        ring, head = self._ring, self._head
        entry = ring[(head - k) & RING_MASK]
        # The step is nearly uniform; walk at most a few entries to the nearest time.
        while entry[0] > t_m and k + 1 < self._count:
            nxt = ring[(head - k - 1) & RING_MASK]
            if abs(nxt[0] - t_m) >= abs(entry[0] - t_m):
                break
            k += 1
            entry = nxt
        while entry[0] < t_m and k > 0:
            nxt = ring[(head - k + 1) & RING_MASK]
            if abs(nxt[0] - t_m) >= abs(entry[0] - t_m):
                break
            k -= 1
            entry = nxt
        te, p, v, q, cp, cv, cq = entry
        if t_m < te - 2.0 * self._dt_avg:
            return None  # older than the buffer's oldest entry
        ncp, ncv = self._cp, self._cv
        dtm = t_m - te
        pm = (
            p[0] + ncp[0] - cp[0] + v[0] * dtm,
            p[1] + ncp[1] - cp[1] + v[1] * dtm,
            p[2] + ncp[2] - cp[2] + v[2] * dtm,
        )
        vm = (v[0] + ncv[0] - cv[0], v[1] + ncv[1] - cv[1], v[2] + ncv[2] - cv[2])
        if cq is not self._cq:  # corrected since it was stored: the corrections since, cq_now (x) cq^-1
            q = quaternion_multiply(quaternion_multiply(self._cq, quaternion_conjugate(cq)), q)
        return pm, vm, q, now - t_m

    # ------------------------------------------------------------------------------------------
    # Fusion
    # ------------------------------------------------------------------------------------------
    def _fuse(self, groups: list) -> list[bool]:
        """Gate, then fuse one measurement: ``groups`` of ``(stats, gate, rows)``, a row being
        ``(state indices, Jacobian entries, innovation, noise variance)``.

        Each group (one sensor's axes, e.g. GPS horizontal position) passes or fails its gate as a
        whole on the prior innovation variances, as PX4 does; the accepted rows are then fused in
        one batch, in Joseph form (Solà §6.1): ``K = P H^T S^-1``, ``S = H P H^T + R``,
        ``P <- (I - K H) P (I - K H)^T + K R K^T``, and the error ``K y`` is injected (§6.2-6.3).
        A batch equals the sequence of scalar updates for a linear ``h`` and costs one set of
        19x19 products instead of one per axis.
        """
        rows = [row for _, _, group_rows in groups for row in group_rows]
        m = len(rows)
        H = np.zeros((m, N))
        for k, (idx, h, _, _) in enumerate(rows):
            for i, hi in zip(idx, h, strict=True):
                H[k, i] = hi
        entries = self._entries
        prior = np.empty(m)
        entries.prior_variances(self.P, H, prior)
        d = prior.tolist()
        now = self.time_s
        keep: list[int] = []
        results: list[bool] = []
        k = 0
        for stats, gate, group_rows in groups:
            worst = 0.0
            for j, (_, _, innov, r) in enumerate(group_rows):
                ratio = innov * innov / (gate * gate * max(d[k + j] + r, MIN_VARIANCE))
                if ratio > worst:
                    worst = ratio
            stats.test_ratio = worst
            stats.innovation = innov
            stats.normalized_innovation = innov / math.sqrt(max(d[k + len(group_rows) - 1] + r, MIN_VARIANCE))
            stats.last_tested_s = now
            window = self._innovations.get(id(stats))
            if window is not None:
                window.append((now, stats.normalized_innovation))
            if worst > 1.0:
                stats.rejected += 1
                stats.last_rejected_s = now
                if stats.rejecting_since_s < 0.0:
                    stats.rejecting_since_s = now
                results.append(False)
            else:
                stats.rejecting_since_s = -1.0
                stats.fused += 1
                stats.last_fused_s = now
                keep.extend(range(k, k + len(group_rows)))
                results.append(True)
            k += len(group_rows)
        if not keep:
            return results
        if len(keep) < m:
            H = H[keep]
        dx = np.empty(N)
        entries.joseph_update(self.P, H, np.array([rows[i][3] for i in keep]),
                              np.array([rows[i][2] for i in keep]), dx)  # fmt: skip
        self._inject(dx)
        return results

    def _inject(self, dx: np.ndarray) -> None:
        """Nominal state <- nominal (+) dx (Solà §6.2, global attitude error), then the reset."""
        d = dx.tolist()
        dp = (d[0], d[1], d[2])
        dv = (d[3], d[4], d[5])
        p, v = self._p, self._v
        self._p = (p[0] + dp[0], p[1] + dp[1], p[2] + dp[2])
        self._v = (v[0] + dv[0], v[1] + dv[1], v[2] + dv[2])
        dq = quaternion_exp(d[6], d[7], d[8])
        self._q = quaternion_normalised(quaternion_multiply(dq, self._q))
        bg, ba, bm = self._bg, self._ba, self._bm
        self._bg = (bg[0] + d[9], bg[1] + d[10], bg[2] + d[11])
        self._ba = (ba[0] + d[12], ba[1] + d[13], ba[2] + d[14])
        self._bm = (bm[0] + d[15], bm[1] + d[16], bm[2] + d[17])
        self._bh += d[18]
        # Bookkeeping for the buffered past states.
        cp, cv = self._cp, self._cv
        self._cp = (cp[0] + dp[0], cp[1] + dp[1], cp[2] + dp[2])
        self._cv = (cv[0] + dv[0], cv[1] + dv[1], cv[2] + dv[2])
        self._cq = quaternion_multiply(dq, self._cq)
        # The previous sample's world force and the reported rate follow the new q and biases.
        self._prev_acc_world = self._world_force(self._prev_force)
        g = self._prev_rate
        self._rate = (g[0] - self._bg[0], g[1] - self._bg[1], g[2] - self._bg[2])
        # Reset, Solà §7.3.3: P <- G P G^T with G_theta = I + [dtheta/2]_x. Below 1 mrad, G - I
        # changes P by less than 0.05 %: skipped there (it costs as much as a fusion).
        hx, hy, hz = 0.5 * d[6], 0.5 * d[7], 0.5 * d[8]
        if hx * hx + hy * hy + hz * hz > 0.25e-6:
            G = np.array(((1.0, -hz, hy), (hz, 1.0, -hx), (-hy, hx, 1.0)))
            P = self.P
            P[ITH : ITH + 3, :] = G @ P[ITH : ITH + 3, :]
            P[:, ITH : ITH + 3] = P[:, ITH : ITH + 3] @ G.T

    def _maybe_reset_position(
        self, stats: SourceStats, target: Vector3, axes: tuple[int, ...], var: float
    ) -> bool:
        """After EST_POS_RST_T of continuous rejections of a good source, jump to it (PX4 does)."""
        since = stats.rejecting_since_s
        if since < 0.0 or self.time_s - since < self.params.pos_reset_timeout_s:
            return False
        p = list(self._p)
        cp = list(self._cp)
        for i in axes:
            delta = target[i] - p[i]
            p[i] += delta
            cp[i] += delta
            self.P[IP + i, :] = 0.0
            self.P[:, IP + i] = 0.0
            self.P[IP + i, IP + i] = var
        self._p = (p[0], p[1], p[2])
        self._cp = (cp[0], cp[1], cp[2])
        stats.resets += 1
        stats.rejecting_since_s = -1.0
        return True

    def fuse_gps(self, fix: GpsFix) -> None:
        """GNSS position (horizontal, height) and velocity, valid EKF2_GPS_DELAY before arrival."""
        p = self.params
        if not self.initialised:
            if self._gps_usable(fix):
                self._pending_gps = fix
            return
        src = self.sources
        st_pos, st_hgt, st_vel, st_vvel = src["gps_pos"], src["gps_hgt"], src["gps_vel"], src["gps_vvel"]
        if not self._gps_usable(fix):
            st_pos.check_rejected += 1
            return
        t_m = fix.time_s - p.gps_delay_s
        past = self._state_at(t_m)
        if past is None:
            st_pos.too_old += 1
            return
        pm, vm, _, D = past
        hv, vv, sv = self._gps_variances(fix)
        z, u = fix.position_m, fix.velocity_m_s
        groups = []
        if p.gps_ctrl & GPS_CTRL_HPOS:
            groups.append(
                (
                    st_pos,
                    p.gps_pos_gate,
                    [
                        ((IP, IV), (1.0, -D), z[0] - pm[0], hv),
                        ((IP + 1, IV + 1), (1.0, -D), z[1] - pm[1], hv),
                    ],
                )
            )
        if p.gps_ctrl & GPS_CTRL_VPOS:
            groups.append((st_hgt, p.baro_gate, [((IP + 2, IV + 2), (1.0, -D), z[2] - pm[2], vv)]))
        if p.gps_ctrl & GPS_CTRL_VEL:
            # Horizontal and vertical velocity gated apart (as PX4 does), so that a vertical
            # accelerometer fault does not also cut the horizontal aiding.
            groups.append(
                (
                    st_vel,
                    p.gps_vel_gate,
                    [((IV,), (1.0,), u[0] - vm[0], sv), ((IV + 1,), (1.0,), u[1] - vm[1], sv)],
                )
            )
            groups.append(
                (st_vvel, p.gps_vel_gate, [((IV + 2,), (1.0,), u[2] - vm[2], sv * 2.25)])
            )  # PX4: 1.5x
        if not groups:
            return
        accepted = self._fuse(groups)
        now = self.time_s
        for (stats, _, _), ok in zip(groups, accepted, strict=True):
            if stats is st_pos:
                if ok:
                    self._last_h_aid_s = self._last_gps_pos_s = now
                else:
                    current = (z[0] + self._p[0] - pm[0], z[1] + self._p[1] - pm[1], 0.0)
                    self._maybe_reset_position(stats, current, (0, 1), hv)
            elif stats is st_hgt and ok:
                self._last_v_aid_s = now
            elif stats is st_vel and ok:
                self._last_h_aid_s = now
            elif stats is st_vvel and ok:
                self._last_v_aid_s = now
        self._check_vertical_accel()

    def _gps_usable(self, fix: GpsFix) -> bool:
        p = self.params
        return (
            fix.fix_type >= GPS_FIX_3D
            and fix.eph_m <= p.gps_req_eph_m
            and fix.epv_m <= p.gps_req_epv_m
            and fix.satellites_visible >= p.gps_req_nsats
        )

    def fuse_baro(self, sample: BaroSample) -> None:
        """Barometric height: ``h = z + b_h`` (the offset is a state), at most EKF2_BARO_RATE."""
        p = self.params
        if not p.baro_enabled:
            return
        if not self.initialised:
            self._pending_baro = sample
            return
        stats = self.sources["baro"]
        if sample.time_s < self._next_baro_s:
            stats.skipped += 1
            return
        self._next_baro_s = sample.time_s + p.baro_period_s - 1e-9
        past = self._state_at(sample.time_s - p.baro_delay_s)
        if past is None:
            stats.too_old += 1
            return
        pm, _, _, D = past
        innov = sample.height_m - pm[2] - self._bh
        if self._fuse(
            [(stats, p.baro_gate, [((IP + 2, IV + 2, IBH), (1.0, -D, 1.0), innov, p.baro_noise_m**2)])]
        )[0]:
            self._last_v_aid_s = self.time_s
        self._check_vertical_accel()

    def fuse_mag(self, sample: MagSample) -> None:
        """Magnetometer, at most EKF2_MAG_RATE: the 3-axis field ``m = R^T m_earth + b_m``
        (EKF2_MAG_TYPE 0) or the tilt-compensated heading (1)."""
        p = self.params
        if p.mag_type == MAG_TYPE_NONE:
            return
        m = sample.field_gauss
        if not self.initialised:
            if self._align_n > 0:
                for i in range(3):
                    self._align_m[i] += m[i]
                self._align_mn += 1
            return
        stats = self.sources["heading" if p.mag_type == MAG_TYPE_HEADING else "mag"]
        if sample.time_s < self._next_mag_s:
            stats.skipped += 1
            return
        self._next_mag_s = sample.time_s + p.mag_period_s - 1e-9
        past = self._state_at(sample.time_s - p.mag_delay_s)
        if past is None:
            stats.too_old += 1
            return
        q = past[2]
        if not self._mag_checks(stats, m, q):
            return
        if p.mag_type == MAG_TYPE_HEADING:
            phi, theta, _ = euler_from_quaternion(*q)
            meas = self._mag_heading(m, phi, theta, self._bm)
            row = (
                (ITH, ITH + 1, ITH + 2),
                yaw_jacobian(q),
                frames.wrap_pi(meas - yaw_of(q)),
                p.heading_noise_rad**2,
            )
            self._fuse([(stats, p.heading_gate, [row])])
            return
        pred, H = mag_model(q, self.earth_field, self._bm)
        var = p.mag_noise_gauss**2
        rows = [((ITH, ITH + 1, ITH + 2, IBM + i), (*H[i], 1.0), m[i] - pred[i], var) for i in range(3)]
        self._fuse([(stats, p.mag_gate, rows)])

    def _mag_checks(self, stats: SourceStats, m: Vector3, q: Quaternion) -> bool:
        """PX4's EKF2_MAG_CHECK: the corrected field's strength and inclination against the model."""
        p = self.params
        bm = self._bm
        c = (m[0] - bm[0], m[1] - bm[1], m[2] - bm[2])
        strength = math.sqrt(c[0] ** 2 + c[1] ** 2 + c[2] ** 2)
        ok = True
        if (
            p.mag_check & MAG_CHECK_STRENGTH
            and abs(strength - self._field_strength) > p.mag_strength_tol_gauss
        ):
            ok = False
        if ok and p.mag_check & MAG_CHECK_INCLINATION and strength > 0.0:
            R = rotation_from_quaternion(*q)
            wz = R[2][0] * c[0] + R[2][1] * c[1] + R[2][2] * c[2]
            incl = math.asin(max(-1.0, min(1.0, -wz / strength)))
            ok = abs(incl - self._field_inclination) <= p.mag_inclination_tol_rad
        if not ok:
            stats.check_rejected += 1
            stats.last_rejected_s = self.time_s
        return ok

    def _mag_heading(self, m: Vector3, phi: float, theta: float, bias: Vector3) -> float:
        """The yaw that turns the tilt-compensated body field onto the earth field's heading."""
        cx, cy, cz = m[0] - bias[0], m[1] - bias[1], m[2] - bias[2]
        sf, cf = math.sin(phi), math.cos(phi)
        st, ct = math.sin(theta), math.cos(theta)
        # Level-frame field: Ry(theta) Rx(phi) m (yaw left out).
        lx = ct * cx + st * sf * cy + st * cf * cz
        ly = cf * cy - sf * cz
        return frames.wrap_pi(self._field_heading - math.atan2(ly, lx))

    def fuse_vision(self, pose: VisionPose) -> None:
        """Motion capture / vision position and yaw, valid EKF2_EV_DELAY before arrival."""
        p = self.params
        if not self.initialised:
            self._pending_vision = pose
            return
        t_m = pose.time_s - p.ev_delay_s
        past = self._state_at(t_m)
        st_pos, st_hgt, st_yaw = self.sources["ev_pos"], self.sources["ev_hgt"], self.sources["ev_yaw"]
        if past is None:
            st_pos.too_old += 1
            return
        pm, _, qm, D = past
        z = pose.position_m
        var = self._ev_pos_var(pose)
        groups = []
        if p.ev_ctrl & EV_CTRL_HPOS:
            groups.append(
                (
                    st_pos,
                    p.ev_pos_gate,
                    [
                        ((IP, IV), (1.0, -D), z[0] - pm[0], var),
                        ((IP + 1, IV + 1), (1.0, -D), z[1] - pm[1], var),
                    ],
                )
            )
        if p.ev_ctrl & EV_CTRL_VPOS:
            groups.append((st_hgt, p.ev_pos_gate, [((IP + 2, IV + 2), (1.0, -D), z[2] - pm[2], var)]))
        if p.ev_ctrl & EV_CTRL_YAW:
            groups.append(
                (
                    st_yaw,
                    p.heading_gate,
                    [
                        (
                            (ITH, ITH + 1, ITH + 2),
                            yaw_jacobian(qm),
                            frames.wrap_pi(pose.yaw_rad - yaw_of(qm)),
                            self._ev_yaw_var(pose),
                        )
                    ],
                )
            )
        if not groups:
            return
        accepted = self._fuse(groups)
        now = self.time_s
        for (stats, _, _), ok in zip(groups, accepted, strict=True):
            if stats is st_pos:
                if ok:
                    self._last_h_aid_s = now
                else:
                    current = (z[0] + self._p[0] - pm[0], z[1] + self._p[1] - pm[1], 0.0)
                    self._maybe_reset_position(stats, current, (0, 1), var)
            elif stats is st_hgt and ok:
                self._last_v_aid_s = now
        self._check_vertical_accel()

    def _check_vertical_accel(self) -> None:
        """Bad vertical acceleration (PX4's bad_acc_vertical, made statistical): the mean of the
        normalised vertical velocity innovations (GPS) over the last BAD_ACCEL_WINDOW_S is beyond
        BAD_ACCEL_MEAN and the height innovation agrees in sign; or, without a velocity source,
        the mean of the normalised vision height innovations is. For a consistent filter the
        mean of n samples has a standard deviation 1/sqrt(n) (0.32 at 10 GPS fixes): by chance
        the test fires about once in 10^5 windows; a vertical accelerometer fault (a bias step the
        random-walk model cannot follow) trips it within about a second."""
        src = self.sources
        now = self.time_s
        bad = False
        for name in ("gps_vvel", "ev_hgt"):
            st = src[name]
            if st.last_tested_s != now:
                continue
            window = self._innovations[id(st)]
            window.drop_before(now - BAD_ACCEL_WINDOW_S)
            if len(window) < BAD_ACCEL_MIN_SAMPLES:
                continue
            mean = window.mean()
            if abs(mean) < BAD_ACCEL_MEAN:
                continue
            if name == "ev_hgt":
                bad = True
            else:
                heights = [src[n] for n in ("gps_hgt", "baro") if src[n].last_tested_s >= 0.0]
                latest = max(heights, key=lambda h: h.last_tested_s, default=None)
                bad = latest is not None and latest.innovation * mean > 0.0
        if bad:
            if now >= self._bad_accel_until_s:
                self.bad_accel_detections += 1
            self._bad_accel_until_s = now + BAD_ACCEL_HOLD_S

    # ------------------------------------------------------------------------------------------
    # Outputs
    # ------------------------------------------------------------------------------------------
    def estimate(self) -> Estimate:
        """The current state estimate (what the controllers are fed)."""
        q = self._q
        euler = euler_from_quaternion(*q)
        rate = self._rate
        return Estimate(
            self.time_s,
            self._p,
            self._v,
            q,
            euler,
            rate,
            euler_rates_from_body_rates(euler[0], euler[1], rate),
            self._bg,
            self._ba,
            self._bm,
            self._bh,
        )

    def estimate_biases(self) -> tuple[Vector3, Vector3]:
        """The gyro and accelerometer bias estimates (cheaper than :meth:`estimate`)."""
        return self._bg, self._ba

    def covariance(self) -> np.ndarray:
        """A copy of the 19x19 error-state covariance (order: :data:`.kernels.STATE_NAMES`)."""
        return self.P.copy()

    def status(self) -> EstimatorStatus:
        """ESTIMATOR_STATUS-like figures and the pre-arm verdict."""
        p = self.params
        now = self.time_s
        src = self.sources
        P = self.P
        if not self.initialised:
            return EstimatorStatus(
                now,
                False,
                False,
                self._align_reason,
                0,
                0.0,
                0.0,
                0.0,
                0.0,
                math.inf,
                math.inf,
                math.inf,
                math.inf,
                math.inf,
                False,
                False,
                {k: _copy(v) for k, v in src.items()},
                self.imu_samples,
                self.imu_dt_rejected,
            )
        pos_h = math.sqrt(max(P[0, 0] + P[1, 1], 0.0))
        pos_v = math.sqrt(max(P[2, 2], 0.0))
        vel = math.sqrt(max(P[3, 3] + P[4, 4] + P[5, 5], 0.0))
        tilt = math.sqrt(max(P[6, 6] + P[7, 7], 0.0))
        yaw = math.sqrt(max(P[8, 8], 0.0))
        dead_reckoning = now - self._last_h_aid_s > p.no_aid_timeout_s
        glitch = (
            src["gps_pos"].last_rejected_s >= 0.0 and now - src["gps_pos"].last_rejected_s < GLITCH_FLAG_S
        )
        reason = ""
        if dead_reckoning:
            reason = f"dead reckoning: no position or velocity aiding for {now - self._last_h_aid_s:.1f} s"
        elif tilt > p.converged_tilt_rad:
            limit = math.degrees(p.converged_tilt_rad)
            reason = f"tilt not converged (1-sigma {math.degrees(tilt):.2f} deg > {limit:g} deg)"
        elif yaw > p.converged_yaw_rad:
            limit = math.degrees(p.converged_yaw_rad)
            reason = f"yaw not converged (1-sigma {math.degrees(yaw):.2f} deg > {limit:g} deg)"
        elif pos_h > p.converged_pos_m:
            reason = f"horizontal position not converged (1-sigma {pos_h:.2f} m > {p.converged_pos_m:g} m)"
        elif pos_v > p.converged_vpos_m:
            # Just after the alignment the height is one GNSS fix (0.5-1 m 1-sigma): not fit to
            # arm on until a few fixes and the baro have brought it down.
            reason = f"vertical position not converged (1-sigma {pos_v:.2f} m > {p.converged_vpos_m:g} m)"
        flags = ESTIMATOR_ATTITUDE
        if not dead_reckoning:
            flags |= ESTIMATOR_VELOCITY_HORIZ | ESTIMATOR_POS_HORIZ_REL | ESTIMATOR_PRED_POS_HORIZ_REL
            if self._last_gps_pos_s >= 0.0 and now - self._last_gps_pos_s <= p.no_aid_timeout_s:
                flags |= ESTIMATOR_POS_HORIZ_ABS | ESTIMATOR_PRED_POS_HORIZ_ABS
        else:
            flags |= ESTIMATOR_CONST_POS_MODE
        if now - self._last_v_aid_s <= p.no_aid_timeout_s:
            flags |= ESTIMATOR_VELOCITY_VERT | ESTIMATOR_POS_VERT_ABS
        if glitch:
            flags |= ESTIMATOR_GPS_GLITCH
        if now < self._bad_accel_until_s:
            flags |= ESTIMATOR_ACCEL_ERROR
        pos_ratio = max(src["gps_pos"].test_ratio, src["ev_pos"].test_ratio)
        vert_ratio = max(src["gps_hgt"].test_ratio, src["baro"].test_ratio, src["ev_hgt"].test_ratio)
        mag_ratio = max(src["mag"].test_ratio, src["heading"].test_ratio, src["ev_yaw"].test_ratio)
        return EstimatorStatus(
            now,
            True,
            reason == "",
            reason,
            flags,
            max(src["gps_vel"].test_ratio, src["gps_vvel"].test_ratio),
            pos_ratio,
            vert_ratio,
            mag_ratio,
            pos_h,
            pos_v,
            vel,
            tilt,
            yaw,
            glitch,
            dead_reckoning,
            {k: _copy(v) for k, v in src.items()},
            self.imu_samples,
            self.imu_dt_rejected,
        )


class _Window:
    """Recent ``(time, value)`` samples (at most ``size``) and their running sum, so that the mean
    over the window costs O(1) per fusion instead of a pass over up to ``size`` samples; the sum
    is recomputed exactly every ``size`` appends, so its round-off cannot build up."""

    def __init__(self, size: int) -> None:
        self.samples: deque[tuple[float, float]] = deque()
        self.size = size
        self.total = 0.0
        self._appends = 0

    def __len__(self) -> int:
        return len(self.samples)

    def append(self, sample: tuple[float, float]) -> None:
        samples = self.samples
        if len(samples) >= self.size:
            self.total -= samples.popleft()[1]
        samples.append(sample)
        self.total += sample[1]
        self._appends += 1
        if self._appends >= self.size:
            self._appends = 0
            self.total = math.fsum(z for _, z in samples)

    def drop_before(self, t: float) -> None:
        samples = self.samples
        while samples and samples[0][0] < t:
            self.total -= samples.popleft()[1]

    def mean(self) -> float:
        return self.total / len(self.samples)


class FilterEntries(NamedTuple):
    """What the filter calls per IMU sample and per fusion: :mod:`.kernels`' compiled entries, or
    the kernels themselves where nothing compiles."""

    predict: Any
    prior_variances: Any
    joseph_update: Any


@functools.cache
def filter_entries() -> FilterEntries:
    """The entries, compiled (or loaded from numba's cache) and run once on scratch arrays of the
    filter's types now, not at the first sample in flight, then frozen: an argument of another
    type is refused (TypeError) instead of stalling a flight for a compilation. Once per process."""
    entries = FilterEntries(
        compiled(kernels.predict), compiled(kernels.prior_variances), compiled(kernels.joseph_update)
    )
    if compiling():
        P, H, z3 = np.eye(N), np.zeros((2, N)), (0.0, 0.0, 0.0)
        H[0, IP] = H[1, IP + 1] = 1.0
        entries.predict(P, np.zeros(N), 0.002, 9.81, z3, z3, z3, z3, z3, z3, (1.0, 0.0, 0.0, 0.0), z3, z3)
        entries.prior_variances(P, H, np.empty(2))
        entries.joseph_update(P, H, np.ones(2), np.zeros(2), np.empty(N))
        for entry in entries:
            freeze(entry)
    return entries


def _copy(stats: SourceStats) -> SourceStats:
    return SourceStats(**vars(stats))
