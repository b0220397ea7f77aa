"""The batch engine flies exactly what the scalar runner flies, run for run.

* wire on (what campaigns fly): against ``sitl.inprocess.run_scenario`` itself, the whole flight
  stack in-process (simulator core, MAVLink frames, autopilot core with its commander and
  cascade), on sampled runs of a +-30 % box with random initial states and random disturbances,
  all three cascades, 40 s: trajectories agree to 1e-9 m (measured: bit for bit), and so do the
  indices (to rounding of the sums);
* wire off: against the plant and the cascade coupled directly (``tests/sitl/campaign/reference.py``),
  40 s, same tolerance;
* what ``run_scenario`` cannot take (rotor constants unknown to the allocator, an initial
  velocity, drag with 1-cos gusts, ramps and Dryden turbulence, CoM and crossed inertia): against
  the reference helper, which is itself checked equal to ``run_scenario``.
"""

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("numba")

from gcs_scripts.analysis.metrics import indices  # noqa: E402
from sitl.campaign import batch  # noqa: E402
from sitl.campaign import engine as eng  # noqa: E402
from sitl.campaign.sampling import sample_run  # noqa: E402
from sitl.campaign.spec import load_campaign  # noqa: E402
from sitl.inprocess import RunOptions, run_scenario  # noqa: E402

from . import specs  # noqa: E402
from .reference import fly_scalar  # noqa: E402

TOLERANCE_M = 1e-9


def _batch_rows(spec, sample, controller):
    flight = batch.flights(spec, sample)[controller]
    metrics, rows = eng.fly(flight, record=True)
    return metrics, rows


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    assert a.shape == b.shape
    return float(np.abs(a - b).max())


@pytest.mark.timeout(600)
@pytest.mark.parametrize("run", [0])  # one drawn run x three cascades x 40 s (wire off: another)
def test_wire_on_equals_run_scenario(tmp_path, run):
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box"))
    assert spec.wire_float32
    sample = sample_run(spec, run)
    for controller in spec.controllers:
        record = run_scenario(
            sample.scenario,
            controller,
            RunOptions(gusts=sample.gusts, duration_s=spec.duration_s),
            sample.vehicle,
        )
        metrics, rows = _batch_rows(spec, sample, controller.name)
        assert len(rows) == len(record.time_s) == 20001
        gap = _gap(rows[:, 1:4], record.position_m)
        assert gap <= TOLERANCE_M, f"{controller.name}: position gap {gap:.3e} m"
        assert _gap(rows[:, 7:10], record.euler_rad) <= 1e-9
        assert _gap(rows[:, 10:13], record.euler_ref_rad) <= 1e-9
        assert _gap(rows[:, 13:17], record.controls) <= 1e-9
        assert np.array_equal(rows[:, 17:20], record.disturbance_force_n)
        assert np.array_equal(rows[:, 20:23], record.disturbance_torque_n_m)
        # the indices accumulated in flight are the analysis package's indices of the record
        ref = indices(record)
        got = eng.metrics_dict(metrics, controller.name)
        for i, axis in enumerate("xyz"):
            assert got[f"final_error_{axis}_m"] == pytest.approx(ref.final_error_m[i], rel=1e-12, abs=1e-15)
        for name, value in ref.ise.items():
            assert got[f"ise_{name}"] == pytest.approx(value, rel=1e-9)
        for name, value in ref.iadu.items():
            assert got[f"iadu_{name}"] == pytest.approx(value, rel=1e-9)
        assert got["failed"] is False
        assert got["max_position_error_m"] == pytest.approx(
            float(np.linalg.norm(record.position_error_m, axis=1).max()), rel=1e-12
        )


@pytest.mark.timeout(600)
@pytest.mark.parametrize("run", [4])
def test_wire_off_equals_the_direct_coupling(tmp_path, run):
    spec = replace(load_campaign(specs.write(tmp_path, specs.BOX, "box")), wire_float32=False)
    sample = sample_run(spec, run)
    for controller in spec.controllers:
        reference = fly_scalar(spec, sample, controller, wire=False)
        _, rows = _batch_rows(spec, sample, controller.name)
        gap = _gap(rows[:, 1:4], reference[:, 1:4])
        assert gap <= TOLERANCE_M, f"{controller.name}: position gap {gap:.3e} m"
        assert _gap(rows[:, 7:17], reference[:, 7:17]) <= 1e-9
        # and the wire does change the flight (the switch is not a no-op)
        on = fly_scalar(spec, sample, controller, wire=True)
        assert _gap(on[:, 1:4], reference[:, 1:4]) > 1e-12


@pytest.mark.timeout(600)
def test_reference_helper_is_run_scenario(tmp_path):
    spec = load_campaign(specs.write(tmp_path, specs.BOX, "box", duration=10.0))
    sample = sample_run(spec, 2)
    controller = spec.controllers[0]
    record = run_scenario(
        sample.scenario,
        controller,
        RunOptions(gusts=sample.gusts, duration_s=spec.duration_s),
        sample.vehicle,
    )
    rows = fly_scalar(spec, sample, controller, wire=True)
    assert np.array_equal(rows[:, 1:4], record.position_m)
    assert np.array_equal(rows[:, 13:17], record.controls)


@pytest.mark.timeout(900)
@pytest.mark.parametrize("template, name", [(specs.WIND, "wind"), (specs.ROTORS, "rotors")])
@pytest.mark.parametrize("wire", [False, True])
def test_unmodelled_dynamics_and_wind_agree(tmp_path, template, name, wire):
    spec = replace(load_campaign(specs.write(tmp_path, template, name)), wire_float32=wire)
    sample = sample_run(spec, 1)
    if name == "rotors":
        assert sample.plant_vehicle.rotors != sample.vehicle.rotors  # the allocator does not know them
    else:
        assert sample.gusts.dryden is not None and sample.gusts.one_minus_cosine and sample.gusts.ramps
        assert sample.initial_velocity_m_s != (0.0, 0.0, 0.0)
    for controller in spec.controllers:
        reference = fly_scalar(spec, sample, controller, wire=wire)
        _, rows = _batch_rows(spec, sample, controller.name)
        gap = _gap(rows[:, 1:4], reference[:, 1:4])
        assert gap <= TOLERANCE_M, f"{name}/{controller.name}/wire={wire}: position gap {gap:.3e} m"
        assert _gap(rows[:, 7:23], reference[:, 7:23]) <= 1e-9
