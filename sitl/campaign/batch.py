"""The unit of work a campaign hands to an Executor: fly some runs, with every controller.

:func:`run_chunk` is a plain top-level function of picklable arguments (the validated spec and
a list of run indices) returning plain rows, so any ``concurrent.futures.Executor`` can run it:
a local process pool or a Dask cluster (``Client.get_executor()``), on any machine with the
package installed. A run's rows depend only on the spec and the run's index (see
:mod:`.sampling`), never on the chunk it travels in.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from autopilot.control.cascade import not_compiled
from autopilot.control.config import ControllerConfig
from gcs_scripts.analysis.record import FlightRecord
from quadcommon.config import VehicleConfig, load_scenario, load_vehicle
from quadcommon.schema import ConfigError
from simulator.dynamics.plant import schedule
from simulator.environment.gust_profile import GustProfile

from . import engine as eng
from .sampling import RunSample, sample_run
from .spec import CampaignSpec


@functools.lru_cache(maxsize=32)
def _controller(controller: ControllerConfig, vehicle: VehicleConfig, dt_control: float) -> eng.Controller:
    # Building a Cascade runs scipy's expm for the command filter: once per process, not per run.
    return eng.pack_controller(controller, vehicle, dt_control)


@functools.lru_cache(maxsize=8)
def _reference(trajectory, rates, duration_s: float, wire: bool) -> np.ndarray:
    # The same reference for every run of a campaign: sampled once per process.
    table = eng.reference_table(trajectory, rates, duration_s, wire)
    table.flags.writeable = False
    return table


def flights(spec: CampaignSpec, sample: RunSample) -> dict[str, eng.Flight]:
    """The packed flights of one sampled run, one per controller (same plant and disturbances)."""
    rates = spec.rates
    dt_control = 1.0 / rates.control_hz
    dtp = eng.dt_physics_of(rates)
    sc = sample.scenario
    state0, P = eng.initial_state(
        sample.plant_vehicle, dtp, sc.initial_position_m, sc.initial_euler_rad, sample.initial_velocity_m_s
    )
    steps, ramps, gusts, dryden, window = eng.disturbance_tables(sample.gusts, dtp, spec.duration_s)
    estimated = spec.estimation is not None
    S = eng.sim_array(rates, spec.duration_s, spec.wire_float32, spec.failure, window, estimated,
                      sample.fault_onset_s, spec.survival)  # fmt: skip
    T = _reference(sc.trajectory, rates, spec.duration_s, spec.wire_float32)
    faults = schedule(sc.actuator_faults)[1] if sc.actuator_faults else eng.NO_FAULTS
    return {
        c.name: eng.Flight(
            state0,
            P,
            _controller(c, spec.vehicle, dt_control),
            T,
            S,
            steps,
            ramps,
            gusts,
            dryden,
            estimation(spec, sample) if estimated else (),
            faults,
        )  # fmt: skip
        for c in spec.controllers
    }


def estimation(spec: CampaignSpec, sample: RunSample) -> tuple:
    """A fresh memory of the run's sensors and filter (each controller's flight writes into its own)."""
    assert spec.estimation is not None and sample.sensors is not None
    return eng.estimator_memory(sample.sensors, spec.estimation.params, spec.vehicle.nominal.gravity_m_s2,
                                _home_altitude(), spec.rates.control_hz)  # fmt: skip


def _home_altitude() -> float:
    return eng.home()[2]


def run_chunk(spec: CampaignSpec, runs: Sequence[int]) -> list[dict[str, Any]]:
    """Fly ``runs`` with every controller of ``spec``: one row per (run, controller)."""
    rows: list[dict[str, Any]] = []
    dt_control = 1.0 / spec.rates.control_hz
    for run in runs:
        sample = sample_run(spec, int(run))
        for name, flight in flights(spec, sample).items():
            metrics, _ = eng.fly(flight)
            row = {"run": int(run), "controller": name, **sample.parameters,
                   **eng.metrics_dict(metrics, name)}  # fmt: skip
            if spec.draws_faults:  # a fault study: what the run survived, and the faults drawn
                row.update(eng.fault_columns(metrics, row, spec.survival, sample.fault_onset_s, dt_control))
                row["fault"] = sample.fault
            rows.append(row)
    return rows


def fly_recorded(spec: CampaignSpec, run: int, controller: str) -> tuple[FlightRecord, dict[str, Any]]:
    """Re-fly one run with the time series recorded: a :class:`FlightRecord` (for figures)."""
    sample = sample_run(spec, run)
    flight = flights(spec, sample)[controller]
    metrics, rows = eng.fly(flight, record=True)
    record = eng.record_to_flight_record(
        rows, f"{controller} (run {run})", spec.scenario.name, controller, sample.gusts.event_times()
    )
    return record, eng.metrics_dict(metrics, controller)


def warm_up(spec: CampaignSpec) -> float:
    """Compile the flight of each of the spec's law pairs now (or load it from numba's cache), in
    this process before the workers fork; returns the seconds it took. Flies a two-step hover with
    each controller; a pair numba cannot compile is a ConfigError naming the controller and the
    cause (:func:`~autopilot.control.cascade.not_compiled`)."""
    start = time.perf_counter()
    vehicle = load_vehicle("paper_quad")
    scenario = load_scenario("hover")
    rates = spec.rates
    dtp = eng.dt_physics_of(rates)
    state0, P = eng.initial_state(vehicle, dtp, scenario.initial_position_m, scenario.initial_euler_rad)
    steps, ramps, gusts, dryden, window = eng.disturbance_tables(GustProfile(), dtp, 0.004)
    S = eng.sim_array(rates, 0.004, True, eng.FailureLimits(), window)
    T = eng.reference_table(scenario.trajectory, rates, 0.004, True)
    estimated = spec.estimation is not None
    if estimated:
        S = eng.sim_array(rates, 0.004, True, eng.FailureLimits(), window, True)
    for controller in spec.controllers:
        C = _controller(controller, spec.vehicle, 1.0 / rates.control_hz)
        est = ()
        if estimated:
            assert spec.estimation is not None
            e = spec.estimation
            est = eng.estimator_memory(e.sensors, e.params, 9.81, _home_altitude(), rates.control_hz)
        try:
            eng.fly(eng.Flight(state0, P, C, T, S, steps, ramps, gusts, dryden, est))
        except Exception as error:  # noqa: BLE001 - numba's typing errors: a law pair it cannot compile
            laws = f"{C.translational} + {C.rotational}"
            raise ConfigError(f"controller {controller.name}: {not_compiled(laws, error)}") from error
    return time.perf_counter() - start
