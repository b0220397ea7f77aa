"""In-process runner: the plant core and a control cascade coupled without sockets.

Deterministic: fixed physics step (RK4), one control step every ``physics_hz / control_hz``
physics steps, actuator commands held in between (zero-order hold), the disturbance evaluated at
every physics step. The actuator commands cross from controller to plant as the same normalised
controls that travel in ``HIL_ACTUATOR_CONTROLS`` in the SITL, so both paths share the code on
either side of the wire.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from autopilot.control.cascade import Cascade, StateEstimate
from autopilot.guidance.trajectories import Trajectory, trajectory_from_spec
from gcs_scripts.analysis.record import FlightRecord
from quadcommon.config import (
    ControllerConfig,
    Rates,
    ScenarioConfig,
    VehicleConfig,
    apply_uncertainty,
    load_sitl,
    load_vehicle,
)
from simulator.dynamics.plant import make_plant
from simulator.environment.gust_profile import DisturbanceSchedule, GustProfile, load_gust_profile

# Columns of one recorded row (per control step).
_COLUMNS = (
    "t", "x", "y", "z", "xd", "yd", "zd", "phi", "theta", "psi", "phid", "thetad", "psid",
    "U1", "tau_phi", "tau_theta", "tau_psi", "Ax", "Ay", "Az", "Ap", "Aq", "Ar",
)  # fmt: skip


@dataclass(frozen=True)
class RunOptions:
    nominal_plant: bool = False  # fly the Section II model instead of the coupled plant
    duration_s: float | None = None  # default: the scenario's
    rates: Rates | None = None  # default: config/sitl.toml
    gusts: GustProfile | None = None  # default: the scenario's profile


def run_scenario(
    scenario: ScenarioConfig,
    controller: ControllerConfig,
    options: RunOptions = RunOptions(),
    vehicle: VehicleConfig | None = None,
    progress: Callable[[float], None] | None = None,
) -> FlightRecord:
    """Fly ``scenario`` with ``controller``; return the time series at the control rate."""
    vehicle = vehicle or load_vehicle(scenario.vehicle)
    rates = options.rates or load_sitl().rates
    plant_vehicle = apply_uncertainty(vehicle, scenario)
    if options.nominal_plant:
        plant_vehicle = _as_nominal(plant_vehicle)
    dt_control = 1.0 / rates.control_hz
    substeps = rates.physics_steps_per_control
    dt_physics = dt_control / substeps
    duration = options.duration_s if options.duration_s is not None else scenario.duration_s

    plant = make_plant(plant_vehicle, dt_physics)
    plant.reset(scenario.initial_position_m, scenario.initial_euler_rad)
    cascade = Cascade(controller, vehicle, dt_control)
    trajectory: Trajectory = trajectory_from_spec(scenario.trajectory)
    profile = options.gusts if options.gusts is not None else load_gust_profile(scenario.gusts)
    schedule = DisturbanceSchedule(profile, step_s=dt_physics)

    steps = int(round(duration / dt_control))
    rows: list[tuple[float, ...]] = []
    append = rows.append
    report_every = max(steps // 20, 1)
    for k in range(steps + 1):
        t = k * dt_control
        position, velocity, euler, euler_rates = plant.kinematics()
        ref = trajectory.sample(t)
        out = cascade.step(StateEstimate(position, velocity, euler, euler_rates), ref)
        force, torque, _ = schedule.evaluate(t)
        append(
            (t, *position, *ref.position_m, *euler, *out.euler_ref_rad, out.thrust_n,
             *out.torque_euler_n_m, *force, *torque)
        )  # fmt: skip
        if k == steps:
            break
        plant.set_actuator_controls(out.actuator_controls)
        for j in range(substeps):
            force, torque, wind = schedule.evaluate(t + j * dt_physics)
            plant.set_disturbance(force, torque, wind)
            plant.step()
        if progress is not None and k % report_every == 0:
            progress(k / steps)
        if not all(math.isfinite(v) for v in position):
            raise FloatingPointError(f"{scenario.name}/{controller.name}: state diverged at t={t:.3f} s")
    if progress is not None:
        progress(1.0)
    data = np.asarray(rows, dtype=float)
    return FlightRecord(
        label=controller.name,
        scenario=scenario.name,
        controller=controller.name,
        time_s=data[:, 0],
        position_m=data[:, 1:4],
        position_ref_m=data[:, 4:7],
        euler_rad=data[:, 7:10],
        euler_ref_rad=data[:, 10:13],
        thrust_n=data[:, 13],
        torque_euler_n_m=data[:, 14:17],
        disturbance_force_n=data[:, 17:20],
        disturbance_torque_n_m=data[:, 20:23],
        event_times_s=profile.event_times(),
        source="in-process (nominal plant)" if options.nominal_plant else "in-process",
    )


def _as_nominal(vehicle: VehicleConfig) -> VehicleConfig:
    """The vehicle flown as the Section II model: no CoM offset, no crossed inertia, wrench."""
    from dataclasses import replace

    plant = replace(
        vehicle.plant,
        model="nominal",
        com_offset_m=(0.0, 0.0, 0.0),
        products_of_inertia_kg_m2=(0.0, 0.0, 0.0),
    )
    return replace(vehicle, plant=plant, actuation=replace(vehicle.actuation, mode="wrench"))
