"""The SITL (two processes, MAVLink on UDP) and the in-process runner fly the same cores.

The autopilot is started with --autostart: armed at t = 0, it flies the scenario's trajectory
exactly as the in-process runner does, so the only difference is the wire: float32 state in
ODOMETRY and float32 controls in HIL_ACTUATOR_CONTROLS. Stated tolerance: the position
trajectories agree within 1 µm and the attitudes within 1e-5 rad (measured over the full 40 s
of both paper scenarios: 2e-8 m).
"""

import numpy as np
import pytest

from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS
from quadcommon.config import load_controller, load_scenario
from sitl.inprocess import RunOptions, run_scenario

from .harness import Sitl

T = {name: i for i, name in enumerate(TRUTH_FIELDS)}
C = {name: i for i, name in enumerate(CONTROLLER_FIELDS)}
DURATION = 12.0  # covers the take-off transient and the disturbances at 5 and 10 s


@pytest.mark.parametrize("scenario, instance", [("helix", 1), ("circle", 2)])
def test_sitl_and_inprocess_agree(scenario, instance):
    inproc = run_scenario(
        load_scenario(scenario), load_controller("intbs_nlhinf"), RunOptions(duration_s=DURATION)
    )
    with Sitl(instance, scenario=scenario, autostart=True, duration=DURATION, collect=True) as sitl:
        assert sitl.wait_simulator_exit(120.0) == 0
        truth = sitl.truth()
        ctrl = sitl.controller_rows()
    times = truth[:, T["time_s"]]
    n = len(inproc.time_s)
    assert len(times) == n, f"{len(times)} truth rows for {n} control steps"
    assert np.allclose(times, inproc.time_s, atol=1e-9)
    pos = truth[:, [T["x_m"], T["y_m"], T["z_m"]]]
    euler = truth[:, [T["phi_rad"], T["theta_rad"], T["psi_rad"]]]
    gap = np.abs(pos - inproc.position_m).max()
    assert gap < 1e-6, f"position gap {gap:.2e} m"
    assert np.abs(euler - inproc.euler_rad).max() < 1e-5
    # the disturbance schedule ran on the simulator's clock exactly as in-process
    assert np.array_equal(truth[:, [T["Ax_n"], T["Ay_n"], T["Az_n"]]], inproc.disturbance_force_n)
    # controller internals: same references, same thrust to float32 precision
    assert len(ctrl) == n
    assert np.allclose(ctrl[:, [C["x_ref_m"], C["y_ref_m"], C["z_ref_m"]]], inproc.position_ref_m, atol=1e-9)
    assert np.allclose(ctrl[:, C["U1_n"]], inproc.thrust_n, rtol=1e-3, atol=1e-3)
