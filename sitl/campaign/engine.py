"""The batch engine: pack a run's configuration into flat arrays and fly it with the kernel.

Every number the kernel uses is read off the project's own objects, built the way the scalar
runner builds them (a :class:`simulator.dynamics.plant.Plant`, a
:func:`autopilot.control.cascade.pack`, the trajectory of :func:`trajectory_from_spec`, the
gust profile's elements, the Dryden generator), so the batch engine and
``sitl.inprocess.run_scenario`` fly the same parameters with the same equations
(:mod:`sitl.campaign.kernels`): any registered law pair flies here, compiled.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from autopilot.control import registry
from autopilot.control.cascade import pack
from autopilot.control.config import ControllerConfig
from autopilot.estimation import filter as ekf
from autopilot.estimation.eskf import DEFAULT_EARTH_FIELD_WORLD_GAUSS
from autopilot.estimation.parameters import EstimatorParams
from gcs_scripts.analysis.record import FlightRecord
from quadcommon.config import Rates, TrajectorySpec, VehicleConfig, load_sitl
from quadcommon.kernel import compiled
from quadcommon.layout import column_names
from quadcommon.trajectories import trajectory_from_spec
from quadcommon.wire_values import frame_time_s, frame_time_usec
from simulator.dynamics.equations import ROTOR_FAULT
from simulator.dynamics.plant import Plant
from simulator.environment.dryden import DrydenWind
from simulator.environment.gust_profile import GustProfile, element_rows
from simulator.sensors import SensorConfig
from simulator.sensors import frame as sensor_frame

from . import kernels as lay

Vector3 = tuple[float, float, float]

FAILURE_NAMES = {
    lay.FAIL_NONE: "",
    lay.FAIL_NONFINITE: "diverged: non-finite state",
    lay.FAIL_POSITION: "diverged: position error above the limit",
    lay.FAIL_TILT: "diverged: tilt above the limit",
    lay.FAIL_GROUND: "crashed: ground contact after take-off",
}  # FAIL_CONTROLLER: named with the controller (failure_reason)


def failure_reason(code: int, controller: str) -> str:
    """A run's failure code (``FAIL_*``) as its reason; a non-finite output names the controller
    as the autopilot names it when it terminates a flight (:func:`registry.non_finite_output`)."""
    if code == lay.FAIL_CONTROLLER:
        return registry.non_finite_output(controller)
    return FAILURE_NAMES[code]

NO_FAULTS = np.zeros((0, ROTOR_FAULT.size))  # a flight without rotor faults (writable: numba's type)

# Names of the metric columns: the kernel's metrics row as its layout names them (kernels.METRICS).
METRIC_COLUMNS = column_names(lay.METRICS)
# On the estimate, after those (kernels.ESTIMATION_METRICS).
ESTIMATION_COLUMNS = column_names(lay.ESTIMATION_METRICS)
# A campaign that draws faults, after those (:func:`fault_columns`).
FAULT_COLUMNS = ("survived", "fault_onset_s", "max_excursion_m", "time_to_recover_s", "impact_speed_m_s")


@dataclass(frozen=True)
class FailureLimits:
    """When a run counts as failed (it then stops at that sample)."""

    max_position_error_m: float = 5.0
    max_tilt_rad: float = 1.3
    airborne_height_m: float = 0.05  # a ground contact after O rose above this is a crash


@dataclass(frozen=True)
class SurvivalLimits:
    """What a run that draws faults must do to survive them: stay within ``envelope_m`` of the
    reference for the whole run (and not fail: no divergence, no tilt past the limit, no ground
    contact after take-off); it has recovered once its position error is back within
    ``recovery_bound_m`` for the rest of the run."""

    envelope_m: float = 1.0
    recovery_bound_m: float = 0.1


@dataclass(frozen=True)
class Controller:
    """A cascade packed for the kernel: its two laws (by name), its own numbers ``K``, the laws'
    gains and how many state entries each has."""

    translational: str
    rotational: str
    K: np.ndarray
    gt: np.ndarray
    gr: np.ndarray
    nxt: int
    nxr: int


@dataclass(frozen=True)
class Flight:
    """One run x controller, packed for :func:`sitl.campaign.kernels.simulate`."""

    state0: np.ndarray
    plant: np.ndarray
    controller: Controller
    reference: np.ndarray  # reference_table()
    sim: np.ndarray
    steps: np.ndarray
    ramps: np.ndarray
    gusts: np.ndarray
    dryden: np.ndarray
    estimation: tuple = ()  # the run's sensors and filter (estimator_memory()); () on the truth
    # the run's rotor faults (simulator.dynamics.plant.fault_table; none: zero rows)
    faults: np.ndarray = field(default_factory=lambda: NO_FAULTS)

    @property
    def samples(self) -> int:
        """How many samples the flight recorded: the physics steps taken plus the initial one."""
        return int(self.sim[lay.SETTINGS.steps]) + 1


# -------------------------------------------------------------------------------------------------
# Packing
# -------------------------------------------------------------------------------------------------
def initial_state(
    plant_vehicle: VehicleConfig,
    dt_physics: float,
    position_m: Vector3,
    euler_rad: Vector3,
    velocity_m_s: Vector3 = (0.0, 0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """``(state0, P)``: the plant placed by :meth:`Plant.reset` and its constants."""
    plant = Plant(plant_vehicle, dt_physics)
    plant.reset(position_m, euler_rad, velocity_m_s)
    return np.array(plant.state, dtype=float), np.array(plant.parameters(), dtype=float)


def pack_controller(controller: ControllerConfig, vehicle: VehicleConfig, dt_control: float) -> Controller:
    """The cascade's numbers as the kernel reads them, packed as :class:`Cascade` packs them."""
    p = pack(controller, vehicle, dt_control)
    return Controller(controller.translational.law, controller.rotational.law, np.array(p.K), np.array(p.gt),
                      np.array(p.gr), len(p.translational.STATE), len(p.rotational.STATE))  # fmt: skip


def reference_table(spec: TrajectorySpec, rates: Rates, duration_s: float, wire_float32: bool) -> np.ndarray:
    """Row k: the reference the controller gets at control step k, from the project's trajectory.

    Columns: :data:`~.kernels.REFERENCE_ROW` (paper frames, SI). The time is
    ``k dt`` in-process, and ``time_usec * 1e-6`` with ``time_usec = round(k * 1e6 / control_hz)``
    through the wire (the autopilot reads its clock off the frame), as the two runners sample it.
    The same for every run of a campaign, so it is sampled once per process.
    """
    trajectory = trajectory_from_spec(spec)
    dt_control = 1.0 / rates.control_hz
    usec_per_frame = 1e6 / rates.control_hz
    steps = int(round(duration_s / dt_control))
    R = lay.REFERENCE_ROW
    table = np.empty((steps + 1, R.size))
    for k in range(steps + 1):
        t = frame_time_s(frame_time_usec(k, usec_per_frame)) if wire_float32 else k * dt_control
        r = trajectory.sample(t)
        row = table[k]
        row[R.position : R.position + 3] = r.position_m
        row[R.velocity : R.velocity + 3] = r.velocity_m_s
        row[R.acceleration : R.acceleration + 3] = r.acceleration_m_s2
        row[R.yaw], row[R.yaw_rate] = r.yaw_rad, r.yaw_rate_rad_s
        row[R.yaw_acceleration] = r.yaw_acceleration_rad_s2
    return table


def disturbance_tables(
    profile: GustProfile, dt_physics: float, duration_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[float, ...]]:
    """Steps, ramps, 1-cos gusts, Dryden wind samples, and the Dryden window (SETTINGS.dryden_*).

    The flat tables of :func:`element_rows`, as ``DisturbanceSchedule`` reads them (start time 0); the
    Dryden wind is drawn by the project's :class:`DrydenWind` at the physics step, one sample
    per step index the run can reach.
    """
    step_rows, ramp_rows, gust_rows = element_rows(profile)
    steps = np.array(step_rows, dtype=float)
    ramps = np.array(ramp_rows, dtype=float)
    gusts = np.array(gust_rows, dtype=float)
    d = profile.dryden
    if d is None:
        return steps, ramps, gusts, np.zeros((1, 3)), (0.0, 0.0, math.inf, math.inf, dt_physics)
    t0 = 0.0 + d.start_s
    last = max(int(math.floor((duration_s + dt_physics - t0) / dt_physics + 0.5)) + 2, 1)
    gen = DrydenWind(d, dt_physics)
    wind = np.array([gen.at_step(n) for n in range(last)], dtype=float).reshape(-1, 3)
    return steps, ramps, gusts, wind, (1.0, t0, d.start_s, d.end_s, dt_physics)


def sim_array(
    rates: Rates,
    duration_s: float,
    wire_float32: bool,
    limits: FailureLimits,
    dryden_window: tuple[float, ...],
    estimated: bool = False,
    fault_onset_s: float = math.inf,
    survival: SurvivalLimits = SurvivalLimits(),
) -> np.ndarray:
    """Timing, the wire switch, the failure limits and the faults' onset and recovery bound (layout
    ``SETTINGS``), as ``run_scenario`` times."""
    dt_control = 1.0 / rates.control_hz
    substeps = rates.physics_steps_per_control
    S = np.zeros(lay.SETTINGS.size)
    S[lay.SETTINGS.dt_control] = dt_control
    S[lay.SETTINGS.dt_physics] = dt_control / substeps
    S[lay.SETTINGS.substeps] = substeps
    S[lay.SETTINGS.steps] = int(round(duration_s / dt_control))
    S[lay.SETTINGS.wire] = 1.0 if wire_float32 else 0.0
    S[lay.SETTINGS.usec_per_frame] = 1e6 / rates.control_hz  # the simulator's time_usec per frame
    S[lay.SETTINGS.max_position_error] = limits.max_position_error_m
    S[lay.SETTINGS.max_tilt] = limits.max_tilt_rad
    S[lay.SETTINGS.airborne_height] = limits.airborne_height_m
    S[lay.SETTINGS.estimated] = 1.0 if estimated else 0.0
    S[lay.SETTINGS.home : lay.SETTINGS.home + 3] = home()
    S[lay.SETTINGS.fault_onset] = fault_onset_s
    S[lay.SETTINGS.recovery_bound] = survival.recovery_bound_m
    (
        S[lay.SETTINGS.dryden_on],
        S[lay.SETTINGS.dryden_t0],
        S[lay.SETTINGS.dryden_from],
        S[lay.SETTINGS.dryden_until],
        S[lay.SETTINGS.dryden_step],
    ) = dryden_window
    return S


def estimator_memory(sensors: SensorConfig, params: EstimatorParams, gravity_m_s2: float,
                     home_altitude_m: float, imu_rate_hz: float) -> lay.EstimatorArrays:  # fmt: skip
    """The memory of one flight's sensors and filter, as :func:`~sitl.campaign.kernels.simulate`
    takes it: the sensors switched on as :class:`~simulator.sensors.SensorSuite` switches them on
    (same seed, same switch-on biases and GNSS errors), a filter not yet started with the
    autopilot's parameters and field. Fresh per flight: the flight writes into it."""
    rng, S, C = sensor_frame.new_sensors(sensors, home_altitude_m, imu_rate_hz)
    faults = sensor_frame.fault_array(sensors.faults)
    F, P, ring, stats, windows, scratch = ekf.new_memory()
    A = ekf.parameter_array(params, gravity_m_s2, DEFAULT_EARTH_FIELD_WORLD_GAUSS)
    delivery = np.zeros(sensor_frame.DELIVERY.size)
    rng = np.asarray(rng, dtype=float)
    return lay.EstimatorArrays(rng, S, C, faults, delivery, F, P, ring, stats, windows, scratch, A)


def no_estimation() -> lay.EstimatorArrays:
    """Placeholder memory of a flight on the truth (the types :func:`estimator_memory`'s has)."""
    one, square = np.zeros(1), np.zeros((1, 1))
    no_faults = np.zeros((0, sensor_frame.FAULT.size))
    return lay.EstimatorArrays(one, one, one, no_faults, one, one, square, square, square, square, one, one)


@functools.cache
def home() -> tuple[float, float, float]:
    """The SITL's geodetic home (``config/sitl.toml``), as the simulator's GNSS fixes carry it."""
    return load_sitl().home


def dt_physics_of(rates: Rates) -> float:
    """The physics step exactly as ``run_scenario`` computes it."""
    return (1.0 / rates.control_hz) / rates.physics_steps_per_control


# -------------------------------------------------------------------------------------------------
# Flying
# -------------------------------------------------------------------------------------------------
@functools.cache
def entry(translational: str, rotational: str, estimated: bool = False):
    """The compiled flight of a law pair, on the truth or on the estimate (numba compiles it on its
    first call in a process, or loads it from its cache; the flight on the truth holds no sensors
    and no filter, and compiles several times faster)."""
    tr = registry.law(registry.TRANSLATIONAL, translational)
    rot = registry.law(registry.ROTATIONAL, rotational)
    estimator = lay.ON_ESTIMATE if estimated else lay.ON_TRUTH
    return compiled(lay.simulate, tr.step, rot.step, *estimator, nogil=True)


def fly(flight: Flight, record: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Fly one packed run: ``(metrics row, recorded rows or None)``."""
    rows = np.zeros((flight.samples if record else 0, lay.RECORD.size))
    c = flight.controller
    estimation = flight.estimation or no_estimation()
    arrays = lay.FlightArrays(flight.state0, flight.plant, c.K, c.gt, c.gr, c.nxt, c.nxr, flight.reference,
                              flight.sim, flight.steps, flight.ramps, flight.gusts, flight.dryden,
                              flight.faults)  # fmt: skip
    metrics = entry(c.translational, c.rotational, bool(flight.estimation))(arrays, estimation, rows)
    if not record:
        return metrics, None
    flown = int(round(metrics[lay.RUN_END.end_time] / flight.sim[lay.SETTINGS.dt_control])) + 1
    return metrics, rows[:flown]


def record_to_flight_record(
    rows: np.ndarray, label: str, scenario: str, controller: str, event_times: list[float]
) -> FlightRecord:
    """Recorded rows (layout :data:`~.kernels.RECORD`) as the analysis package's :class:`FlightRecord`."""
    R = lay.RECORD
    return FlightRecord(
        label=label,
        scenario=scenario,
        controller=controller,
        time_s=rows[:, R.t].copy(),
        position_m=rows[:, R.position : R.position + 3].copy(),
        position_ref_m=rows[:, R.position_ref : R.position_ref + 3].copy(),
        euler_rad=rows[:, R.euler : R.euler + 3].copy(),
        euler_ref_rad=rows[:, R.euler_ref : R.euler_ref + 3].copy(),
        thrust_n=rows[:, R.thrust].copy(),
        torque_euler_n_m=rows[:, R.torque_euler : R.torque_euler + 3].copy(),
        disturbance_force_n=rows[:, R.disturbance_force : R.disturbance_force + 3].copy(),
        disturbance_torque_n_m=rows[:, R.disturbance_torque : R.disturbance_torque + 3].copy(),
        event_times_s=list(event_times),
        source="campaign batch engine",
    )


def metrics_dict(metrics: np.ndarray, controller: str) -> dict[str, float | bool | str]:
    """``controller``'s metrics row as named columns (plus the final-error norm and the failure
    reason)."""
    out: dict[str, float | bool | str] = {
        name: float(metrics[lay.METRICS.start + i]) for i, name in enumerate(METRIC_COLUMNS)
    }
    fx, fy, fz = out["final_error_x_m"], out["final_error_y_m"], out["final_error_z_m"]
    out["final_error_m"] = math.sqrt(fx * fx + fy * fy + fz * fz)  # type: ignore[operator]
    code = int(metrics[lay.RUN_END.failure])
    out["failed"] = code != lay.FAIL_NONE
    out["failure"] = failure_reason(code, controller)
    out["failure_time_s"] = float(metrics[lay.RUN_END.failure_time])
    if not math.isnan(metrics[lay.ESTIMATION_METRICS.estimate_rms_error_m]):
        for i, name in enumerate(ESTIMATION_COLUMNS):
            out[name] = float(metrics[lay.ESTIMATION_METRICS.start + i])
    return out


def fault_columns(metrics: np.ndarray, row: dict, survival: SurvivalLimits, onset_s: float,
                  dt_control: float) -> dict[str, float | bool]:  # fmt: skip
    """A fault study's columns of one flight (:data:`FAULT_COLUMNS`), from its metrics row and its
    named columns (``row``: :func:`metrics_dict`'s): ``survived`` (the run flew to its end and its
    position error stayed within the envelope), ``fault_onset_s`` (the first fault's, ``onset_s``),
    ``max_excursion_m`` (the largest position error from the onset on; NaN when the run ended
    before it),
    ``time_to_recover_s`` (from the onset until the error is back within the recovery bound for
    good: 0 if it never left it; NaN when it had not recovered by the run's end, or the run failed)
    and ``impact_speed_m_s`` (the downward speed at a ground contact after take-off; NaN: none)."""
    failed = bool(row["failed"])
    last_out = float(metrics[lay.FAULT_METRICS.last_out])
    end = float(metrics[lay.RUN_END.end_time])
    if failed or not onset_s <= end:
        recover = math.nan
    elif math.isnan(last_out):
        recover = 0.0
    elif last_out >= end:  # still out at the last sample
        recover = math.nan
    else:
        recover = max(last_out + dt_control - onset_s, 0.0)
    return {
        "survived": not failed and float(row["max_position_error_m"]) <= survival.envelope_m,
        "fault_onset_s": onset_s,
        "max_excursion_m": float(metrics[lay.FAULT_METRICS.excursion]),
        "time_to_recover_s": recover,
        "impact_speed_m_s": float(metrics[lay.FAULT_METRICS.impact_speed]),
    }
