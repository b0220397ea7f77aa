"""Campaigns on the estimate: the batch engine flies the sensor models and the autopilot's EKF
(estimator = "ekf", sensors = NAME), each run with its own noise; the spec draws sensor figures
and faults per run; the results carry the estimation columns; and the runs are the ones the
scalar in-process stack flies with the same seeds."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from autopilot.control.config import load_controller
from quadcommon.schema import ConfigError
from sitl.campaign import batch
from sitl.campaign import engine as eng
from sitl.campaign.sampling import sample_run
from sitl.campaign.spec import load_campaign

pytestmark = pytest.mark.timeout(300)

SPEC = """
name = "test_estimate"
scenario = "helix"
controllers = ["intbs_nlhinf"]
runs = 6
seed = 5
duration_s = {duration}
estimator = "ekf"
sensors = "{sensors}"

[plant]
mass_scale = {{ uniform = [0.8, 1.2] }}
{extra}
"""

DRAWS = """
[sensor_parameters]
gps_horizontal_noise_std_m = { uniform = [0.2, 0.6] }
accel_noise_density = { uniform = [1e-3, 3e-3] }

[[sensor_faults]]
kind = "gps_glitch"
start_s = { uniform = [2.0, 3.0] }
duration_s = 1.0
value = [{ uniform = [8.0, 12.0] }, 0.0, 0.0]

[[sensor_faults]]
kind = "mag_disturbance"
start_s = 1.0
duration_s = { uniform = [0.5, 1.0] }
value = [0.05, 0.0, 0.0]
"""


def write(tmp_path: Path, sensors: str = "gps", duration: float = 6.0, extra: str = "") -> Path:
    path = tmp_path / f"estimate_{sensors}.toml"
    path.write_text(SPEC.format(duration=duration, sensors=sensors, extra=extra))
    return path


def error(tmp_path: Path, text: str) -> str:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_campaign(path)
    message = str(info.value)
    assert str(path) in message
    return message


def test_the_spec_is_validated_naming_file_key_value_and_range(tmp_path):
    base = SPEC.format(duration=6.0, sensors="gps", extra="")
    message = error(tmp_path, base.replace('sensors = "gps"\n', ""))
    assert "'sensors' is missing" in message
    message = error(tmp_path, base.replace('sensors = "gps"', 'sensors = "no_such_profile"'))
    assert "'sensors'" in message and "no_such_profile" in message
    message = error(tmp_path, base + "[sensor_parameters]\ngps_horizontal_noise_std_m = 50.0\n")
    assert (
        "sensor_parameters.gps_horizontal_noise_std_m" in message and "50" in message and "[0, 20]" in message
    )
    message = error(tmp_path, base + "[sensor_parameters]\nbogus = 1.0\n")
    assert "bogus" in message
    message = error(tmp_path, base + '[[sensor_faults]]\nkind = "gps_jam"\nstart_s = 1.0\n')
    assert "sensor_faults[0].kind" in message and "gps_jam" in message and "gps_glitch" in message
    message = error(tmp_path, base + '[[sensor_faults]]\nkind = "gps_outage"\nstart_s = 9.0\n')
    assert "sensor_faults[0].start_s" in message and "[0, 6]" in message
    truth = base.replace('estimator = "ekf"\n', "")
    message = error(tmp_path, truth)
    assert "'sensors'" in message and 'estimator = "ekf"' in message


def test_each_run_has_its_own_noise_and_draws_and_the_columns_are_filled(tmp_path):
    spec = load_campaign(write(tmp_path, extra=DRAWS))
    assert spec.estimator == "ekf" and spec.estimation.sensors_name == "gps"
    rows = batch.run_chunk(spec, [0, 1, 0])
    first, second, again = rows
    assert first.keys() == again.keys()
    for key, value in first.items():  # a run depends on (spec, run) only
        assert value == again[key] or (value != value and again[key] != again[key]), key
    assert first["sensor_seed"] != second["sensor_seed"]
    assert first["estimate_rms_error_m"] != second["estimate_rms_error_m"]
    for row in (first, second):
        assert not row["failed"], row["failure"]
        assert 0.2 <= row["gps_horizontal_noise_std_m"] <= 0.6
        assert 8.0 <= row["fault0_gps_glitch_value_x"] <= 12.0
        assert 0.01 < row["estimate_rms_error_m"] < 0.5
        assert row["rejected_samples"] >= 5  # the 10 m glitch: GNSS fixes gated out (10 Hz, 1 s)
        assert row["worst_test_ratio"] > 1.0
        assert 0.0 <= row["time_not_converged_s"] < 6.0
    sample = sample_run(spec, 1)
    kinds = [f.kind for f in sample.sensors.faults]
    assert kinds == ["gps_glitch", "mag_disturbance"]
    assert sample.sensors.gps.reported_eph_m == pytest.approx(second["gps_horizontal_noise_std_m"])


def test_a_truth_campaign_has_no_estimation_columns(tmp_path):
    path = tmp_path / "truth.toml"
    path.write_text(
        SPEC.format(duration=2.0, sensors="gps", extra="").replace('estimator = "ekf"\nsensors = "gps"\n', "")
    )
    spec = load_campaign(path)
    assert spec.estimator == "truth"
    row = batch.run_chunk(spec, [0])[0]
    assert "estimate_rms_error_m" not in row and "sensor_seed" not in row


def fly_both(spec, run: int):
    """Run ``run`` of ``spec`` through the batch engine (recorded) and through the in-process
    stack (simulator core, MAVLink frames, autopilot core with its EKF) with the run's sensors."""
    from sitl.inprocess import RunOptions, paper_stack

    sample = sample_run(spec, run)
    controller = spec.controllers[0]
    _, rows = eng.fly(batch.flights(spec, sample)[controller.name], record=True)
    options = RunOptions(duration_s=spec.duration_s, rates=spec.rates, gusts=sample.gusts, estimator="ekf",
                         sensors=spec.estimation.sensors_name, sensor_config=sample.sensors,
                         true_plant=sample.plant_vehicle,
                         initial_velocity_m_s=sample.initial_velocity_m_s)  # fmt: skip
    stack = paper_stack(sample.scenario, controller, options, sample.vehicle)
    for _ in range(int(round(spec.duration_s / stack.sim.dt_control))):
        stack.step()
    stack.final_frame()
    return rows, np.asarray(stack.truth_rows), np.asarray(stack.controller_rows)


@pytest.mark.parametrize(
    ("sensors", "extra", "runs", "controller"),
    [
        ("gps", DRAWS, (0, 3), "intbs_nlhinf"),
        ("mocap", "", (2,), "intbs_nlhinf"),
        ("gps", "", (1,), "px4_pid"),
    ],
)
def test_campaign_runs_agree_with_the_in_process_stack(tmp_path, sensors, extra, runs, controller):
    """Tolerance: the position and attitude of the vehicle at every frame agree to 1e-9 (m, rad),
    i.e. to round-off: both paths run the same kernels (sensor frame, filter, cascade, plant) on
    the same seeds, and the batch engine reproduces what the wire does to the samples (float32
    HIL_SENSOR and vision, HIL_GPS in 1e-7 deg, mm, cm/s and cm). Measured: identical bits.
    Flown in simulation time (6 s of flight per run)."""
    spec = load_campaign(write(tmp_path, sensors=sensors, extra=extra.replace("intbs_nlhinf", controller)))
    spec = replace(spec, controllers=(load_controller(controller),))
    for run in runs:
        rows, truth, _ = fly_both(spec, run)
        assert len(truth) == len(rows)
        assert np.isfinite(rows[:, 1:10]).all()
        position = np.abs(truth[:, 1:4] - rows[:, 1:4]).max()
        attitude = np.abs(truth[:, 14:17] - rows[:, 7:10]).max()  # phi, theta, psi
        assert position <= 1e-9 and attitude <= 1e-9, (run, position, attitude)
        # ... and the run flew on the estimate: its estimate is not the truth.
        assert np.abs(rows[10:, 23:26] - rows[10:, 1:4]).max() > 1e-3
        assert math.isfinite(rows[-1, 23])


def test_paper_box_gps_is_the_paper_box_on_the_estimate():
    """Same scenario, cascades, plant box, seed and limits as paper_box, so a run's plant and
    disturbances are the same in both tables; flown on the gps profile and its EKF profile."""
    box, gps = load_campaign("paper_box"), load_campaign("paper_box_gps")
    assert gps.estimator == "ekf" and box.estimator == "truth"
    assert gps.estimation.sensors_name == "gps"
    assert gps.controller_names == box.controller_names and gps.runs == box.runs == 1000
    for key in ("seed", "failure", "duration_s", "wire_float32", "plant", "initial", "base_profile"):
        assert getattr(gps, key) == getattr(box, key), key
    for run in (0, 17):
        a, b = sample_run(box, run), sample_run(gps, run)
        assert a.plant_vehicle == b.plant_vehicle and a.gusts == b.gusts
        assert b.sensors is not None and b.sensors.gps.enabled
