"""The gust-upload hook: ``Simulator.schedule_gust_profile`` swaps the schedule at a frame boundary.

The simulator runs in-process (in a thread) so the test can call the hook while the loop waits
for an answer; the frames are compared with a plant coupled as sitl.inprocess couples it.
"""

from __future__ import annotations

import threading

import pytest

from quadcommon import frames
from quadcommon.config import apply_uncertainty, load_scenario, load_sitl, load_vehicle
from simulator.app import Simulator, SimulatorOptions
from simulator.dynamics.plant import make_plant
from simulator.environment.gust_profile import DisturbanceSchedule, GustProfile, Step, load_gust_profile

from .sim_harness import ScriptedAutopilot, airborne_scenario

N = 53
RATES = load_sitl().rates


def test_uploaded_profile_replaces_the_schedule_from_the_next_frame(tmp_path):
    scenario_path = airborne_scenario(tmp_path)
    scenario = load_scenario(scenario_path)
    dt = 1.0 / RATES.control_hz
    substeps = RATES.physics_steps_per_control
    plant = make_plant(apply_uncertainty(load_vehicle("paper_quad"), scenario), dt / substeps)
    plant.reset(scenario.initial_position_m, scenario.initial_euler_rad)
    schedule = DisturbanceSchedule(load_gust_profile(scenario.gusts))
    upload = GustProfile("test", (Step("force_y", 0.0, 3.0), Step("torque_yaw", 0.004, -0.5)))
    swap_frame = 5
    controls = (0.3, 0.0, 0.01, 0.0)

    sim = Simulator(SimulatorOptions(instance=N, scenario=str(scenario_path), speed=None))
    sim.open()
    loop = threading.Thread(target=sim.run, daemon=True)
    loop.start()
    try:
        with ScriptedAutopilot(N) as ap:
            frame = ap.link()
            for k in range(15):
                truth = plant.truth()
                odo = frame["ODOMETRY"]
                assert (odo.x, odo.y, odo.z) == pytest.approx(
                    frames.vector_to_ned(truth.position_m), abs=1e-6
                )
                if k == swap_frame:
                    # The loop is blocked on our answer to frame k: the swap lands at frame k + 1.
                    start = (k + 1) * dt
                    sim.schedule_gust_profile(upload, start)
                    assert sim.schedule is not None and sim._pending_schedule is not None
                t = k * dt
                plant.set_actuator_controls(controls)
                for j in range(substeps):
                    plant.set_disturbance(*schedule.evaluate(t + j * dt / substeps))
                    plant.step()
                if k == swap_frame:
                    schedule = DisturbanceSchedule(upload, start)
                frame = ap.step(frame, controls=controls, armed=True)
            assert sim._pending_schedule is None
            assert sim.schedule.profile == upload
            # The uploaded force acted (and the scenario's +x step no longer does).
            assert sim.schedule.evaluate(14 * dt)[0] == (0.0, 3.0, 0.0)
    finally:
        sim.stop()
        loop.join(2.0)
        sim.close()
    assert not loop.is_alive()
