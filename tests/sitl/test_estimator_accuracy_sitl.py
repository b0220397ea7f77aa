"""The reported accuracies through the two-process SITL, as a new user checks them: ``quadsitl up
--estimator ekf --sensors PROFILE``, the 2 m square (``quadsitl fly setpoints``), the recorder's
session, the estimator's ``pos_*_accuracy_m`` against the truth beside it.

One flight on ``gps``: the wire path (HIL sensors in, ESTIMATOR_STATUS and the recorder out) is
the same for every profile, and ``mocap``'s and ``ideal``'s accuracies are checked with the same
criteria in simulation time (tests/autopilot/estimation/test_accuracy.py). At least 90 % of the
airborne samples inside 3 sigma, and the median reported 1-sigma at most 3x the RMS error of its
axes (horizontal, vertical). The statistics over seeds (NEES) are in
tests/autopilot/estimation/test_accuracy.py, in simulation time.

Instance 55. Waits are bounded on the wall clock; every check is on recorded, simulation-time
rows.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from gcs_scripts import fly_setpoints, record
from gcs_scripts.analysis.log_reader import read_session
from gcs_scripts.link import mavutil
from quadcommon.bus_records import ESTIMATOR_FIELDS
from sitl.launcher import Launcher, VehicleSpec, python_script
from tests.ports import instance_ports

pytestmark = [pytest.mark.processes, pytest.mark.timeout(150)]

PROFILES = {"gps": 55}
_E = {n: i for i, n in enumerate(ESTIMATOR_FIELDS)}


def _wait_fit_to_arm(instance: int, wall_timeout_s: float) -> None:
    """SYS_STATUS with the AHRS healthy (the filter converged) on the API port, then let it go for
    the script."""
    m = mavutil.mavlink
    url = f"udpin:127.0.0.1:{instance_ports(instance).api_remote}"
    conn = mavutil.mavlink_connection(url, source_system=254)
    try:
        deadline = time.monotonic() + wall_timeout_s
        while time.monotonic() < deadline:
            msg = conn.recv_match(type="SYS_STATUS", blocking=True, timeout=0.5)
            if msg is not None and msg.onboard_control_sensors_health & m.MAV_SYS_STATUS_AHRS:
                return
        raise AssertionError(f"the filter of vehicle {instance} did not converge within {wall_timeout_s} s")
    finally:
        conn.close()


@pytest.mark.parametrize("profile", list(PROFILES))
def test_reported_accuracies_against_the_truth_through_the_sitl(tmp_path: Path, profile: str) -> None:
    n = PROFILES[profile]
    spec = VehicleSpec(instance=n, scenario="hover", speed="4", sensors=profile, estimator="ekf")
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 20.0)
        rec = launcher.spawn("record.py", python_script(Path(record.__file__), "--instance", str(n), "--out",
                                                        str(tmp_path / "s"), "--until-disarmed"))  # fmt: skip
        _wait_fit_to_arm(n, 30.0)
        args = ("--instance", str(n), "--hold", "1", "--timeout", "60")
        square = python_script(Path(fly_setpoints.__file__), *args)
        fly = launcher.spawn("fly_setpoints.py", square)
        assert fly.wait(100.0) == 0, fly.tail()
        assert rec.wait(15.0) == 0, rec.tail()
    flight = read_session(tmp_path / "s.parquet")
    est = flight.estimator
    assert est is not None
    air = (flight.position_m[:, 2] > 0.5) & ~np.isnan(est[:, _E["x_est_m"]])
    assert air.sum() > 5000  # 10 s of the square at 500 Hz at least
    err = est[air][:, [_E["x_est_m"], _E["y_est_m"], _E["z_est_m"]]] - flight.position_m[air]
    err_h, err_v = np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2])
    sigma_h, sigma_v = est[air, _E["pos_horiz_accuracy_m"]], est[air, _E["pos_vert_accuracy_m"]]
    rms_h, rms_v = float(np.sqrt(np.mean(err_h**2))), float(np.sqrt(np.mean(err_v**2)))
    inside_h, inside_v = np.mean(err_h <= 3.0 * sigma_h), np.mean(err_v <= 3.0 * sigma_v)
    print(f"{profile}: horizontal RMS {rms_h * 1e3:.2f} mm, median 1-sigma {np.median(sigma_h) * 1e3:.2f} mm "
          f"({inside_h:.1%} inside 3 sigma); vertical RMS {rms_v * 1e3:.2f} mm, median 1-sigma "
          f"{np.median(sigma_v) * 1e3:.2f} mm ({inside_v:.1%} inside 3 sigma)")  # fmt: skip
    assert np.all(est[air, _E["converged"]] == 1.0)
    assert inside_h >= 0.9 and inside_v >= 0.9
    assert np.median(sigma_h) <= 3.0 * rms_h and np.median(sigma_v) <= 3.0 * rms_v
