"""The paper's experiment in-process: the closed loops track, and the paper's pattern holds."""

import re
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from autopilot.control.config import CONTROLLER_NAMES, PAPER_CONTROLLERS, load_controller
from autopilot.control.registry import ControllerFailure
from gcs_scripts.analysis.metrics import indices
from quadcommon.config import load_scenario
from sitl.inprocess import RunOptions, run_scenario
from sitl.paper import run_job
from tests.own_law import laws_forgotten_afterwards, nan_above, write_overlay

# The module's runs (15 flights of 40 s, the EKF ones the slowest) take about 2 min on two cores, more
# while numba compiles the law pairs for the first time.
pytestmark = pytest.mark.timeout(420)


@pytest.fixture(scope="module")
def all_runs():
    """The paper's runs of every cascade (40 s each, the whole stack in-process) and the helix again
    with the paper's three on the autopilot's EKF over the motion-capture sensors, on two processes
    as ``quadsitl paper`` flies them."""
    jobs = [(s, c, False, None, None, None) for s in ("circle", "helix") for c in CONTROLLER_NAMES]
    jobs += [("helix", c, False, None, "ekf", "mocap") for c in PAPER_CONTROLLERS]
    with ProcessPoolExecutor(max_workers=2) as pool:
        done = zip(jobs, pool.map(run_job, jobs), strict=True)
        return {(s, c, job[4]): rec for job, (s, c, rec, _) in done}


@pytest.fixture(scope="module")
def runs(all_runs):
    return {(s, c): rec for (s, c, estimator), rec in all_runs.items() if estimator is None}


@pytest.fixture(scope="module")
def ekf_runs(all_runs):
    return {c: rec for (s, c, estimator), rec in all_runs.items() if estimator == "ekf"}


def test_on_the_ekf_with_mocap_the_paper_pattern_holds(ekf_runs):
    """The estimator in the loop (mocap: 1 mm, 0.11 deg, 100 Hz, 10 ms; a MEMS IMU): IntBS-NLHinf
    still ends within 5 mm and has the lowest position ISE of the paper's three."""
    ours = ekf_runs["intbs_nlhinf"]
    assert np.abs(ours.position_error_m[-1]).max() <= 5e-3
    table = {c: indices(rec).ise for c, rec in ekf_runs.items()}
    for axis in ("x", "y", "z"):
        assert min(PAPER_CONTROLLERS, key=lambda c: table[c][axis]) == "intbs_nlhinf", (axis, table)
    est = ours.estimator  # the estimate beside the truth, frame by frame
    assert est is not None and est.shape[0] == len(ours.time_s)
    error = est[:, 1:4] - ours.position_m
    assert np.sqrt(np.mean(np.sum(error**2, axis=1))) < 5e-3


# Largest position error after the first 4 s (disturbances included) and largest tilt, per cascade.
# The paper's three and SE(3) stay within 10 cm (SE(3) measured 5 cm on the circle, 7 cm on the
# helix, as BS-NLHinf: no integral action) under the tilt limit 0.7 rad plus a small overshoot.
# PX4's default gains are far softer than the paper's: its attitude loop gives 0.9 N m per rad
# where NLHinf gives ~15, so the 1 N m torque steps tilt it by up to ~1 rad for about a second before
# its rate integrals take them over, and the vehicle is pushed up to 5 m off the path (measured
# 5.0 m on the circle, 4.9 m on the helix, 4.8 m on the EKF), tilting to 0.85 rad (limit 45 deg).
# Autotuned (px4_pid_tuned) it holds the torque steps within 0.22 rad; what is left is its position
# loop's (PX4's default MPC gains take the 1 N steps over in ~5 s): 0.74 m on the circle, 0.57 m on
# the helix.
TRACKING_BOUNDS = {"px4_pid": (6.0, 0.9), "px4_pid_tuned": (0.9, 0.3)}


@pytest.mark.parametrize("scenario", ["circle", "helix"])
@pytest.mark.parametrize("controller", CONTROLLER_NAMES)
def test_closed_loop_tracks_with_the_papers_gains(runs, scenario, controller):
    rec = runs[(scenario, controller)]
    err = np.abs(rec.position_error_m)
    after_transient = rec.time_s > 4.0
    position_bound, tilt_bound = TRACKING_BOUNDS.get(controller, (0.1, 0.75))
    assert err[after_transient].max() < position_bound
    assert np.abs(rec.euler_rad[:, :2]).max() < tilt_bound


@pytest.mark.parametrize("scenario", ["circle", "helix"])
def test_paper_pattern_final_errors(runs, scenario):
    ours = np.abs(runs[(scenario, "intbs_nlhinf")].position_error_m[-1])
    intbs = np.abs(runs[(scenario, "intbs")].position_error_m[-1])
    bs = np.abs(runs[(scenario, "bs_nlhinf")].position_error_m[-1])
    assert ours.max() < 1e-3  # IntBS-NLHinf: below 1 mm on every axis
    assert 1e-3 < intbs.max() < 2e-2  # IntBS: a few mm, still converging
    assert bs.max() >= 1e-2  # BS-NLHinf keeps a centimetre offset


@pytest.mark.parametrize("scenario", ["circle", "helix"])
def test_paper_controller_has_lowest_position_ise(runs, scenario):
    """Of the paper's three (the baselines are compared in the docs' tables, as measured)."""
    table = {c: indices(runs[(scenario, c)]).ise for c in PAPER_CONTROLLERS}
    for axis in ("x", "y", "z"):
        best = min(PAPER_CONTROLLERS, key=lambda c: table[c][axis])
        assert best == "intbs_nlhinf", (axis, table)


def test_identical_runs_give_identical_results(runs):
    """Deterministic: a fresh 10 s run is the first 10 s of the 40 s one, bit for bit."""
    again = run_scenario(load_scenario("helix"), load_controller("intbs_nlhinf"), RunOptions(duration_s=10.0))
    first = runs[("helix", "intbs_nlhinf")]
    n = len(again.time_s)
    assert np.array_equal(first.position_m[:n], again.position_m)
    assert np.array_equal(first.torque_euler_n_m[:n], again.torque_euler_n_m)


def test_disturbances_follow_the_papers_schedule(runs):
    rec = runs[("circle", "intbs_nlhinf")]
    t = rec.time_s
    assert rec.event_times_s == [5.0, 10.0, 15.0, 20.0, 25.0, 30.0]
    assert np.all(rec.disturbance_force_n[t < 5.0] == 0.0)
    assert np.all(rec.disturbance_force_n[t >= 25.0] == 1.0)
    assert np.all(rec.disturbance_torque_n_m[t >= 30.0] == 1.0)


def test_nominal_plant_option_flies_the_section_ii_model():
    rec = run_scenario(
        load_scenario("helix"),
        load_controller("intbs_nlhinf"),
        RunOptions(nominal_plant=True, duration_s=12.0),
    )
    assert rec.source.endswith("(nominal plant)")
    assert np.abs(rec.position_error_m[-1]).max() < 5e-3


@pytest.mark.timeout(120)
def test_a_law_giving_nan_ends_the_run_with_an_error_naming_it(tmp_path):
    """The autopilot terminates the flight (as the SITL does: flight termination, a STATUSTEXT
    naming the controller); the in-process runner ends the run there with that reason instead of
    flying on to a table of NaN."""
    with laws_forgotten_afterwards(tmp_path):
        name = write_overlay(tmp_path, "toy_nan_run", failure=nan_above(1.5))
        with pytest.raises(ControllerFailure) as failure:
            run_scenario(load_scenario("hover"), load_controller(name), RunOptions(duration_s=6.0))
    text = str(failure.value)
    assert re.match(r"hover: flight terminated at t=\d+\.\d+ s: controller toy_nan_run: non-finite output "
                    r"\(U1 nan", text), text  # fmt: skip
    assert 0.5 < float(re.search(r"t=(\S+) s", text).group(1)) < 6.0
