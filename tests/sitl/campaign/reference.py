"""The scalar reference the batch engine is tested against, built from the project's own parts.

:func:`fly_scalar` is ``sitl.inprocess.run_scenario``'s loop (plant core + cascade coupled
without sockets, zero-order hold, the disturbance at every physics step), generalised to what a
campaign samples and ``run_scenario`` cannot take (a plant whose rotor constants differ from the
allocator's, an initial velocity). With ``wire=True`` every frame crosses the MAVLink HIL wire as
in the SITL: ``plant.truth()`` -> ``HilFrameEncoder.encode`` -> ``frame_of`` (ODOMETRY, float32)
-> cascade -> ``ActuatorEncoder.encode`` -> ``ActuatorDecoder.decode`` (float32 controls) -> plant.
"""

from __future__ import annotations

import numpy as np

from autopilot.control.cascade import Cascade
from autopilot.control.config import ControllerConfig
from autopilot.mavlink.codec import Encoder
from autopilot.mavlink.hil import ActuatorEncoder, frame_of
from autopilot.records import StateEstimate
from quadcommon import wire as wire_contract
from quadcommon.config import load_sitl
from quadcommon.mavlink_fast import MessageParts
from quadcommon.trajectories import trajectory_from_spec
from simulator.dynamics.plant import make_plant
from simulator.environment.gust_profile import DisturbanceSchedule
from simulator.mavlink.hil import ActuatorDecoder, HilFrameEncoder
from simulator.sensors import SensorSuite, load_sensors
from sitl.campaign.sampling import RunSample
from sitl.campaign.spec import CampaignSpec


def fly_scalar(spec: CampaignSpec, sample: RunSample, controller: ControllerConfig, wire: bool) -> np.ndarray:
    """Rows of ``sitl.campaign.kernels.RECORD_COLUMNS`` (truth position/attitude, references, controls)."""
    rates = spec.rates
    dt_control = 1.0 / rates.control_hz
    substeps = rates.physics_steps_per_control
    dt_physics = dt_control / substeps
    sc = sample.scenario
    plant = make_plant(sample.plant_vehicle, dt_physics)
    plant.reset(sc.initial_position_m, sc.initial_euler_rad, sample.initial_velocity_m_s)
    cascade = Cascade(controller, sample.vehicle, dt_control)
    trajectory = trajectory_from_spec(sc.trajectory)
    schedule = DisturbanceSchedule(sample.gusts, step_s=dt_physics)
    steps = int(round(spec.duration_s / dt_control))
    if wire:
        home = load_sitl().home
        frames_out = HilFrameEncoder(1, home)
        sensors = SensorSuite(load_sensors("default"), home[2])
        answers = ActuatorEncoder(
            Encoder(1, wire_contract.AUTOPILOT_COMPONENT_ID), sample.vehicle.actuation.mode == "wrench"
        )
        answers_in = ActuatorDecoder()
        usec_per_frame = 1e6 / rates.control_hz
    rows = []
    for k in range(steps + 1):
        t = k * dt_control
        force, torque, wind = schedule.evaluate(t)
        if wire:
            truth = plant.truth()
            time_usec = round(k * usec_per_frame)
            datagram = frames_out.encode(time_usec, truth, sensors.sample(truth), wind)
            frame = frame_of(MessageParts.of_datagram(datagram), home)
            estimate = frame.state
            t_ref = frame.time_usec * 1e-6
            position, euler = truth.position_m, truth.euler_rad
        else:
            position, velocity, euler, euler_rates = plant.kinematics()
            estimate = StateEstimate(position, velocity, euler, euler_rates)
            t_ref = t
        ref = trajectory.sample(t_ref)
        out = cascade.step(estimate, ref)
        rows.append(
            (t, *position, *ref.position_m, *euler, *out.euler_ref_rad, out.thrust_n, *out.torque_euler_n_m,
             *force, *torque)
        )  # fmt: skip
        if k == steps:
            break
        if wire:
            answer = answers_in.decode(answers.encode(time_usec, out.actuator_controls, True))
            plant.set_actuator_controls(answer.controls)
        else:
            plant.set_actuator_controls(out.actuator_controls)
        for j in range(substeps):
            f, tq, w = schedule.evaluate(t + j * dt_physics)
            plant.set_disturbance(f, tq, w)
            plant.step()
    return np.asarray(rows, dtype=float)
