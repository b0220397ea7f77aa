"""Ground truth, the sensor models and the filter wired together as the autopilot will (tests only).

``helix_truth`` flies the paper's helix once (the in-process cascade on ground truth, the coupled
plant +30 %, the paper's disturbance steps) and records the plant's truth every control frame;
the vehicle is first held still at the start pose for ``PRE_ROLL_S`` (the filter's alignment, as
on the ground before arming). ``run_filter`` replays a truth through a :class:`SensorSuite` and
the filter, feeding every reading at its delivery frame with that frame's time (the arrival time
the autopilot knows; the filter subtracts its EKF2_*_DELAY), and returns errors and NEES.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from autopilot.control.cascade import Cascade
from autopilot.control.config import load_controller
from autopilot.estimation import (
    BaroSample,
    ErrorStateEkf,
    EstimatorParams,
    GpsFix,
    ImuSample,
    MagSample,
    VisionPose,
)
from autopilot.estimation.kernels import IBA, IBG, IP, ITH, IV
from autopilot.records import StateEstimate
from quadcommon.config import apply_uncertainty, load_scenario, load_sitl, load_vehicle
from quadcommon.rigid_body import quaternion_multiply, rotation_from_quaternion
from quadcommon.trajectories import trajectory_from_spec
from simulator.dynamics.plant import TruthState, make_plant
from simulator.environment.gust_profile import DisturbanceSchedule, load_gust_profile
from simulator.sensors import SensorConfig, SensorSuite

PRE_ROLL_S = 2.0  # held still at the start pose before the helix starts
HOME_ALT_M = 488.0
MOVING = IBA + 3  # the error state up to the accelerometer bias: what a run's errors and sigmas hold


@functools.lru_cache(maxsize=2)
def _helix_flight(duration_s: float) -> tuple[TruthState, tuple[TruthState, ...]]:
    """The rest state at the start pose, and the plant's truth at frames 1..n of the helix."""
    scenario = load_scenario("helix")
    vehicle = load_vehicle(scenario.vehicle)
    rates = load_sitl().rates
    dt = 1.0 / rates.control_hz
    substeps = rates.physics_steps_per_control
    plant = make_plant(apply_uncertainty(vehicle, scenario), dt / substeps)
    plant.reset(scenario.initial_position_m, scenario.initial_euler_rad)
    cascade = Cascade(load_controller("intbs_nlhinf"), vehicle, dt)
    trajectory = trajectory_from_spec(scenario.trajectory)
    schedule = DisturbanceSchedule(load_gust_profile(scenario.gusts), step_s=dt / substeps)
    # On the stand: at rest at the start pose, the accelerometer reads gravity only.
    t0 = plant.truth()
    g = vehicle.nominal.gravity_m_s2
    R = rotation_from_quaternion(*t0.quaternion)
    rest = t0._replace(
        velocity_m_s=(0.0, 0.0, 0.0),
        acceleration_m_s2=(0.0, 0.0, 0.0),
        body_rates_rad_s=(0.0, 0.0, 0.0),
        euler_rates_rad_s=(0.0, 0.0, 0.0),
        specific_force_body_m_s2=(R[2][0] * g, R[2][1] * g, R[2][2] * g),  # R^T (0, 0, g)
    )
    # Released at t = 0; each later frame samples the truth before that frame's command is
    # applied, as the SITL does (the first command acts over [0, dt]).
    flight = []
    for k in range(round(duration_s / dt) + 1):
        t = k * dt
        position, velocity, euler, euler_rates = plant.kinematics()
        out = cascade.step(StateEstimate(position, velocity, euler, euler_rates), trajectory.sample(t))
        if k > 0:
            flight.append(plant.truth())
        plant.set_actuator_controls(out.actuator_controls)
        for j in range(substeps):
            force, torque, wind = schedule.evaluate(t + j * dt / substeps)
            plant.set_disturbance(force, torque, wind)
            plant.step()
    return rest, tuple(flight)


@functools.lru_cache(maxsize=4)
def helix_truth(
    duration_s: float = 40.0, pre_roll_s: float = PRE_ROLL_S
) -> tuple[tuple[float, TruthState], ...]:
    """``(t, truth)`` per control frame: ``pre_roll_s`` held at rest, then the helix released at
    ``t = pre_roll_s`` (the scenario's own time is ``t - pre_roll_s``)."""
    rest, flight = _helix_flight(duration_s)
    dt = 1.0 / load_sitl().rates.control_hz
    n_pre = round(pre_roll_s / dt)
    frames = [(k * dt, rest) for k in range(n_pre + 1)]  # the last one at the release
    frames += [((n_pre + 1 + k) * dt, truth) for k, truth in enumerate(flight)]
    return tuple(frames)


def attitude_error(q_true, q_est) -> tuple[float, float, float]:
    """``dtheta`` with ``q_true = Exp(dtheta) (x) q_est`` (the filter's global error), rad."""
    w, x, y, z = quaternion_multiply(q_true, (q_est[0], -q_est[1], -q_est[2], -q_est[3]))
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    angle = 2.0 * math.atan2(s, w)
    return (x / s * angle, y / s * angle, z / s * angle)


@dataclass
class FilterRun:
    t: np.ndarray  # s, frames after initialisation
    pos_err: np.ndarray  # (n, 3) true - estimate, m
    vel_err: np.ndarray
    att_err: np.ndarray  # (n, 3) rad, world frame
    gyro_bias_err: np.ndarray  # (n, 3) rad/s
    accel_bias_err: np.ndarray  # (n, 3) m/s^2
    sigma: np.ndarray  # (n, MOVING) sqrt of the covariance diagonal up to the accelerometer bias
    nees: np.ndarray  # (n,) NEES of the first 15 error states
    gps_err: np.ndarray  # (m, 3) raw GPS fix errors against the truth at their validity time
    gps_t: np.ndarray
    converged_t: float  # first time the filter reported converged (nan: never)
    ekf: ErrorStateEkf
    suite: SensorSuite
    statuses: list = field(default_factory=list)

    def rms(self, err: np.ndarray, t_from: float = -math.inf) -> float:
        """3D RMS of an error series from ``t_from`` on."""
        sel = self.t >= t_from
        return float(np.sqrt(np.mean(np.sum(err[sel] ** 2, axis=1))))

    def at(self, t: float) -> int:
        return int(np.searchsorted(self.t, t))


def run_filter(
    truth: tuple[tuple[float, TruthState], ...],
    sensors: SensorConfig,
    params: EstimatorParams,
    *,
    faults=(),
    until_s: float | None = None,
    status_every_s: float = 0.0,
    nees_every: int = 1,
    reset_at_s: float | None = None,
    each_frame: Callable[[float, ErrorStateEkf], None] | None = None,
) -> FilterRun:
    """Replay ``truth`` through the sensors (seeded by ``sensors.seed``) and the filter.

    ``reset_at_s``: instead of the alignment, start the filter there with
    :meth:`ErrorStateEkf.reset_to` on the true position, velocity and attitude (biases unknown:
    zero, with their EKF2_*BIAS_INIT priors), e.g. in the air. ``each_frame(t, ekf)``: called
    after every frame's prediction and fusions once the filter is initialised."""
    suite = SensorSuite(sensors, HOME_ALT_M, imu_rate_hz=500.0)
    for f in faults:
        suite.add_fault(f)
    ekf = ErrorStateEkf(params, earth_field_world_gauss=sensors.earth_field_world_gauss)
    by_time = {round(t * 1e6): s for t, s in truth}
    ts, pe, ve, ae, bge, bae, sig, nees = [], [], [], [], [], [], [], []
    gps_err, gps_t = [], []
    statuses = []
    converged_t = math.nan
    t_prev = None
    next_status = 0.0
    for k, (t, tr) in enumerate(truth):
        if until_s is not None and t > until_s:
            break
        frame = suite.step(t, tr)
        imu = frame.imu
        sample = ImuSample(t, t - t_prev if t_prev is not None else 0.002, imu.angular_rate_rad_s,
                           imu.specific_force_m_s2)  # fmt: skip
        t_prev = t
        if reset_at_s is not None and not ekf.initialised:
            if t < reset_at_s:
                continue
            ekf.reset_to(sample, tr.position_m, tr.velocity_m_s, tr.quaternion, position_std_m=0.01)
        else:
            ekf.predict(sample)
        if frame.gps is not None:
            g = frame.gps
            ekf.fuse_gps(GpsFix(t, g.position_m, g.velocity_m_s, g.eph_m, g.epv_m, g.speed_accuracy_m_s,
                                g.fix_type, g.satellites_visible))  # fmt: skip
            if g.fix_type >= 3:
                ref = by_time.get(round(g.time_s * 1e6))
                if ref is not None:
                    gps_err.append(np.subtract(g.position_m, ref.position_m))
                    gps_t.append(g.time_s)
        if frame.baro is not None:
            ekf.fuse_baro(BaroSample(t, frame.baro.pressure_altitude_m - HOME_ALT_M))
        if frame.mag is not None:
            ekf.fuse_mag(MagSample(t, frame.mag.field_gauss))
        if frame.vision is not None:
            v = frame.vision
            ekf.fuse_vision(VisionPose(t, v.position_m, v.yaw_rad, v.position_std_m, v.yaw_std_rad))
        if not ekf.initialised:
            continue
        if each_frame is not None:
            each_frame(t, ekf)
        if math.isnan(converged_t) and ekf.status().converged:
            converged_t = t
        if status_every_s > 0.0 and t >= next_status:
            statuses.append((t, ekf.status()))
            next_status = t + status_every_s
        if k % nees_every:
            continue
        est = ekf.estimate()
        e = np.empty(MOVING)
        e[IP : IP + 3] = np.subtract(tr.position_m, est.position_m)
        e[IV : IV + 3] = np.subtract(tr.velocity_m_s, est.velocity_m_s)
        e[ITH : ITH + 3] = attitude_error(tr.quaternion, est.quaternion)
        ba_true, bg_true = suite.imu_biases(t)
        e[IBG : IBG + 3] = np.subtract(bg_true, est.gyro_bias_rad_s)
        e[IBA : IBA + 3] = np.subtract(ba_true, est.accel_bias_m_s2)
        P = ekf.P[:MOVING, :MOVING]
        ts.append(t)
        pe.append(e[IP : IP + 3])
        ve.append(e[IV : IV + 3])
        ae.append(e[ITH : ITH + 3])
        bge.append(e[IBG : IBG + 3])
        bae.append(e[IBA : IBA + 3])
        sig.append(np.sqrt(np.diag(P)))
        nees.append(float(e @ _solve_covariance(P, e)))
    return FilterRun(
        np.array(ts), np.array(pe), np.array(ve), np.array(ae), np.array(bge), np.array(bae), np.array(sig),
        np.array(nees), np.array(gps_err).reshape(-1, 3), np.array(gps_t), converged_t, ekf, suite, statuses,
    )  # fmt: skip


def _solve_covariance(P: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``P^-1 e``; for a singular P (a direction known exactly: after alignment on exact sensors,
    the tilt and the accelerometer bias it was measured with) the pseudo-inverse, whose NEES
    counts only the directions that have an uncertainty."""
    try:
        return np.linalg.solve(P, e)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(P, hermitian=True) @ e
