"""zenoh rows -> the view's samples: disturbance onsets across batches, the exact join, JSON."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs_scripts.analysis.log_reader import disturbance_events
from gcs_scripts.view.sampler import DISTURBANCE_COLUMNS, DisturbanceOnsets, VehicleSampler
from quadcommon.bus_records import TRUTH_FIELDS
from tests.gcs_scripts.helpers import control_times, controller_rows, ref_x, truth_rows, truth_x

pytestmark = pytest.mark.timeout(30)
COL = {n: i for i, n in enumerate(TRUTH_FIELDS)}


def _steps_and_ramps(times: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = np.zeros((len(times), 6))
    for _ in range(4):
        ch, t0 = rng.integers(0, 6), rng.uniform(times[0], times[-1])
        if rng.random() < 0.5:
            d[:, ch] += np.where(times >= t0, rng.uniform(-2, 2), 0.0)
        else:
            d[:, ch] += np.clip((times - t0) / 0.3, 0.0, 1.0) * rng.uniform(-2, 2)
    return d


@pytest.mark.parametrize("seed", range(6))
def test_onsets_over_batches_equal_the_analysis_rule_on_the_whole_log(seed):
    times = control_times(0.0, 3000)
    d = _steps_and_ramps(times, seed)
    onsets = DisturbanceOnsets()
    got: list[float] = []
    rng = np.random.default_rng(100 + seed)
    cuts = np.sort(rng.choice(np.arange(1, len(times)), size=40, replace=False))
    for chunk in np.split(np.arange(len(times)), cuts):
        got += onsets.add(times[chunk], d[chunk])
    assert got == disturbance_events(times, d)
    assert len(got) >= 1


def test_sample_joins_truth_and_controller_of_the_same_step():
    times = control_times(1.0, 100)
    s = VehicleSampler()
    s.add_truth(truth_rows(times))
    s.add_controller(controller_rows(times[:57]))  # the controller's batches lag behind
    sample = s.take()
    t = times[56]
    assert sample.time_s == pytest.approx(t)
    assert sample.position_m[0] == pytest.approx(truth_x(t), abs=1e-6)
    assert sample.position_ref_m[0] == pytest.approx(ref_x(t), abs=1e-6)
    assert sample.thrust_n == pytest.approx(9.81 + math.sin(5 * t), abs=1e-5)
    assert s.take() is None  # nothing new since
    s.add_controller(controller_rows(times[57:80]))
    assert s.take().time_s == pytest.approx(times[79])


def test_sample_without_controller_rows_has_unknown_references_and_valid_json():
    times = control_times(0.0, 20)
    rows = truth_rows(times)
    rows[-1, COL["x_m"]] = np.nan
    s = VehicleSampler()
    s.add_truth(rows)
    sample = s.take()
    js = sample.to_json()
    assert js["pr"] == [None, None, None] and js["u1"] is None
    assert js["p"][0] is None  # NaN never reaches JSON
    assert js["t"] == pytest.approx(times[-1])


def test_sampler_reports_each_onset_once():
    times = control_times(0.0, 1500)  # the helpers' disturbance steps at t = 1 s and 2 s
    s = VehicleSampler()
    for chunk in np.array_split(np.arange(len(times)), 7):
        s.add_truth(truth_rows(times[chunk]))
    assert s.take_events() == pytest.approx([1.0, 2.0])
    assert s.take_events() == []
    assert len(DISTURBANCE_COLUMNS) == 6


def test_each_step_is_sampled_once_and_a_stalled_controller_does_not_freeze_the_vehicle():
    times = control_times(0.0, 400)
    s = VehicleSampler()
    s.add_truth(truth_rows(times[:20]))
    s.add_controller(controller_rows(times[:10]))
    first = s.take()
    assert first.time_s == pytest.approx(times[9])
    s.add_truth(truth_rows(times[20:30]))  # truth moves on, the controller not yet: nothing new to show
    assert s.take() is None
    s.add_controller(controller_rows(times[10:20]))
    assert s.take().time_s == pytest.approx(times[19])
    s.add_truth(truth_rows(times[30:400]))  # the autopilot stopped: 0.74 s of truth alone
    alone = s.take()
    assert alone.time_s == pytest.approx(times[-1]) and alone.position_ref_m == [None, None, None]


def test_a_sample_carries_the_rotors_health():
    """The truth rows' rotor health (effectiveness, FAILURE_TYPE; rotors 1 front, 2 right, 3 rear,
    4 left) reaches the page as ``rot``: the view colours a failed rotor and names it."""
    times = control_times(0.0, 20)
    rows = truth_rows(times)
    rows[:, [COL[f"rotor{n}_effectiveness"] for n in (1, 2, 3, 4)]] = 1.0
    rows[10:, COL["rotor2_effectiveness"]] = 0.6
    rows[10:, COL["rotor2_failure"]] = 4.0  # wrong: a loss of effectiveness
    rows[15:, COL["rotor4_effectiveness"]] = 0.0
    rows[15:, COL["rotor4_failure"]] = 1.0  # off
    s = VehicleSampler()
    s.add_truth(rows)
    sample = s.take()
    assert sample.to_json()["rot"] == [1.0, 0.6, 1.0, 0.0, 0.0, 4.0, 0.0, 1.0]
